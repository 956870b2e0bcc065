"""Push and Toss with either dynamics: API checks, documentation, bad input, divergence."""

from __future__ import annotations

import inspect
import re
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from sim_factories import quiet_simulator, wild_simulator
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs import CubeTossEnv, PushEnv, TossEnv
from fignet_gym.simulator.checkpoint import save

ENV_IDS = ["fignet_gym/Push-v2", "fignet_gym/Push-v1", "fignet_gym/PushT-v0", "fignet_gym/Toss-v0"]
#: Keep learned Toss steps cheap in tests: 3 learned steps per toss instead of 50.
FAST = {"fignet_gym/Push-v2": {}, "fignet_gym/Push-v1": {}, "fignet_gym/PushT-v0": {},
        "fignet_gym/Toss-v0": {"settle_steps": 3}}


def make_kwargs(env_id: str, dynamics: str) -> dict[str, Any]:
    if dynamics == "mujoco":
        return {"dynamics": "mujoco"}
    return {"dynamics": "fignet", "checkpoint": quiet_simulator(), **FAST[env_id]}


# ----------------------------------------------------------------------------- API checkers
@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_and_sb3_check_env(env_id: str, dynamics: str) -> None:
    env = gym.make(
        env_id, render_mode="rgb_array", width=64, height=64, **make_kwargs(env_id, dynamics)
    )
    gym_check_env(env.unwrapped, skip_render_check=False)
    sb3_check_env(env.unwrapped, warn=True, skip_render_check=True)
    frame = env.unwrapped.render()
    assert frame.shape == (64, 64, 3) and frame.dtype == np.uint8
    env.close()


@pytest.mark.parametrize("dynamics", ["mujoco", "fignet"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_seeded_resets_and_reward_terms(env_id: str, dynamics: str) -> None:
    env = gym.make(env_id, **make_kwargs(env_id, dynamics))
    a, _ = env.reset(seed=7)
    b, _ = env.reset(seed=7)
    c, _ = env.reset(seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    env.action_space.seed(0)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        terms = {k: v for k, v in info.items() if k.startswith("reward_")}
        assert terms and reward == pytest.approx(sum(terms.values()), abs=1e-12)
        if terminated or truncated:
            break


# ----------------------------------------------------------------------------- documentation
def _table(doc: str, heading: str) -> list[list[str]]:
    """Rows (stripped cells; no header, no separator) of the first table under ``## heading``."""
    section = doc.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]
    rows = [ln.strip() for ln in section.splitlines() if ln.strip().startswith("|")]
    return [[c.strip() for c in r.strip("|").split("|")] for r in rows[2:]]


def _slice(cell: str) -> slice:
    a, b = (int(x) for x in cell.split(":"))
    return slice(a, b)


@pytest.mark.parametrize("cls", [PushEnv, TossEnv, CubeTossEnv])
def test_docstring_tables_match_spaces(cls: type) -> None:
    env = cls()
    doc = inspect.getdoc(cls)
    obs_rows = _table(doc, "Observation space")
    documented = {row[1]: _slice(row[0]) for row in obs_rows}
    assert documented == env.observation_layout
    covered = sorted((s.start, s.stop) for s in documented.values())
    assert covered[0][0] == 0
    assert all(p[1] == q[0] for p, q in zip(covered, covered[1:], strict=False))
    assert covered[-1][1] == env.observation_space.shape[0]
    intro = doc.split("## Observation space")[1].split("|")[0]  # the text above the table
    assert re.search(rf"\b{env.observation_space.shape[0]}\b", intro)
    act_rows = _table(doc, "Action space")
    assert (
        sum(_slice(r[0]).stop - _slice(r[0]).start for r in act_rows) == env.action_space.shape[0]
    )
    assert f"({env.action_space.shape[0]},)" in doc.split("## Action space")[1]
    # every constructor argument is documented, and nothing else
    args = [r[0] for r in _table(doc, "Arguments")]
    params = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    assert args == params
    # defaults in the table match the signature
    for row in _table(doc, "Arguments"):
        default = inspect.signature(cls.__init__).parameters[row[0]].default
        cell = row[1].strip("`")
        if isinstance(default, (int, float, str)) or default is None:
            assert cell == repr(default).replace("'", '"'), (row[0], cell, default)
    # the reward table lists exactly the reward terms returned in info (all terms switched on)
    env = cls(success_weight=1.0) if cls is PushEnv else env
    env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    documented_terms = {r[0] for r in _table(doc, "Reward")}
    assert documented_terms == {k for k in info if k.startswith("reward_")}
    env.close()


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_bad_actions_raise(env_id: str) -> None:
    env = gym.make(env_id)
    env.reset(seed=0)
    n = env.action_space.shape[0]
    name = type(env.unwrapped).__name__
    with pytest.raises(ValueError, match=rf"{name}.*NaN or infinite"):
        env.step(np.full(n, np.nan))
    with pytest.raises(ValueError, match=rf"{name}.*NaN or infinite"):
        env.step(np.full(n, np.inf))
    with pytest.raises(ValueError, match=rf"{name}.*shape"):
        env.step(np.zeros(n + 1))
    with pytest.raises(ValueError, match="not numeric"):
        env.step("left")
    venv = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, n)))
    bad = np.zeros((2, n))
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        venv.step(bad)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_divergence_truncates_with_reason(env_id: str) -> None:
    env = gym.make(env_id, dynamics="fignet", checkpoint=wild_simulator(), **FAST[env_id])
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0)
    assert truncated and "diverged" in info["diverged"]
    assert np.isfinite(reward)
    venv = gym.make_vec(
        env_id,
        num_envs=2,
        vectorization_mode="vector_entry_point",
        dynamics="fignet",
        checkpoint=wild_simulator(),
        **FAST[env_id],
    )
    venv.reset(seed=0)
    _, _, _, truncated, info = venv.step(np.zeros((2, env.action_space.shape[0])))
    assert truncated.all() and info["_diverged"].all()


