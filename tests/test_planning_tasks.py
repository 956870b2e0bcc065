"""Planners over any task: a user's own environment, CubeToss-v0 on both dynamics, SB3's
``predict(deterministic)``, and the same mocap motion in both backends over multi-step calls."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium import spaces
from sim_factories import quiet_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import CEMConfig, CEMPlanner, MPPIConfig, MPPIPlanner, run_episode
from fignet_gym.dynamics import (
    STATE_SPEC,
    Dynamics,
    FIGNetDynamics,
    MujocoDynamics,
    compile_with_history,
)
from fignet_gym.envs.base import MjDynamicsEnv
from fignet_gym.envs.tasks import StateLayout, Task
from fignet_gym.mjcf import push_scene_xml

#: A ball in free space: its velocity, set by the action, carries it to a target.
BALL_XML = """<mujoco><option gravity="0 0 0" timestep="0.01"/><worldbody>
<body name="ball"><freejoint/><geom type="sphere" size="0.05" mass="1"/></body>
</worldbody></mujoco>"""
#: The user's action box, not [-1, 1]: the planner must map onto it.
KICK = 3.0


def _rows(nstep: int, frame_skip: int) -> np.ndarray:
    """Control rows ``float[1, T, 0]`` of a model without mocap bodies: ``T = nstep //
    frame_skip`` recorded states of ``nstep`` MuJoCo timesteps."""
    return np.zeros((1, nstep // frame_skip, 0))


class KickTask(Task):
    """Kick the ball along x (m/s) so that it ends at ``target`` after one step."""

    plan_horizon = 1

    def __init__(self, model: mujoco.MjModel) -> None:
        self.layout = StateLayout(model)

    def kick(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        out = np.broadcast_to(states, (len(actions), states.shape[-1])).copy()
        out[:, self.layout.qvel] = actions[:, 0]
        return out

    def plan_rollout(self, dynamics: Dynamics, model: mujoco.MjModel, state: np.ndarray,
                     actions: np.ndarray, **context: Any) -> np.ndarray:
        skip = int(context["frame_skip"])
        return dynamics.rollout(model, self.kick(state[None], actions[:, 0]), _rows(skip, skip),
                                nstep=skip, frame_skip=skip)

    def plan_cost(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray,
                  shaping: float = 0.0, terminal: float = 0.0, **context: Any) -> np.ndarray:
        return np.abs(states[:, -1, self.layout.qpos] - float(context["target"]))


class KickEnv(MjDynamicsEnv):
    """A user's environment: nothing in fignet_gym.agents knows it."""

    def __init__(self) -> None:
        model = mujoco.MjModel.from_xml_string(BALL_XML)
        self.task = KickTask(model)
        self.action_space = spaces.Box(-KICK, KICK, (1,), np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, (1,), np.float32)
        self.target = 0.0
        super().__init__(model, "mujoco", None, 100, None, 64, 64, None)

    def task_context(self) -> dict[str, Any]:
        return {**super().task_context(), "target": self.target}

    def _reset_task(self, rng: np.random.Generator, options: Any) -> None:
        self.target = float(rng.uniform(-2.0, 2.0))

    def _apply_action(self, action: np.ndarray) -> None:
        self.data.qvel[0] = action[0]

    def _observe(self) -> np.ndarray:
        return self.data.qpos[:1].astype(np.float32)

    def _evaluate(self, action: np.ndarray) -> tuple[dict[str, float], bool, bool, dict[str, Any]]:
        return {"reward_distance": -abs(self.data.qpos[0] - self.target)}, True, False, {}


@pytest.mark.parametrize("planner_cls, config", [
    (CEMPlanner, CEMConfig(horizon=1, population=32, elites=4, iterations=4, seed=0)),
    (MPPIPlanner, MPPIConfig(horizon=1, population=64, iterations=4, temperature=0.01, seed=0)),
])
def test_a_users_own_env_plans_without_changing_agents(planner_cls: Any, config: Any) -> None:
    env = KickEnv()
    planner = planner_cls(MujocoDynamics(nthread=1), config, env=env)
    for seed in range(3):
        env.reset(seed=seed)
        action = planner.plan(env)
        assert env.action_space.contains(action)
        # the optimum is target / (1 s) m/s, inside the box: found to a few cm
        _, reward, *_ = env.step(action)
        assert -reward < 0.1, (seed, action, env.target)


