"""Issue 16: bad input never corrupts state, hangs, leaks NaN or prints a traceback.

One test (or a parametrised family) per class of the audit, each reproducing what went wrong:
1 atomic vector steps, 2 bounded checkpoint configs, 3 checksummed and finite weights, 4 exact
resume after SIGKILL, 5 one ``error:`` line instead of a traceback, 6 silent wrong answers,
7 no silent overwrite, 8 nonsense values refused at the boundary.
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import warnings
import zipfile
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import h5py
import mujoco
import numpy as np
import pytest
import torch
from sim_factories import quiet_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.cli import main
from fignet_gym.data.format import (
    MAX_SPEED,
    TrajectoryFile,
    TrajectoryFormatError,
    validate_trajectory,
    write_trajectories,
)
from fignet_gym.data.generate import default_config, iter_trajectories
from fignet_gym.envs.push import PushEnv
from fignet_gym.envs.sb3 import SB3VecEnvAdapter
from fignet_gym.envs.toss import TossEnv
from fignet_gym.mjcf import TossObject
from fignet_gym.pretrained import available_pretrained, load_pretrained, pretrained_path
from fignet_gym.simulator.checkpoint import (
    CheckpointError,
    CheckpointWarning,
    add_checksum,
    content_checksum,
    save,
)
from fignet_gym.simulator.checkpoint import load as load_checkpoint_file
from fignet_gym.simulator.model import LearnedSimulator, SimulatorConfig
from fignet_gym.simulator.scene import Scene, UnsupportedSceneError
from fignet_gym.train.config import TrainConfig

SMALL = SimulatorConfig(latent_size=8, message_passing_steps=1, collision_radius=0.03)


@pytest.fixture(scope="module")
def push_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rel") / "push.h5"
    short = replace(default_config("push"), duration=0.4)  # 20 poses: quick validation rollouts
    write_trajectories(path, list(iter_trajectories("push", 3, seed=11, config=short)))
    return path


def one_error_line(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """The captured stderr must be exactly one ``error:`` line containing every needle."""
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


# ----------------------------------------------------------------------------- 1 atomic vector steps
def _snapshot(venv: gym.vector.VectorEnv | SB3VecEnvAdapter) -> list[tuple]:
    inner = venv.venv if isinstance(venv, SB3VecEnvAdapter) else venv.unwrapped
    return [(e.data.qpos.copy(), e.data.qvel.copy(), e.data.mocap_pos.copy(), e.data.time,
             getattr(e, "released", None)) for e in inner.envs]


def _same(a: list[tuple], b: list[tuple]) -> bool:
    return all(all(np.array_equal(x, y) for x, y in zip(p, q, strict=True))
               for p, q in zip(a, b, strict=True))


@pytest.mark.parametrize("sb3", [False, True], ids=["vector", "sb3"])
@pytest.mark.parametrize("row", [0, 2])
@pytest.mark.parametrize("env_id", ["fignet_gym/Push-v2", "fignet_gym/Toss-v0"])
def test_a_rejected_vector_batch_changes_nothing(env_id: str, row: int, sb3: bool) -> None:
    """A NaN in any row is refused before any row is applied (was: earlier rows applied)."""
    kw = {"settle_steps": 2} if "Toss" in env_id else {}
    venv = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kw)
    ref = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kw)
    if sb3:
        venv, ref = SB3VecEnvAdapter(venv), SB3VecEnvAdapter(ref)
        for v in (venv, ref):
            v.seed(5)
            v.reset()
    else:
        venv.reset(seed=5)
        ref.reset(seed=5)
    before = _snapshot(venv)
    bad = np.full((3, 2), 0.5)
    bad[row, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        venv.step(bad)
    assert _same(before, _snapshot(venv))
    # And the rejected batch leaves no trace: the next valid step equals a fresh environment's.
    good = np.full((3, 2), 0.5)
    a, b = venv.step(good), ref.step(good)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert _same(_snapshot(venv), _snapshot(ref))


def test_a_nan_in_a_row_being_reset_is_refused_too() -> None:
    """NEXT_STEP autoreset ignores the action of a row that resets; a NaN there is still refused
    (it is an agent's bug), and the refused batch changes nothing."""
    venv = gym.make_vec("fignet_gym/Toss-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        objects=[TossObject("cube", 0.7, "metal")], settle_steps=2)
    venv.reset(seed=0)
    _, _, term, _, _ = venv.step(np.zeros((2, 2)))
    assert term.all()  # one object each: both episodes ended, both rows reset on the next step
    before = _snapshot(venv)
    with pytest.raises(ValueError, match="NaN"):
        venv.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    assert _same(before, _snapshot(venv))


def test_a_rejected_batch_with_the_learned_dynamics_changes_nothing() -> None:
    venv = gym.make_vec("fignet_gym/Push-v2", num_envs=2, vectorization_mode="vector_entry_point",
                        dynamics="fignet", checkpoint=quiet_simulator())
    venv.reset(seed=1)
    venv.step(np.zeros((2, 2)))
    before = _snapshot(venv)
    with pytest.raises(ValueError):
        venv.step(np.array([[0.3, 0.1], [np.inf, 0.0]]))
    assert _same(before, _snapshot(venv))


# ----------------------------------------------------------------------------- 2 and 3 checkpoints
@pytest.fixture(scope="module")
def sealed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small checkpoint saved by this version (with its checksum)."""
    path = tmp_path_factory.mktemp("ckpt") / "small.pt"
    torch.manual_seed(0)
    save(LearnedSimulator(SMALL), path, meta={"note": "x"})
    return path


def _unsealed(src: Path, dst: Path, **config: object) -> Path:
    blob = torch.load(src, weights_only=True)
    blob.pop("checksum", None)
    blob["config"].update(config)
    torch.save(blob, dst)
    return dst


@pytest.mark.parametrize("field,value", [("message_passing_steps", 10**7), ("latent_size", 200_000),
                                         ("history", 10**6), ("hidden_size", -5),
                                         ("latent_size", "big"), ("dt", float("nan")),
                                         ("mesh_options", {"sphere_subdivisions": 40})])
def test_unbounded_configs_are_refused_before_anything_is_built(sealed: Path, tmp_path: Path,
                                                                 field: str, value: object) -> None:
    """Was: 10**7 processor blocks grew memory without bound, latent 200000 asked for 160 GB."""
    bad = _unsealed(sealed, tmp_path / "bad.pt", **{field: value})
    with pytest.raises(CheckpointError, match=f"bad.pt: config: .*{field.split('_')[0]}"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CheckpointWarning)
            load_pretrained(bad)
    if field != "mesh_options":
        with pytest.raises(ValueError, match=field):
            SimulatorConfig(**{field: value})


def test_config_that_does_not_match_its_weights_is_refused(sealed: Path, tmp_path: Path) -> None:
    bad = _unsealed(sealed, tmp_path / "m.pt", latent_size=16)
    with pytest.warns(CheckpointWarning), pytest.raises(CheckpointError, match="do not match"):
        load_pretrained(bad)


def _flip_weight_bytes(src: Path, dst: Path, n: int, seed: int = 0) -> None:
    raw = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as z:
        info = max((i for i in z.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    head = raw[info.header_offset:info.header_offset + 30]  # the local header's own lengths
    start = info.header_offset + 30 + int.from_bytes(head[26:28], "little") + int.from_bytes(
        head[28:30], "little")
    for pos in np.random.default_rng(seed).integers(start, start + info.file_size, n):
        raw[pos] ^= 0xFF
    dst.write_bytes(bytes(raw))


@pytest.mark.parametrize("flips", [1, 50])
def test_flipped_bytes_are_caught_by_the_checksum(sealed: Path, tmp_path: Path, flips: int) -> None:
    """Was: 2000 flipped bytes in push.pt changed 286 weights and every loader accepted it."""
    bad = tmp_path / "flipped.pt"
    _flip_weight_bytes(sealed, bad, flips)
    # torch itself reads the damaged file without complaint: only the checksum can tell.
    changed = torch.load(bad, weights_only=True)
    assert changed["checksum"] != content_checksum(changed)
    with pytest.raises(CheckpointError, match="flipped.pt: content checksum mismatch"):
        load_pretrained(bad)


def test_nan_weights_are_refused_even_when_sealed(tmp_path: Path) -> None:
    sim = LearnedSimulator(SMALL)
    with torch.no_grad():
        next(sim.parameters()).fill_(float("nan"))
    save(sim, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match="NaN or infinite"):
        load_pretrained(tmp_path / "nan.pt")


def test_old_checkpoints_load_with_a_warning_and_can_be_sealed(tmp_path: Path) -> None:
    """A checkpoint from before checksums (push.pt with its checksum removed) loads with a
    warning, and add_checksum re-saves exactly the same content sealed, after which a flipped
    byte is caught."""
    old_path = _unsealed(pretrained_path("push"), tmp_path / "old.pt")
    with pytest.warns(CheckpointWarning, match="add_checksum"):
        old = load_pretrained(old_path)
    sealed_path = add_checksum(old_path, tmp_path / "push.pt")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CheckpointWarning)
        new = load_pretrained(sealed_path)
    for (k, a), b in zip(old.state_dict().items(), new.state_dict().values(), strict=True):
        assert torch.equal(a, b), k
    _flip_weight_bytes(sealed_path, tmp_path / "bad.pt", 3)
    with pytest.raises(CheckpointError, match="checksum"):
        load_pretrained(tmp_path / "bad.pt")


def test_shipped_checkpoints_are_sealed() -> None:
    """Every shipped model carries its content checksum: it loads without a CheckpointWarning."""
    for name in available_pretrained():
        with warnings.catch_warnings():
            warnings.simplefilter("error", CheckpointWarning)
            load_pretrained(pretrained_path(name))


def _structural_variants(blob: dict) -> dict[str, object]:
    sd = blob["state_dict"]
    return {
        "not a dict": [1, 2, 3],
        "no config": {k: v for k, v in blob.items() if k != "config"},
        "config is a list": {**blob, "config": [1, 2]},
        "no state_dict": {k: v for k, v in blob.items() if k != "state_dict"},
        "state_dict is a list": {**blob, "state_dict": [1]},
        "strings for weights": {**blob, "state_dict": {k: "x" for k in sd}},
        "meta is a list": {**blob, "meta": [1]},
        "unknown mesh option": {**blob, "config": {**blob["config"], "mesh_options": {"nope": 1}}},
        "gravity is text": {**blob, "config": {**blob["config"], "gravity": "down"}},
        "extra weight": {**blob, "state_dict": {**sd, "bogus": torch.zeros(3)}},
        "missing weight": {**blob, "state_dict": dict(list(sd.items())[1:])},
        "unknown config key": {**blob, "config": {**blob["config"], "colour": "red"}},
    }


def test_structurally_wrong_checkpoints_raise_checkpoint_error(sealed: Path, tmp_path: Path) -> None:
    """Was: KeyError / AttributeError / TypeError for 33 of 208 crafted loads."""
    blob = torch.load(sealed, weights_only=True)
    blob.pop("checksum")
    for name, variant in _structural_variants(blob).items():
        path = tmp_path / "s.pt"
        torch.save(variant, path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CheckpointWarning)
            with pytest.raises(CheckpointError, match="s.pt"):
                load_pretrained(path)
            assert name  # (the loop names the variant in a failure's traceback)


def test_a_pickle_payload_is_refused_without_torchs_unsafe_hint(tmp_path: Path) -> None:
    class Payload:
        def __reduce__(self) -> tuple:
            return (os.getcwd, ())

    buf = io.BytesIO()
    torch.save({"format": "fignet_gym.checkpoint/1", "x": Payload()}, buf)
    (tmp_path / "evil.pt").write_bytes(buf.getvalue())
    with pytest.raises(CheckpointError) as info:
        load_pretrained(tmp_path / "evil.pt")
    assert "evil.pt" in str(info.value) and "weights_only=False" not in str(info.value)
    assert "could run code" in str(info.value)


def test_a_corrupt_pickle_is_unreadable_not_code(tmp_path: Path) -> None:
    (tmp_path / "junk.pt").write_bytes(b"\x80\x02garbage" * 10)  # a pickle header, then junk
    with pytest.raises(CheckpointError) as info:
        load_pretrained(tmp_path / "junk.pt")
    assert "junk.pt: not a readable checkpoint" in str(info.value)
    assert "could run code" not in str(info.value)


# ----------------------------------------------------------------------------- 4 resume after SIGKILL
_KILLED_RUN = """
import os, signal, sys, json
from fignet_gym.train import trainer as training
kill_at = int(sys.argv[3])
orig = training.Trainer.validate
def validate(self, writer=None):
    rec = orig(self, writer)
    if self.state.step == kill_at:
        writer.flush()  # the worst case: the discarded branch's records are all on disk
        os.kill(os.getpid(), signal.SIGKILL)
    return rec
training.Trainer.validate = validate
training.train_from_files([sys.argv[1]], None, "push-cpu", sys.argv[2],
                          overrides=json.loads(sys.argv[4]), resume="--resume" in sys.argv)
"""
TINY = {"simulator.latent_size": 8, "simulator.message_passing_steps": 1,
        "training.batch_size": 2, "training.steps": 6, "training.valid_every": 2,
        "training.valid_trajectories": 1, "training.valid_horizon": 5, "training.threads": 1,
        "training.checkpoint_every": 3, "training.unroll_steps": 1}
TIMING = ("cpu_hours", "ms_per_step_batched", "seconds")


def _curve(run: Path) -> list[dict]:
    return [{k: v for k, v in json.loads(line).items() if k not in TIMING}
            for line in (run / "curve.jsonl").read_text().splitlines()]


def _tb_steps(run: Path, tag: str = "valid/score") -> list[int]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run / "tb"))
    acc.Reload()
    return [e.step for e in acc.Scalars(tag)]


def test_resume_after_sigkill_is_exact(push_file: Path, tmp_path: Path) -> None:
    """A run SIGKILLed between checkpoints (after a new best and its records) and resumed ends
    with the uninterrupted run's curve, TensorBoard steps and best.pt (was: duplicated steps in
    curve.jsonl, best.pt from discarded steps, a stale last.pt.tmp)."""
    from fignet_gym.train.trainer import train_from_files

    straight = tmp_path / "straight"
    train_from_files([str(push_file)], None, "push-cpu", str(straight), overrides=TINY)
    run = tmp_path / "killed"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    args = [sys.executable, "-c", _KILLED_RUN, str(push_file), str(run), "4", json.dumps(TINY)]
    p = subprocess.run(args, capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == -signal.SIGKILL, p.stderr[-2000:]
    # What the kill left: the record of step 4 after last.pt at step 3, and a stale temporary.
    assert [r["step"] for r in _curve(run)] == [2, 4]
    assert torch.load(run / "last.pt", weights_only=True)["meta"]["train_state"]["step"] == 3
    if (run / "best.pt").exists():  # best.pt only ever holds a checkpointed step
        assert load_checkpoint_file(run / "best.pt")[1]["valid"]["step"] <= 3
    (run / "last.pt.tmp").write_bytes(b"half a checkpoint")
    p = subprocess.run(args[:-2] + ["-1", json.dumps(TINY), "--resume"], capture_output=True,
                       text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert _curve(run) == _curve(straight)
    assert _tb_steps(run) == _tb_steps(straight) == [2, 4, 6]
    assert not (run / "last.pt.tmp").exists() and not (run / "best.new.pt").exists()
    best_k, best_s = (load_checkpoint_file(r / "best.pt") for r in (run, straight))
    assert best_k[1]["valid"]["step"] == best_s[1]["valid"]["step"]
    for (k, a), b in zip(best_k[0].state_dict().items(), best_s[0].state_dict().values(), strict=True):
        assert torch.equal(a, b), k


def test_a_kill_never_leaves_best_pt_from_discarded_steps(push_file: Path, tmp_path: Path) -> None:
    """Between checkpoints a new best waits in best.new.pt; a resume drops it if it is newer than
    last.pt and promotes it if not."""
    from fignet_gym.train.rundir import rewind

    sim = LearnedSimulator(SMALL)
    save(sim, tmp_path / "best.new.pt", meta={"valid": {"step": 5}})
    rewind(tmp_path, 3)
    assert not (tmp_path / "best.new.pt").exists() and not (tmp_path / "best.pt").exists()
    save(sim, tmp_path / "best.new.pt", meta={"valid": {"step": 3}})
    rewind(tmp_path, 3)
    assert load_checkpoint_file(tmp_path / "best.pt")[1]["valid"]["step"] == 3


# ----------------------------------------------------------------------------- 5 one error line
def test_cli_user_errors_print_one_line_naming_the_file(push_file: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Was: tracebacks in evaluate, train, floor and ship."""
    missing = tmp_path / "missing.pt"
    assert main(["evaluate", "--checkpoint", str(missing), "--data", str(push_file)]) == 2
    one_error_line(capsys, "missing.pt")
    assert main(["evaluate", "--checkpoint", "nosuchmodel", "--data", str(push_file)]) == 2
    one_error_line(capsys, "nosuchmodel", "push")  # lists the pretrained names
    assert main(["evaluate", "--checkpoint", "push", "--data", str(tmp_path / "none.h5")]) == 2
    one_error_line(capsys, "none.h5")
    (tmp_path / "junk.h5").write_text("not hdf5")
    assert main(["evaluate", "--checkpoint", "push", "--data", str(tmp_path / "junk.h5")]) == 2
    one_error_line(capsys, "junk.h5")
    assert main(["floor", "--data", str(tmp_path / "junk.h5")]) == 2
    one_error_line(capsys, "junk.h5")
    assert main(["ship", "--run", str(tmp_path / "norun"), "--name", "x", "--data", str(push_file),
                 "--dest", str(tmp_path / "dest")]) == 2
    one_error_line(capsys, "norun")
    for bad_set, needle in (("{bad json", "--set"), ('{"lr": 0.1}', "'lr'"), ("[1]", "--set"),
                            ('{"training.nope": 1}', "nope")):
        assert main(["train", "--data", str(push_file), "--set", bad_set,
                     "--out", str(tmp_path / "r")]) == 2
        one_error_line(capsys, needle)
    assert main(["train", "--data", str(push_file), "--config", "nope", "--out", str(tmp_path / "r")]) == 2
    one_error_line(capsys, "nope")


def test_a_truncated_last_pt_on_resume_names_the_file(push_file: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Was: ``OSError: [Errno 22] Invalid argument`` without the file's name."""
    run = tmp_path / "run"
    run.mkdir()
    save(LearnedSimulator(SMALL), run / "last.pt")
    raw = (run / "last.pt").read_bytes()
    (run / "last.pt").write_bytes(raw[: len(raw) // 2])
    assert main(["train", "--data", str(push_file), "--out", str(run), "--resume"]) == 2
    one_error_line(capsys, "last.pt", "truncated")


# ----------------------------------------------------------------------------- 6 silent wrong answers
GHOST = """
<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
<body name="cube" pos="0 0 .1"><freejoint/><geom type="box" size=".05 .05 .05"/></body>
<body name="ghost" pos=".5 0 .3"><freejoint/>
  <geom type="sphere" size=".05" contype="0" conaffinity="0"/></body>
</worldbody></mujoco>
"""


def test_a_free_body_without_collidable_geom_is_refused_by_name() -> None:
    """Was: FIGNet left it hanging in the air while MuJoCo dropped it."""
    model = mujoco.MjModel.from_xml_string(GHOST)
    with pytest.raises(UnsupportedSceneError, match="'ghost'.*no collidable geom"):
        Scene.from_mjmodel(model)
    # MuJoCo does move it: the refusal is not about a body at rest.
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, 50)
    assert data.qpos[9] < 0.3 - 1e-3


PUSH_BAD = [("max_speed", float("nan")), ("max_speed", -1.0), ("goal_distance", float("nan")),
            ("friction", 0.0), ("frame_skip", 0), ("frame_skip", -1), ("frame_skip", 2.5),
            ("workspace", 0.0), ("success_position", float("nan")), ("position_weight", float("inf")),
            ("tip_friction", float("nan")), ("width", 0)]
TOSS_BAD = [("target_radius", float("nan")), ("settle_frame_skip", 0), ("settle_steps", 0),
            ("floor_half_size", -1.0), ("release_position", (0, 0, float("nan"))),
            ("release_velocity_low", (1.0,)), ("target_low", (2.0, 2.0)),
            ("distance_weight", float("nan")), ("height", -3)]


@pytest.mark.parametrize("cls,name,value", [(PushEnv, n, v) for n, v in PUSH_BAD]
                         + [(TossEnv, n, v) for n, v in TOSS_BAD])
def test_env_arguments_are_validated_at_construction(cls: type, name: str, value: object) -> None:
    """Was: NaN in observations or a division by zero at the first step."""
    with pytest.raises(ValueError, match=name):
        cls(**{name: value})


@pytest.mark.parametrize("cls", [PushEnv, TossEnv])
def test_stepping_before_reset_raises(cls: type) -> None:
    env = cls()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    env.step(np.zeros(2))


def test_a_small_file_declaring_gigabytes_is_refused_before_reading(push_file: Path,
                                                                    tmp_path: Path) -> None:
    """Was: 46 KB declaring 16 GB made ``show`` die of memory."""
    big = tmp_path / "big.h5"
    big.write_bytes(push_file.read_bytes())
    with h5py.File(big, "a") as f:
        g = f["trajectories"][sorted(f["trajectories"])[0]]
        del g["poses"]
        g.create_dataset("poses", shape=(200_000_000, 3, 7), dtype="f4", chunks=(1000, 3, 7),
                         compression="gzip")
    assert big.stat().st_size < 10 * push_file.stat().st_size
    with TrajectoryFile(big) as f, pytest.raises(TrajectoryFormatError, match="big.h5.*poses.*GB"):
        f[0]


def test_dataset_validation_bounds_teleports_and_absurd_positions(push_file: Path) -> None:
    traj = TrajectoryFile(push_file)[0]
    validate_trajectory(traj)
    obj = int(np.flatnonzero(np.asarray(traj.kinds) == 0)[0])
    jump = traj.poses.copy()
    jump[10:, obj, 0] += 5.0  # 5 m in one step of 0.02 s
    with pytest.raises(TrajectoryFormatError, match="jumps 5 m between steps 9 and 10"):
        validate_trajectory(replace(traj, poses=jump))
    fast_ok = traj.poses.copy()
    fast_ok[10:, obj, 0] += 0.9 * MAX_SPEED * traj.dt  # just under the bound: accepted
    validate_trajectory(replace(traj, poses=fast_ok))
    far = traj.poses.copy()
    far[5, obj, :3] = 1e30
    with pytest.raises(TrajectoryFormatError, match="1e\\+30 m from the origin"):
        validate_trajectory(replace(traj, poses=far))


# ----------------------------------------------------------------------------- 7 no silent overwrite
def test_train_into_an_existing_run_is_refused_unless_force(push_file: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "curve.jsonl").write_text('{"step": 1}\n')
    assert main(["train", "--data", str(push_file), "--out", str(run)]) == 2
    one_error_line(capsys, str(run), "--resume", "--force")
    assert (run / "curve.jsonl").read_text() == '{"step": 1}\n'
    from fignet_gym.train.rundir import prepare_run_folder

    prepare_run_folder(run, resume=False, force=True)
    assert not (run / "curve.jsonl").exists()


def test_resume_with_another_config_is_refused(push_file: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from fignet_gym.train.config import load_run_config

    run = tmp_path / "run"
    run.mkdir()
    sim_cfg, cfg = load_run_config("push-cpu")
    save(LearnedSimulator(SimulatorConfig.from_dict(sim_cfg)), run / "last.pt")
    assert main(["train", "--data", str(push_file), "--config", "toss-cpu", "--out", str(run),
                 "--resume"]) == 2
    one_error_line(capsys, "last.pt", "scene_type")


def test_generate_never_replaces_a_file_unless_force(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "old.h5"
    out.write_bytes(b"precious")
    assert main(["generate", "push", "--num", "1", "--out", str(out), "--no-progress"]) != 0
    one_error_line(capsys, "old.h5", "--force")
    assert out.read_bytes() == b"precious"
    assert main(["generate", "push", "--num", "1", "--out", str(out), "--no-progress",
                 "--workers", "1", "--force"]) == 0
    assert len(TrajectoryFile(out)) == 1


# ----------------------------------------------------------------------------- 8 nonsense values
@pytest.mark.parametrize("argv,needle", [
    (["generate", "push", "--num", "-3", "--out", "x.h5"], "--num"),
    (["generate", "push", "--num", "1", "--workers", "-2", "--out", "x.h5"], "--workers"),
    (["generate", "push", "--num", "1", "--duration", "0", "--out", "x.h5"], "--duration"),
    (["evaluate", "--checkpoint", "push", "--data", "x.h5", "--horizon", "-1"], "--horizon"),
    (["evaluate", "--checkpoint", "push", "--data", "x.h5", "--num", "0"], "--num"),
    (["floor", "--data", "x.h5", "--noise", "-1"], "--noise"),
    (["train", "--data", "x.h5", "--out", "r", "--max-train", "0"], "--max-train"),
])
def test_nonsense_cli_values_are_refused_by_the_parser(argv: list[str], needle: str,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"error: argument {needle}" in err and "must be" in err


@pytest.mark.parametrize("key,value", [("lr", 0), ("valid_every", 0), ("checkpoint_every", 0),
                                       ("batch_size", -1), ("steps", 1.5), ("ema_decay", 1.0),
                                       ("lr_final", float("nan"))])
def test_training_settings_are_bounded(key: str, value: object) -> None:
    """Was: ZeroDivisionError (valid_every=0, checkpoint_every=0) or a silent no-op (lr=0)."""
    with pytest.raises(ValueError, match=f"training.{key}"):
        TrainConfig(**{key: value})


def test_evaluate_refuses_data_of_another_scene_type(push_file: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", "--checkpoint", "toss", "--data", str(push_file), "--out",
                 str(tmp_path / "e"), "--videos", "0"]) == 2
    one_error_line(capsys, "push.h5", "'toss'")


def test_import_movi_without_metadata_writes_nothing(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "meshes.json").write_text("{}")
    out = tmp_path / "movi.h5"
    assert main(["import-movi", str(tmp_path / "empty"), "--meshes", str(tmp_path / "meshes.json"),
                 "--out", str(out)]) != 0
    one_error_line(capsys, "metadata.json")
    assert not out.exists()


@pytest.mark.parametrize("seed", [1.5, -1, "a", [1.5, 2], True])
def test_vector_reset_refuses_non_integer_seeds(seed: object) -> None:
    venv = gym.make_vec("fignet_gym/Push-v2", num_envs=2, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=seed)
    venv.reset(seed=[3, None])
