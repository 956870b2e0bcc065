"""Planners (CEM, MPPI) and PPO helpers: behaviour against MuJoCo, divergence, determinism."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
import torch
from sim_factories import wild_simulator

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import (
    CEMConfig,
    CEMPlanner,
    MPPIConfig,
    MPPIPlanner,
    PushProblem,
    plan_state,
    run_episode,
)
from fignet_gym.agents.ppo import (
    EVAL_KEYS,
    PPOConfig,
    RunConfig,
    evaluate_policy_on,
    load_run_policy,
    run_ppo,
)
from fignet_gym.agents.ppo.callback import RunCallback
from fignet_gym.dynamics import DivergenceError, DynamicsBase, FIGNetDynamics, MujocoDynamics
from fignet_gym.envs import PushEnv
from fignet_gym.mjcf import push_object
from fignet_gym.simulator.checkpoint import save
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.model import LearnedSimulator

PUSH = "fignet_gym/Push-v1"
#: Tiny planners: the machine is shared, tests must stay fast.
TINY_CEM = CEMConfig(horizon=3, population=6, elites=2, iterations=2, seed=0)
TINY_MPPI = MPPIConfig(horizon=3, population=6, iterations=2, seed=0)
PLANNERS = [(CEMPlanner, TINY_CEM), (MPPIPlanner, TINY_MPPI)]


def small_simulator() -> LearnedSimulator:
    """The untrained model of the brief (junk motion, but it runs)."""
    cfg = SimulatorConfig(dt=0.02, latent_size=16, message_passing_steps=2, scene_type="push")
    return LearnedSimulator(cfg).eval()




def contact_scene(env: gym.Env) -> None:
    """Object at the origin (heading 0), the tip 2 mm behind its -x face, the goal 3 cm along +x."""
    env.reset(seed=0)
    u = env.unwrapped
    half = float(push_object(u.shape).outline[:, 0].max())  # the -x face is at -half
    tip_r = float(u.model.geom_size[mujoco.mj_name2id(u.model, mujoco.mjtObj.mjOBJ_GEOM, "tip"), 0])
    u.data.qpos[u._qadr : u._qadr + 7] = (0.0, 0.0, u._rest_z, 1.0, 0.0, 0.0, 0.0)
    u.data.qvel[:] = 0.0
    u.data.mocap_pos[u._tip_mocap, :2] = (-(half + tip_r + 0.002), 0.0)
    u.goal = np.array([0.03, 0.0, 0.0])
    mujoco.mj_forward(u.model, u.data)


# ----------------------------------------------------------------------------- planners
@pytest.mark.parametrize("planner_cls, config", PLANNERS)
def test_planner_pushes_object_towards_goal_on_mujoco(planner_cls: type, config: Any) -> None:
    """Judged by MuJoCo itself: the planned pushes beat doing nothing, on the env's own reward."""
    cfg = type(config)(**{**config.__dict__, "horizon": 5, "population": 12, "approach_weight": 0.0})
    envs = {k: gym.make(PUSH) for k in ("planned", "idle")}
    for env in envs.values():
        contact_scene(env)
    planner = planner_cls(MujocoDynamics(nthread=1), cfg, env=envs["planned"])
    returns = {"planned": 0.0, "idle": 0.0}
    errors: dict[str, float] = {}
    # At most 0.1 m/s for 12 steps: the tip can push the object up to ~2 cm.
    for _ in range(12):
        for name, env in envs.items():
            action = planner.plan(env) if name == "planned" else np.zeros(2)
            _, reward, _, _, info = env.step(action)
            returns[name] += reward
            errors[name] = info["position_error"]
    assert errors["idle"] == pytest.approx(0.03, abs=1e-4)  # nothing moved it
    assert errors["planned"] < errors["idle"] - 0.002  # pushed at least 2 mm closer
    assert returns["planned"] > returns["idle"]


@pytest.mark.parametrize("make", [lambda: gym.make(PUSH), lambda: PushEnv(cone="pyramidal")],
                         ids=["Push-v1", "PushEnv-defaults"])