def test_predict_follows_sb3_deterministic_meaning() -> None:
    env = KickEnv()
    cfg = CEMConfig(horizon=1, population=16, elites=4, iterations=2, noise_std=0.5, seed=0)
    obs, _ = env.reset(seed=0)
    mode = CEMPlanner(MujocoDynamics(nthread=1), cfg, env=env).predict(obs, deterministic=True)[0]
    again = CEMPlanner(MujocoDynamics(nthread=1), cfg, env=env).predict(obs, deterministic=True)[0]
    np.testing.assert_array_equal(mode, again)  # the plan's action, seeded
    planner = CEMPlanner(MujocoDynamics(nthread=1), cfg, env=env)
    draws = [planner.predict(obs, deterministic=False)[0] for _ in range(6)]
    draws = np.array(draws)
    assert all(env.action_space.contains(d) for d in draws)
    assert np.ptp(draws) > 0 and not np.allclose(draws, mode)  # a draw around the plan


@pytest.mark.parametrize("planning", ["mujoco", "fignet"])
def test_cem_plans_cube_toss_with_either_dynamics(planning: str) -> None:
    env = gym.make("fignet_gym/CubeToss-v0")
    dyn: Dynamics = (MujocoDynamics(nthread=1) if planning == "mujoco"
                     else FIGNetDynamics(quiet_simulator("cube-real", dt=0.006756756756756757)))
    model = None
    if planning == "fignet":  # the learned model sees its nominal scene: same bodies and joints
        model = gym.make("fignet_gym/CubeToss-v0", dynamics="fignet",
                         checkpoint=dyn.simulator).unwrapped.model
    cfg = CEMConfig(horizon=1, population=6, elites=2, iterations=1, seed=0)
    planner = CEMPlanner(dyn, cfg, env=env, model=model)
    out = run_episode(env, planner, seed=0)
    assert out["length"] == 1 and np.isfinite(out["distance"]) and "is_success" in out
    if planning == "mujoco":  # planning on the acting model beats the mean random toss
        rng = np.random.default_rng(0)
        rand = []
        for _ in range(6):
            env.reset(seed=0)
            rand.append(env.step(rng.uniform(-1, 1, 6))[4]["distance"])
        assert out["distance"] < np.mean(rand)


@pytest.mark.parametrize("backend", ["mujoco", "fignet"])
def test_mocap_moves_the_same_way_over_one_call_or_several(backend: str) -> None:
    """One call of 2 learned steps moves the tip as two calls with its linear midpoint do, in
    both backends: the tip glides to its target (MuJoCo's mocap path), it is not held there."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.052, 0.0)))
    dyn: Dynamics = (MujocoDynamics(nthread=1) if backend == "mujoco"
                     else FIGNetDynamics(quiet_simulator("push")))
    one, two = mujoco.MjData(model), mujoco.MjData(model)
    for d in (one, two):
        mujoco.mj_forward(model, d)
    start = one.mocap_pos[0].copy()
    goal = start + np.array([0.008, 0.002, 0.0])
    one.mocap_pos[0] = goal
    dyn.step(model, one, 20)
    two.mocap_pos[0] = (start + goal) / 2
    dyn.step(model, two, 10)
    two.mocap_pos[0] = goal
    dyn.step(model, two, 10)
    a, b = np.empty(mujoco.mj_stateSize(model, STATE_SPEC)), np.empty(
        mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, one, a, STATE_SPEC)
    mujoco.mj_getState(model, two, b, STATE_SPEC)
    n = 1 + model.nq + model.nv  # time, qpos, qvel: the physics
    np.testing.assert_allclose(a[:n], b[:n], rtol=0, atol=1e-9 if backend == "mujoco" else 1e-5)
