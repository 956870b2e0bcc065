"""``fignet-gym collect``: planner episodes recorded in the trajectory format, checked against
MuJoCo replaying them from the stored MJCF."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.cli import main
from fignet_gym.data import load_trajectories
from fignet_gym.simulator.scene import ObjectKind
from fignet_gym.tools.collect import COLLECTED_SOURCE, noisy_action, record_episode

#: One step of MuJoCo replaying the recorded tip path gives the recorded pose (float64 round-off;
#: an object moves ~1.6 mm per step).
REPLAY_TOL = 1e-12


@pytest.fixture(scope="module")
def collected(tmp_path_factory: Any) -> Path:
    out = tmp_path_factory.mktemp("collect") / "plan.h5"
    argv = ["collect", "--env", "fignet_gym/Push-v1", "--episodes", "2", "--seed", "100000",
            "--action-noise", "0.3", "--epsilon", "0.2", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    return out


#: What a step of MuJoCo depends on (the env model's userdata is the learned history: no physics).
_PHYSICS = (mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_WARMSTART
            | mujoco.mjtState.mjSTATE_MOCAP_POS | mujoco.mjtState.mjSTATE_MOCAP_QUAT)


class _StateLog(gym.Wrapper):
    """Keeps the env's MuJoCo state before every step."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.states: list[np.ndarray] = []

    def step(self, action: Any) -> Any:
        u = self.env.unwrapped
        state = np.empty(mujoco.mj_stateSize(u.model, _PHYSICS))
        mujoco.mj_getState(u.model, u.data, state, _PHYSICS)
        self.states.append(state)
        return self.env.step(action)