def test_task_rewards_equal_env_rewards_under_mujoco(make: Any) -> None:
    """The planner's cost calls the env's task: on MuJoCo's rollout from a state taken out of a
    running env, it is exactly what env.step returns (terms, success and errors), with Push-v1's
    task and with ``PushEnv``'s own (no success reward, the tip anywhere around the object)."""
    env = make()
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(4):
        env.step(rng.uniform(-1, 1, 2))
    u = env.unwrapped
    state = u.get_state()
    actions = rng.uniform(-1.2, 1.2, (2, 6, 2))  # out of range: clipped
    control = u.task.controls(state[None], actions)
    states = MujocoDynamics(nthread=1).rollout(u.model, state[None], control, frame_skip=u.frame_skip)
    predicted = u.task.reward(states, u.goal, actions)
    cost, _ = PushProblem(env).evaluate(MujocoDynamics(nthread=1), state, actions)
    stepped = []
    for a in actions[0]:
        _, r, _, _, info = env.step(a)
        stepped.append(r)
    np.testing.assert_allclose(predicted[0], stepped, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(cost[0], -sum(stepped), rtol=1e-9)
    pos, yaw = u.task.errors(states[0, -1], u.goal)
    assert pos == pytest.approx(info["position_error"], abs=1e-12)
    assert yaw == pytest.approx(info["orientation_error"], abs=1e-12)


class CountingDynamics(DynamicsBase):
    """A user's dynamics: MuJoCo's step, counted (rollout is DynamicsBase's loop)."""

    def __init__(self) -> None:
        self.calls = 0

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        self.calls += 1
        mujoco.mj_step(model, data, nstep)


@pytest.mark.parametrize("planner_cls, config", PLANNERS)
def test_planner_accepts_user_dynamics(planner_cls: type, config: Any) -> None:
    env = gym.make(PUSH)
    env.reset(seed=1)
    dyn = CountingDynamics()
    action = planner_cls(dyn, config).plan(env)
    assert action.shape == (2,) and action.dtype == np.float32
    assert np.isfinite(action).all() and np.abs(action).max() <= 1.0
    assert dyn.calls == config.iterations * config.population * config.horizon


class NaNDynamics(DynamicsBase):
    """Every rollout diverges: NaN rows, as FIGNet's rollout reports a blow-up."""

    def rollout(
        self,
        model: mujoco.MjModel,
        initial_state: np.ndarray,
        control: Any = None,
        nstep: int | None = None,
        *,
        frame_skip: int = 1,
    ) -> np.ndarray:
        return np.full((control.shape[0], control.shape[1], initial_state.shape[-1]), np.nan)


class HalfNaNDynamics(MujocoDynamics):
    """MuJoCo, but odd candidates diverge after their first step."""

    def rollout(self, *args: Any, **kwargs: Any) -> np.ndarray:
        out = super().rollout(*args, **kwargs)
        out[1::2, 1:] = np.nan
        return out


class RaisingStepDynamics(DynamicsBase):
    """A user's dynamics whose every step blows up (DynamicsBase.rollout turns that into NaN)."""

    def step(self, model: mujoco.MjModel, data: mujoco.MjData, nstep: int = 1) -> None:
        raise DivergenceError("blew up")


class RaisingRolloutDynamics(DynamicsBase):
    """A user's dynamics that raises from rollout instead of returning NaN rows."""

    def rollout(self, *args: Any, **kwargs: Any) -> np.ndarray:
        raise DivergenceError("blew up in rollout")


@pytest.mark.parametrize("planner_cls, config", PLANNERS)
@pytest.mark.parametrize(
    "make_dyn",
    [NaNDynamics, RaisingStepDynamics, RaisingRolloutDynamics,
     lambda: FIGNetDynamics(wild_simulator("push"))],
    ids=["nan", "raising-step", "raising-rollout", "fignet-wild"],
)
def test_all_rollouts_diverging_gives_finite_action(planner_cls: type, config: Any, make_dyn: Any) -> None:
    env = gym.make(PUSH)
    env.reset(seed=2)
    planner = planner_cls(make_dyn(), config)
    for _ in range(2):  # also through the warm start
        action = planner.plan(env)
        assert np.isfinite(action).all() and np.abs(action).max() <= 1.0
        assert planner.last.diverged == planner.last.evaluated
        assert planner.last.cost == np.inf
        env.step(action)


@pytest.mark.parametrize("planner_cls, config", PLANNERS)
def test_partly_diverging_rollouts_are_never_chosen(planner_cls: type, config: Any) -> None:
    env = gym.make(PUSH)
    env.reset(seed=2)
    planner = planner_cls(HalfNaNDynamics(nthread=1), config)
    action = planner.plan(env)
    assert np.isfinite(action).all()
    assert np.isfinite(planner.last.cost)
    assert planner.last.diverged == config.iterations * (config.population // 2)


@pytest.mark.parametrize("planner_cls, config", PLANNERS)
def test_planner_is_deterministic_for_a_seed(planner_cls: type, config: Any) -> None:
    def actions(seed: int) -> np.ndarray:
        env = gym.make(PUSH)
        env.reset(seed=3)
        planner = planner_cls(MujocoDynamics(nthread=2), type(config)(**{**config.__dict__, "seed": seed}))
        out = []
        for _ in range(3):
            out.append(planner.plan(env))
            env.step(out[-1])
        return np.array(out)

    first = actions(0)
    np.testing.assert_array_equal(first, actions(0))
    assert not np.array_equal(first, actions(1))


def test_plan_from_state_equals_plan_from_env() -> None:
    env = gym.make(PUSH)
    env.reset(seed=4)
    from_env = CEMPlanner(MujocoDynamics(nthread=1), TINY_CEM).plan(env)
    planner = CEMPlanner(MujocoDynamics(nthread=1), TINY_CEM, env=env)
    state = plan_state(env)
    env.step(np.ones(2))  # the live env moves on: the planner must use the given state
    np.testing.assert_array_equal(planner.plan(state), from_env)
    with pytest.raises(ValueError, match="STATE_SPEC"):
        planner.plan(state[:-1])


def test_run_episode_reports_its_keys() -> None:
    env = gym.make(PUSH)
    out = run_episode(env, CEMPlanner(MujocoDynamics(nthread=1), TINY_CEM), seed=0, max_steps=3)
    assert set(out) == {
        "return",
        "length",
        "is_success",
        "position_error",
        "orientation_error",
        "diverged",
        "plan_seconds",
        "plan_cpu_seconds",
        "diverged_candidates",
    }
    assert out["length"] == 3 and out["plan_seconds"] > 0 and not out["diverged"]


def test_configs_are_validated_and_frozen() -> None:
    with pytest.raises(ValueError, match="elites"):
        CEMConfig(population=4, elites=5)
    with pytest.raises(ValueError, match="temperature"):
        MPPIConfig(temperature=0.0)
    with pytest.raises(ValueError, match="horizon"):
        CEMConfig(horizon=0)
    with pytest.raises(AttributeError):
        TINY_CEM.horizon = 5  # type: ignore[misc]
    with pytest.raises(ValueError, match="batch_size"):
        PPOConfig(num_envs=2, n_steps=4, batch_size=16)


# ----------------------------------------------------------------------------- PPO
TINY_PPO = PPOConfig(total_timesteps=64, num_envs=2, n_steps=16, batch_size=16, n_epochs=1)


def tiny_run(dynamics: str, simulator: str | None = None) -> RunConfig:
    """A 64-step run on Push-v1 with no periodic evaluation."""
    return RunConfig(env_id=PUSH, dynamics=dynamics, ppo=TINY_PPO, simulator=simulator,
                     eval_every=0, final_episodes=2)


@pytest.fixture()
def thread_probe(monkeypatch: pytest.MonkeyPatch) -> set[int]:
    """torch's thread counts seen at every training step of ``run_ppo`` (its callback, probed)."""
    seen: set[int] = set()
    step = RunCallback._on_step

    def probed(self: RunCallback) -> bool:
        seen.add(torch.get_num_threads())
        return step(self)

    monkeypatch.setattr(RunCallback, "_on_step", probed)
    return seen


def check_report(report: dict[str, Any], n: int) -> None:
    assert tuple(report) == EVAL_KEYS
    assert report["n_episodes"] == n and len(report["episode_returns"]) == n
    assert 0.0 <= report["success_rate"] <= 1.0
    assert 1 <= report["mean_length"] <= gym.spec(PUSH).max_episode_steps
    assert np.isfinite(
        [report["mean_return"], report["final_position_error"], report["final_orientation_error"]]
    ).all()


def test_ppo_on_mujoco_saves_loads_and_evaluates(tmp_path: Path, thread_probe: set[int]) -> None:
    torch.set_num_threads(2)
    result = run_ppo(tmp_path / "run", tiny_run("mujoco"), progress=False)
    assert result["timesteps"] >= TINY_PPO.total_timesteps
    assert thread_probe == {2} and torch.get_num_threads() == 2  # MuJoCo: left as it was
    loaded = load_run_policy(tmp_path / "run")
    again = load_run_policy(tmp_path / "run")
    obs = np.random.default_rng(0).normal(size=(3, 19)).astype(np.float32)
    np.testing.assert_array_equal(
        loaded.predict(obs, deterministic=True)[0], again.predict(obs, deterministic=True)[0]
    )
    report = evaluate_policy_on("mujoco", loaded, n_episodes=2, seed=10_000, env_id=PUSH)
    check_report(report, 2)
    # The run's own final evaluation is the same policy on the same seeds: the same episodes.
    assert report["episode_returns"] == result["eval"]["mujoco"]["episode_returns"]


def test_ppo_on_learned_dynamics_uses_one_thread_and_checks_on_mujoco(
    tmp_path: Path, thread_probe: set[int]
) -> None:
    """The core user story: train on the learned simulator, check on MuJoCo."""
    torch.set_num_threads(2)
    save(small_simulator(), tmp_path / "small.pt")
    result = run_ppo(tmp_path / "run", tiny_run("fignet", str(tmp_path / "small.pt")), progress=False)
    assert thread_probe == {1} and torch.get_num_threads() == 2  # restored afterwards
    check_report(result["eval"]["fignet"], 2)
    check_report(result["eval"]["mujoco"], 2)


class ChasePolicy:
    """A fixed policy: drive the tip at the object (enough to make episodes differ)."""

    def predict(
        self, obs: np.ndarray, state: Any = None, episode_start: Any = None, deterministic: bool = False
    ) -> tuple[np.ndarray, None]:
        return np.clip((obs[:, 0:2] - obs[:, 4:6]) * 30.0, -1, 1).astype(np.float32), None


def test_evaluate_policy_matches_single_env_episodes() -> None:
    """Batched evaluation reproduces plain gym.make episodes seeded seed + k."""
    report = evaluate_policy_on("mujoco", ChasePolicy(), n_episodes=3, seed=7, max_parallel=2,
                                env_id=PUSH)
    env = gym.make(PUSH)
    for k in range(3):
        obs, _ = env.reset(seed=7 + k)
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(ChasePolicy().predict(obs[None])[0][0])
            total += r
            done = term or trunc
        assert report["episode_returns"][k] == pytest.approx(total, rel=1e-9)
        assert report["episode_position_errors"][k] == pytest.approx(info["position_error"])


def test_documented_result_keys_match_code() -> None:
    """The docstrings name every key the functions return (documentation drift)."""
    assert all(f"``{k}``" in evaluate_policy_on.__doc__ for k in EVAL_KEYS)
    out = run_episode(gym.make(PUSH), CEMPlanner(NaNDynamics(), TINY_CEM), seed=0, max_steps=1)
    assert all(f'"{k}"' in run_episode.__doc__ for k in out)