@pytest.mark.parametrize(
    "env_id,other", [("fignet_gym/Push-v2", "toss"), ("fignet_gym/Toss-v0", "push")]
)
def test_checkpoint_of_another_scene_type_is_refused(
    env_id: str, other: str, tmp_path: Any
) -> None:
    path = tmp_path / f"{other}.pt"
    save(quiet_simulator(other), path)
    with pytest.raises(ValueError, match=f"trained on '{other}' scenes"):
        gym.make(env_id, dynamics="fignet", checkpoint=str(path))
    with pytest.raises(ValueError, match="checkpoint= only applies"):
        gym.make(env_id, dynamics="mujoco", checkpoint=str(path))


def test_unknown_push_shape_lists_valid_ones() -> None:
    with pytest.raises(ValueError, match="rect1"):
        gym.make("fignet_gym/Push-v2", shape="banana")


def test_push_tip_moves_at_bounded_speed() -> None:
    env = gym.make("fignet_gym/Push-v2")
    obs, _ = env.reset(seed=0)
    lay = env.unwrapped.observation_layout
    tip0 = obs[lay["tip_xy"]].copy()
    obs, *_ = env.step(np.array([5.0, -1.0]))  # clipped to (1, -1)
    np.testing.assert_allclose(obs[lay["tip_xy"]] - tip0, [0.002, -0.002], atol=1e-6)


def test_toss_episode_releases_each_object_once() -> None:
    env = gym.make("fignet_gym/Toss-v0")
    obs, _ = env.reset(seed=3)
    lay = env.unwrapped.observation_layout
    assert obs[lay["released"]].sum() == 0 and obs[lay["next_object"]][0] == 1
    total_in = 0.0
    for k in range(3):
        obs, reward, terminated, truncated, info = env.step(np.zeros(2))
        assert obs[lay["released"]].sum() == k + 1
        total_in += info["reward_in_target"]
        assert terminated == (k == 2) and not truncated
    assert total_in == info["num_in_target"]
    assert obs[lay["next_object"]].sum() == 0
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


def test_user_dynamics_object_works_in_single_and_vector_envs() -> None:
    """Any object with the Dynamics methods plugs in; DynamicsBase supplies step_many/rollout."""
    import mujoco

    from fignet_gym.dynamics import DynamicsBase

    class CountingMujoco(DynamicsBase):
        def __init__(self) -> None:
            self.calls = 0

        def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
            self.calls += 1
            mujoco.mj_step(model, data, nstep)

    dyn = CountingMujoco()
    env = gym.make("fignet_gym/Push-v2", dynamics=dyn)
    gym_check_env(env.unwrapped)
    venv = gym.make_vec(
        "fignet_gym/Push-v2", num_envs=3, vectorization_mode="vector_entry_point", dynamics=dyn
    )
    venv.reset(seed=0)
    before = dyn.calls
    venv.step(np.zeros((3, 2)))
    assert dyn.calls == before + 3
    with pytest.raises(ValueError, match="only apply to dynamics given by name"):
        gym.make("fignet_gym/Push-v2", dynamics=dyn, checkpoint="x.pt")


def test_push_reward_is_the_hand_computed_sum_of_its_terms_from_mujocos_own_state() -> None:
    """The reward Push-v2 returns, against the documented formula computed here from MuJoCo's
    ``qpos`` (the object's yaw from its quaternion, not the task's helpers): a flipped sign or
    a wrong heading error in ``envs/tasks.py`` fails this, where comparing ``env.step`` with the
    same task code cannot."""
    import math

    import mujoco

    env = gym.make("fignet_gym/Push-v2", dynamics="mujoco")
    _, _ = env.reset(seed=3)
    u = env.unwrapped
    free = [j for j in range(u.model.njnt) if u.model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    adr = int(u.model.jnt_qposadr[free[0]])
    action = np.array([0.4, -0.7])
    _, reward, _, _, info = env.step(action)
    qpos = u.data.qpos[adr:adr + 7]
    yaw = 2.0 * math.atan2(qpos[6], qpos[3])  # a rotation about z: q = (cos, 0, 0, sin)
    dyaw = abs((u.goal[2] - yaw + math.pi) % (2 * math.pi) - math.pi)
    dpos = float(np.hypot(*(u.goal[:2] - qpos[:2])))
    t = u.task
    expected = (-t.position_weight * dpos - t.orientation_weight * dyaw
                - t.action_weight * float(action @ action))
    if t.success_weight:
        expected += t.success_weight * float(dpos < t.success_position and dyaw < t.success_yaw)
    assert dyaw > 0.02 and dpos > 0.01  # both terms matter in this case
    assert reward == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert info["reward_orientation"] == pytest.approx(-t.orientation_weight * dyaw)
    assert info["orientation_error"] == pytest.approx(dyaw)
    env.close()