def _step_from(mjcf: str, state: np.ndarray, tip_from: np.ndarray, tip_to: np.ndarray,
               substeps: int) -> np.ndarray:
    """MuJoCo alone on the stored MJCF: one env step from ``state`` with the tip moved linearly
    from ``tip_from`` to ``tip_to`` (``float[3]``); the object's pose after it, ``float[7]``."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, _PHYSICS)
    for s in range(1, substeps + 1):
        data.mocap_pos[0] = tip_from + (tip_to - tip_from) * s / substeps
        mujoco.mj_step(model, data)
    return data.qpos[:7].copy()


def test_recorded_poses_are_what_mujoco_simulates_from_the_stored_scene(collected: Path) -> None:
    """The file holds the episode a fresh recording of the same seed gives (rounded to float32),
    and every recorded step is what MuJoCo alone simulates on the stored MJCF from the state
    before it, the tip moving linearly between its recorded poses. (Replaying a whole episode
    open-loop is no oracle: a block flat on the floor turns 1e-18 m of round-off into
    millimetres within 50 steps, when a corner's contact switches.)"""
    from fignet_gym.agents import make_planner
    from fignet_gym.dynamics import MujocoDynamics

    trajs = load_trajectories(collected)
    assert [t.metadata["seed"] for t in trajs] == [100000, 100001]
    for t in trajs:
        meta = t.metadata
        assert meta["source"] == COLLECTED_SOURCE and meta["kind"] == "push"
        assert t.num_steps == meta["length"] + 1 and meta["length"] > 5
        assert t.dt == pytest.approx(0.02)
    t = trajs[0]
    env = _StateLog(gym.make("fignet_gym/Push-v1", dynamics="mujoco"))
    planner = make_planner("cem", MujocoDynamics(), "push", env=env, seed=100000)
    rng = np.random.default_rng(np.random.SeedSequence([100000, 100000]))
    poses, row = record_episode(env, planner, 100000, rng, action_noise=0.3, epsilon=0.2)
    assert row["length"] == t.metadata["length"] == len(env.states)
    np.testing.assert_allclose(t.poses, poses, atol=1e-6)
    obj, tip = t.names.index("object"), t.names.index("tip")
    assert t.kinds[obj] == ObjectKind.DYNAMIC and t.kinds[tip] == ObjectKind.KINEMATIC
    assert np.linalg.norm(poses[-1, obj, :2] - poses[0, obj, :2]) > 0.01  # it was pushed
    substeps = round(t.dt / mujoco.MjModel.from_xml_string(t.mjcf).opt.timestep)
    for k, state in enumerate(env.states):
        after = _step_from(t.mjcf, state, poses[k, tip, :3], poses[k + 1, tip, :3], substeps)
        np.testing.assert_allclose(after, poses[k + 1, obj], atol=REPLAY_TOL, err_msg=f"step {k}")


def test_the_episode_ends_where_the_env_says(collected: Path) -> None:
    """The last pose is the env's final state: its errors to the recorded goal are the episode's."""
    for t in load_trajectories(collected):
        meta = t.metadata
        obj = t.poses[-1, t.names.index("object")]
        w, z = float(obj[3]), float(obj[6])
        yaw = 2 * np.arctan2(z, w)
        goal = np.asarray(meta["goal"])
        assert np.linalg.norm(obj[:2] - goal[:2]) == pytest.approx(meta["position_error"], abs=1e-6)
        dyaw = (goal[2] - yaw + np.pi) % (2 * np.pi) - np.pi
        assert abs(dyaw) == pytest.approx(meta["orientation_error"], abs=1e-5)


def test_noisy_action() -> None:
    rng = np.random.default_rng(0)
    low, high = -np.ones(2, np.float32), np.ones(2, np.float32)
    planned = np.array([0.5, -0.25], np.float32)
    np.testing.assert_array_equal(noisy_action(planned, rng, 0.0, 0.0, low, high), planned)
    noisy = np.stack([noisy_action(planned, rng, 0.3, 0.0, low, high) for _ in range(2000)])
    assert np.all(noisy >= low) and np.all(noisy <= high)
    assert noisy.mean(axis=0) == pytest.approx(planned, abs=0.03)
    assert noisy.std(axis=0) == pytest.approx([0.3, 0.3], abs=0.03)
    random = np.stack([noisy_action(planned, rng, 0.0, 1.0, low, high) for _ in range(2000)])
    assert random.mean(axis=0) == pytest.approx([0.0, 0.0], abs=0.05)  # uniform, not the plan
    assert random.min() < -0.9 and random.max() > 0.9


@pytest.mark.parametrize("extra, says", [
    (["--epsilon", "1.5"], "--epsilon"),
    (["--action-noise", "-0.1"], "--action-noise"),
    (["--action-noise", "nan"], "--action-noise"),
    (["--checkpoint", "push"], "--checkpoint"),
    (["--env", "fignet_gym/Nope-v0"], "unknown environment"),
    (["--env", "fignet_gym/Toss-v0"], "no push scene"),
    (["--env", "fignet_gym/RealPush-v0"], "edits its compiled model"),
])
def test_bad_arguments_are_refused_before_writing(tmp_path: Path, capsys: Any, extra: list[str],
                                                  says: str) -> None:
    out = tmp_path / "x.h5"
    assert main(["collect", "--episodes", "1", "--out", str(out), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and says in err[0]
    assert not list(tmp_path.iterdir())


def test_an_existing_output_is_kept_without_force(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "x.h5"
    out.write_bytes(b"keep")
    assert main(["collect", "--episodes", "1", "--out", str(out), "--no-progress"]) == 2
    assert "--force" in capsys.readouterr().err
    assert out.read_bytes() == b"keep"


#: ``--env-kwargs`` of a variant whose goals sit within this distance (m) of the object, at its
#: starting heading (Push-v1 draws them 2 to 5 cm away, within 0.3 rad).
_NEAR = 0.004


def test_env_kwargs_reach_the_env(tmp_path: Path, collected: Path) -> None:
    """The recorded goals are drawn as the given env arguments say (and Push-v1's are not)."""
    out = tmp_path / "near.h5"
    kwargs = f'{{"goal_distance_min": 0.0, "goal_distance": {_NEAR}, "goal_yaw": 0.0}}'
    assert main(["collect", "--episodes", "2", "--seed", "100000", "--env-kwargs", kwargs,
                 "--out", str(out), "--no-progress"]) == 0

    def offsets(path: Path) -> list[tuple[float, float]]:
        rows = []
        for t in load_trajectories(path):
            obj = t.poses[0, t.names.index("object")]
            goal = np.asarray(t.metadata["goal"])
            dyaw = (goal[2] - 2 * np.arctan2(obj[6], obj[3]) + np.pi) % (2 * np.pi) - np.pi
            rows.append((float(np.linalg.norm(goal[:2] - obj[:2])), float(abs(dyaw))))
        return rows

    for dist, dyaw in offsets(out):
        assert dist <= _NEAR + 1e-6 and dyaw < 1e-5
    assert load_trajectories(out)[0].metadata["env_kwargs"] == json.loads(kwargs)
    assert all(dist >= 0.02 - 1e-6 for dist, _ in offsets(collected))


@pytest.mark.parametrize("kwargs, says", [
    ("{goal_yaw: 1}", "not JSON"),
    ("[0.1]", "JSON object"),
    ('{"goal_yawn": 0.8}', "takes no argument goal_yawn"),
    ('{"dynamics": "fignet"}', "cannot be set"),
    ('{"goal_distance_min": 0.06}', "refuses"),
])
def test_bad_env_kwargs_are_refused_before_writing(tmp_path: Path, capsys: Any, kwargs: str,
                                                   says: str) -> None:
    out = tmp_path / "x.h5"
    assert main(["collect", "--episodes", "1", "--env-kwargs", kwargs, "--out", str(out),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --env-kwargs") and says in err[0]
    assert not list(tmp_path.iterdir())
