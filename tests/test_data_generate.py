"""Generators: reproducible for a seed whatever the worker count, true to MuJoCo and the specs."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fignet_gym.cli import main
from fignet_gym.data import generate as gen
from fignet_gym.data.format import INCOMPLETE_SUFFIX, TrajectoryFile, load_trajectories
from fignet_gym.mjcf import MATERIALS, MIT_OBJECTS, TOSS_SHAPES
from fignet_gym.simulator.scene import ObjectKind

SHORT_TOSS = replace(gen.TossConfig(), duration=0.3)


def _run_cli(*argv: str) -> int:
    return main(list(argv))


def test_same_seed_same_data_for_any_worker_count() -> None:
    serial = list(gen.iter_trajectories("toss-simple", 3, seed=7, workers=1, config=SHORT_TOSS))
    parallel = list(gen.iter_trajectories("toss-simple", 3, seed=7, workers=2, config=SHORT_TOSS))
    for a, b in zip(serial, parallel, strict=True):
        assert a.name == b.name and a.mjcf == b.mjcf
        np.testing.assert_array_equal(a.poses, b.poses)
    other = next(gen.iter_trajectories("toss-simple", 1, seed=8, config=SHORT_TOSS))
    assert other.mjcf != serial[0].mjcf
    # trajectory i does not depend on how many come before it
    alone = list(gen.iter_trajectories("toss-simple", 3, seed=7, config=SHORT_TOSS))[2]
    np.testing.assert_array_equal(alone.poses, serial[2].poses)


def test_push_poses_match_an_independent_mujoco_replay(tmp_path: Path) -> None:
    path = tmp_path / "push.h5"
    assert _run_cli("generate", "push", "--num", "2", "--seed", "3", "--out", str(path),
                    "--workers", "1", "--no-progress") == 0
    for traj in load_trajectories(path):
        meta = traj.metadata
        model = mujoco.MjModel.from_xml_string(traj.mjcf)
        data = mujoco.MjData(model)
        start, vel = np.array(meta["tip_start"]), np.array(meta["tip_velocity"])
        sub = meta["substeps"]
        obj = model.body("object").id
        assert traj.dt == pytest.approx(model.opt.timestep * sub) and traj.dt == pytest.approx(0.02)
        for k in range(1, traj.num_steps):
            for j in range(sub):
                t = (k - 1) * sub * model.opt.timestep + (j + 1) * model.opt.timestep
                data.mocap_pos[0, :2] = start + vel * min(t, meta["tip_stop_time"])
                mujoco.mj_step(model, data)
            # a free body's pose is its joint's qpos (xpos lags one step behind after mj_step)
            adr = model.jnt_qposadr[model.body_jntadr[obj]]
            np.testing.assert_allclose(traj.poses[k, 1], data.qpos[adr:adr + 7], atol=2e-6)
            np.testing.assert_allclose(traj.poses[k, 2, :3], data.mocap_pos[0], atol=2e-6)
        assert traj.names == ("world", "object", "tip")
        assert traj.kinds.tolist() == [ObjectKind.STATIC, ObjectKind.DYNAMIC, ObjectKind.KINEMATIC]


def test_push_kinematics_follow_the_real_protocol() -> None:
    cfg = gen.PushConfig()
    for index in range(4):
        traj = gen._one(("push", cfg, 11, index))
        m = traj.metadata
        speed = m["speed_mm_s"] / 1000
        assert m["speed_mm_s"] in cfg.speeds_mm_s and m["angle_deg"] in cfg.angles_deg
        assert m["shape"] in MIT_OBJECTS and cfg.friction_range[0] <= m["friction"] <= 0.35
        tip = traj.poses[:, 2, :2]
        step = np.linalg.norm(np.diff(tip, axis=0), axis=1) / traj.dt
        moving = (np.arange(1, traj.num_steps) * traj.dt) <= m["tip_stop_time"] - 1e-9
        np.testing.assert_allclose(step[moving], speed, rtol=1e-4)
        # the approach is 0.04 m unless that takes longer than 0.2 s; 0.05 m past the contact
        approach = min(0.04, speed * 0.2)
        assert m["tip_contact_time"] == pytest.approx(approach / speed)
        assert m["tip_stop_time"] == pytest.approx((approach + 0.05) / speed)
        # before the tip reaches the object, the object does not move
        before = int(np.floor(m["tip_contact_time"] / traj.dt))
        drift = np.abs(traj.poses[:before + 1, 1, :2] - traj.poses[0, 1, :2]).max()
        assert drift < 1e-5
        assert np.all(np.abs(traj.poses[:, 1, 2] - 0.0065) < 5e-4)  # stays flat on the floor


def test_toss_distribution_matches_movi() -> None:
    cfg = replace(SHORT_TOSS, duration=0.04)
    counts = []
    for index in range(12):
        traj = gen._one(("toss-simple", cfg, 5, index))
        m = traj.metadata
        n = len(m["shapes"])
        counts.append(n)
        assert set(m["shapes"]) <= {"cube", "sphere", "cylinder"}
        assert set(m["sizes"]) <= {0.7, 1.4}
        fr = np.array([MATERIALS[mat][0] for mat in m["materials"]])
        np.testing.assert_allclose(traj.props[1:, 1], fr)
        p0 = traj.poses[0, 1:, :3]
        assert np.all(np.abs(p0[:, :2]) <= 5) and np.all((p0[:, 2] >= 1) & (p0[:, 2] <= 5))
        v = np.array(m["init_qvel"])
        # tossed toward the centre: v + (x, y) is U(-4, 4), no vertical or angular velocity
        assert np.all(np.abs(v[:, :2] + p0[:, :2]) <= 4) and np.all(v[:, 2:] == 0)
        np.testing.assert_allclose(np.linalg.norm(traj.poses[..., 3:], axis=-1), 1, atol=1e-9)
        assert traj.dt == pytest.approx(0.02)
    assert min(counts) >= 3 and max(counts) <= 10 and len(set(counts)) > 2


def test_toss_poses_match_mujoco_from_keyframe() -> None:
    traj = gen._one(("toss-complex", SHORT_TOSS.__class__(complex=True, duration=0.2), 2, 0))
    model = mujoco.MjModel.from_xml_string(traj.mjcf)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    for k in range(1, traj.num_steps):
        mujoco.mj_step(model, data, nstep=10)
        qpos = data.qpos.reshape(-1, 7)
        np.testing.assert_allclose(traj.poses[k, 1:], qpos, atol=1e-9)
    assert set(traj.metadata["shapes"]) <= set(TOSS_SHAPES)
    assert all(0.7 <= s <= 1.4 for s in traj.metadata["sizes"])


def test_interrupted_generation_leaves_no_file(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "toss.h5"
    real = gen.generate_toss
    calls = {"n": 0}

    def flaky(rng, cfg):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(rng, cfg)

    monkeypatch.setattr(gen, "generate_toss", flaky)
    with pytest.raises(KeyboardInterrupt):
        gen.generate("toss-simple", 3, 0, out, workers=1, config=SHORT_TOSS, progress=False)
    assert not out.exists() and not out.with_name("toss.h5" + INCOMPLETE_SUFFIX).exists()


def test_cli_generate_file_metadata_and_bad_kind(tmp_path: Path, capsys) -> None:
    out = tmp_path / "t.h5"
    assert _run_cli("generate", "toss-simple", "--num", "2", "--seed", "1", "--out", str(out),
                    "--workers", "1", "--duration", "0.1", "--no-progress") == 0
    with TrajectoryFile(out) as f:
        assert len(f) == 2
        assert f.metadata["kind"] == "toss-simple" and f.metadata["seed"] == 1
        assert f.metadata["config"]["mesh_options"]["sphere_subdivisions"] == 1
        assert f[1].num_steps == 6
        coarse = f[1].poses
    # Half the substeps: the same tosses (draws do not depend on the step), stored twice as often
    fine = tmp_path / "t5.h5"
    assert _run_cli("generate", "toss-simple", "--num", "2", "--seed", "1", "--out", str(fine),
                    "--workers", "1", "--duration", "0.1", "--substeps", "5", "--no-progress") == 0
    with TrajectoryFile(fine) as f:
        assert f[1].dt == pytest.approx(0.01) and f[1].num_steps == 11
        np.testing.assert_allclose(f[1].poses[::2], coarse, atol=1e-12)
    # Out-of-range values are refused by the parser (usage error: exit 2), before any work.
    with pytest.raises(SystemExit) as info:
        _run_cli("generate", "push", "--num", "1", "--out", str(fine), "--substeps", "0",
                 "--no-progress")
    assert info.value.code == 2
    assert "argument --substeps: must be an integer >= 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _run_cli("generate", "push", "--num", "1", "--seed", "-1", "--out", str(out),
                 "--workers", "1", "--no-progress")
    assert "argument --seed: must be an integer >= 0" in capsys.readouterr().err
    with pytest.raises(ValueError, match="valid: push, toss-simple, toss-complex"):
        gen.default_config("toss")


def test_resimulate_replays_and_nudges_only_the_free_bodies() -> None:
    toss = gen._one(("toss-simple", SHORT_TOSS, 3, 0))
    push = gen._one(("push", replace(gen.PushConfig(), duration=0.3), 3, 0))
    for traj in (toss, push):
        np.testing.assert_allclose(gen.resimulate(traj), traj.poses, atol=1e-9)
        nudged = gen.resimulate(traj, position_noise=1e-3, at_pose=2, seed=5)
        np.testing.assert_array_equal(nudged[:2], traj.poses[:2])
        free = traj.kinds == int(ObjectKind.DYNAMIC)
        shift = np.linalg.norm(nudged[2, :, :3] - traj.poses[2, :, :3], axis=-1)
        np.testing.assert_allclose(shift[free], 1e-3, rtol=1e-6)
        np.testing.assert_allclose(nudged[2, free, 2], traj.poses[2, free, 2], atol=1e-12)
        # orientation, the static floor and the pusher's prescribed path are untouched
        np.testing.assert_allclose(nudged[2, :, 3:], traj.poses[2, :, 3:], atol=1e-12)
        np.testing.assert_allclose(nudged[:, ~free], traj.poses[:, ~free], atol=1e-9)
    imported = replace(push, metadata={**push.metadata, "source": "mit-push"})
    with pytest.raises(ValueError, match="cannot be re-simulated"):
        gen.resimulate(imported)
    with pytest.raises(ValueError, match="at_pose"):
        gen.resimulate(toss, 1e-3, at_pose=toss.num_steps)
