"""Issue 13: rollouts from whole states, the task API, Push-v1, planning on Push and Toss."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from sim_factories import quiet_simulator, zero_simulator
from stable_baselines3.common.evaluation import evaluate_policy

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.agents import (
    CEMConfig,
    CEMPlanner,
    MPPIConfig,
    MPPIPlanner,
    TossProblem,
    run_episode,
)
from fignet_gym.dynamics import (
    STATE_SPEC,
    FIGNetDynamics,
    MujocoDynamics,
    rollout_loop,
    userdata_slice,
)

PUSH_IDS = ["fignet_gym/Push-v1", "fignet_gym/Push-v2"]
TOSS_FAST = {"settle_steps": 8}
TINY_CEM = CEMConfig(horizon=3, population=6, elites=2, iterations=2, seed=0)
TINY_MPPI = MPPIConfig(horizon=3, population=6, iterations=2, seed=0)


def _rows(nstep: int, frame_skip: int) -> np.ndarray:
    """Control rows ``float[1, T, 0]`` of a model without mocap bodies: ``T = nstep //
    frame_skip`` recorded states of ``nstep`` MuJoCo timesteps."""
    return np.zeros((1, nstep // frame_skip, 0))


def running_push(env_id: str, steps: int = 6, **kwargs: Any) -> gym.Env:
    """A push env a few random steps into an episode (the tip has moved, the object may too)."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=3)
    rng = np.random.default_rng(1)
    for _ in range(steps):
        env.step(rng.uniform(-1, 1, 2))
    return env


def running_toss(**kwargs: Any) -> gym.Env:
    """A toss env after its first release."""
    env = gym.make("fignet_gym/Toss-v0", **TOSS_FAST, **kwargs)
    env.reset(seed=2)
    env.step(np.array([0.3, -0.2]))
    return env


# ----------------------------------------------------------------------------- item 1: whole states
@pytest.mark.parametrize("env_id", PUSH_IDS)
def test_mujoco_rollout_from_a_running_push_env_equals_stepping_it(env_id: str) -> None:
    env = running_push(env_id)
    u = env.unwrapped
    state = u.get_state()
    actions = np.random.default_rng(2).uniform(-1, 1, (3, 7, 2))
    out = MujocoDynamics(nthread=2).rollout(
        u.model, state[None], u.task.controls(state[None], actions), frame_skip=u.frame_skip
    )
    stepped = []
    for a in actions[1]:
        env.step(a)
        stepped.append(u.get_state())
    np.testing.assert_allclose(out[1], np.array(stepped), rtol=0, atol=1e-9)


def test_mujoco_rollout_from_a_running_toss_env_equals_stepping_it() -> None:
    env = running_toss()
    u = env.unwrapped
    action = np.array([-0.4, 0.7])
    released = u.task.release(u.get_state(), u.released, float(u.release_yaws[u.released]), action)
    dyn = MujocoDynamics(nthread=1)
    nstep = u.frame_skip
    skip = u.settle_frame_skip
    out = dyn.rollout(u.model, released[None], _rows(nstep, skip), nstep=nstep, frame_skip=skip)
    whole = dyn.rollout(u.model, released[None], _rows(nstep, nstep), nstep=nstep, frame_skip=nstep)
    env.step(action)
    np.testing.assert_allclose(whole[0, -1], u.get_state(), rtol=0, atol=1e-9)
    # recorded every learned step, the pose history in userdata has finer frames than one step
    # of the whole settle records; the physics is the same
    phys = np.ones(len(out[0, -1]), bool)
    phys[userdata_slice(u.model)] = False
    np.testing.assert_allclose(out[0, -1, phys], u.get_state()[phys], rtol=0, atol=1e-9)


def test_mujoco_rollout_starts_the_tip_where_the_state_has_it() -> None:
    """The bug of issue 13: a scratch MjData's tip must not leak into the next rollout."""
    env = running_push("fignet_gym/Push-v1", steps=0)
    u = env.unwrapped
    dyn = MujocoDynamics(nthread=1)
    state = u.get_state()
    # First a rollout that leaves the scratch data's tip 5 cm away, through the object's centre.
    far = state.copy()
    far[u.task.layout.mocap_pos : u.task.layout.mocap_pos + 2] = u.goal[:2]
    dyn.rollout(u.model, far[None], u.task.controls(far[None], np.zeros((1, 2, 2))), frame_skip=10)
    # Then the tip held still, 5 mm behind the object: nothing may move.
    out = dyn.rollout(u.model, state[None], u.task.controls(state[None], np.zeros((1, 5, 2))),
                      frame_skip=10)
    pose = u.task.object_pose(out[0])
    np.testing.assert_allclose(pose, np.repeat(u.task.object_pose(state)[None], 5, 0), atol=1e-6)


@pytest.mark.parametrize("kind", ["push", "toss"])
def test_learned_rollout_from_a_running_env_equals_its_own_single_steps(kind: str) -> None:
    dyn = FIGNetDynamics(quiet_simulator(kind))
    if kind == "push":
        env = running_push("fignet_gym/Push-v1", steps=3, dynamics=dyn)
        u = env.unwrapped
        state = u.get_state()
        control = u.task.controls(state[None], np.random.default_rng(0).uniform(-1, 1, (2, 4, 2)))
        frame_skip, nstep = u.frame_skip, None
    else:
        env = running_toss(dynamics=dyn)
        u = env.unwrapped
        state = u.task.release(u.get_state(), u.released, 0.3, np.zeros(2))
        frame_skip, nstep = u.settle_frame_skip, 4 * u.settle_frame_skip
        control = _rows(nstep, frame_skip)
    out = dyn.rollout(u.model, state[None], control, nstep=nstep, frame_skip=frame_skip)
    ctrl = control[0] if control is not None else np.zeros((4, 0))
    ref = rollout_loop(dyn, u.model, mujoco.MjData(u.model), state, ctrl, frame_skip)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out[0], ref, atol=1e-5)
    # the mocap part of the output is where the controls put the tip
    if control is not None:
        np.testing.assert_array_equal(u.task.layout.mocap(out[0]), control[0])


# ----------------------------------------------------------------------------- item 2: task API
def test_push_task_is_batched_and_agrees_with_the_env() -> None:
    env = running_push("fignet_gym/Push-v1")
    u = env.unwrapped
    rng = np.random.default_rng(4)
    states, rewards, success = [], [], []
    for _ in range(5):
        a = rng.uniform(-1, 1, 2)
        _, r, term, _, info = env.step(a)
        states.append(u.get_state())
        rewards.append((r, a))
        success.append(info["is_success"])
    batch = np.array(states)  # [5, nstate]
    acts = np.array([a for _, a in rewards])
    np.testing.assert_allclose(
        u.task.reward(batch, u.goal, acts), [r for r, _ in rewards], rtol=1e-12
    )
    assert u.task.is_success(batch, u.goal).tolist() == success
    # a hand-made success: the object exactly at the goal pose
    at_goal = batch[-1].copy()
    q = u.task.layout.qpos + u.task.qadr
    at_goal[q : q + 2] = u.goal[:2]
    at_goal[q + 3 : q + 7] = (np.cos(u.goal[2] / 2), 0, 0, np.sin(u.goal[2] / 2))
    assert u.task.is_success(at_goal, u.goal)
    assert u.task.reward_terms(at_goal, u.goal, np.zeros(2))["reward_success"] == 1.0
    lifted = at_goal.copy()
    lifted[q + 2] += 0.05
    assert u.task.out_of_workspace(np.stack([at_goal, lifted]), np.zeros(2)).tolist() == [
        False,
        True,
    ]


def test_tip_path_clips_actions_and_bounds() -> None:
    u = gym.make("fignet_gym/Push-v1").unwrapped
    step = u.task.max_speed * u.task.dt
    path = u.task.tip_path(np.array([0.0, 0.0]), np.array([[[2.0, -0.5], [1.0, 0.0]]]))
    np.testing.assert_allclose(path[0], [[step, -0.5 * step], [2 * step, -0.5 * step]])
    edge = u.task.tip_path(np.array([u.task.tip_bound, 0.0]), np.ones((1, 2)))
    assert edge[0, 0] == u.task.tip_bound


def test_toss_task_reward_agrees_with_the_env() -> None:
    env = running_toss()
    u = env.unwrapped
    k, before = u.released, u.task.in_target(u.get_state(), u.target, u.released)
    _, r, _, _, info = env.step(np.array([0.0, 0.1]))
    terms = u.task.reward_terms(u.get_state(), u.target, k, before)
    assert float(terms["reward_distance"] + terms["reward_in_target"]) == pytest.approx(r)
    assert u.task.in_target(u.get_state(), u.target, k + 1) == info["num_in_target"]


# ----------------------------------------------------------------------------- item 3: Push-v1
def test_push_v1_starts_behind_the_object_and_unsolved() -> None:
    env = gym.make("fignet_gym/Push-v1")
    u = env.unwrapped
    for seed in range(20):
        env.reset(seed=seed)
        s = u.get_state()
        obj = u.task.object_pose(s)[:2]
        to_goal, to_tip = u.goal[:2] - obj, u.task.tip_xy(s) - obj
        assert np.dot(to_goal, to_tip) < 0  # the tip is on the side away from the goal
        gap = np.linalg.norm(u.task.tip_xy(s) - u.task.pushing_point(s, u.goal))
        assert gap <= np.hypot(u.tip_gap, u.tip_jitter) + 1e-9
        assert 0.02 <= np.linalg.norm(to_goal) <= 0.05
        assert not u.task.is_success(s, u.goal)
    assert env.spec.max_episode_steps == 75 and env.spec.kwargs["tip_start"] == "behind"


# ----------------------------------------------------------------------------- item 4: planners
@pytest.mark.parametrize("planner_cls, config", [(CEMPlanner, TINY_CEM), (MPPIPlanner, TINY_MPPI)])
def test_planners_toss_one_release_per_decision(planner_cls: type, config: Any) -> None:
    env = gym.make("fignet_gym/Toss-v0", **TOSS_FAST)
    dyn = MujocoDynamics(nthread=1)
    planner = planner_cls(dyn, config)
    out = run_episode(env, planner, seed=0)
    assert out["length"] == 3 and 0 <= out["num_in_target"] <= 3
    assert planner.horizon == 1 and planner.plan_actions.shape == (1, 2)
    assert planner.last.evaluated == config.iterations * config.population


def test_toss_planning_beats_most_of_a_grid_of_releases() -> None:
    """Judged by MuJoCo against a brute-force 5 x 5 grid of releases: the planned one is in the
    best quarter."""
    env = gym.make("fignet_gym/Toss-v0", **TOSS_FAST)
    env.reset(seed=1)
    u = env.unwrapped
    dyn = MujocoDynamics(nthread=1)
    state = u.get_state()
    cfg = CEMConfig(horizon=1, population=12, elites=3, iterations=2, noise_std=1.0, seed=0)
    action = CEMPlanner(dyn, cfg, env=env).plan(env)
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-1, 1, 5)), -1).reshape(-1, 1, 2)
    problem = TossProblem(env)
    grid_cost = problem.evaluate(dyn, state, grid)[0]
    planned = float(problem.evaluate(dyn, state, action[None, None].astype(float))[0][0])
    assert planned <= np.quantile(grid_cost, 0.25)


def test_planner_works_with_sb3_evaluate_policy() -> None:
    env = gym.make("fignet_gym/Push-v1", max_episode_steps=4)
    planner = CEMPlanner(MujocoDynamics(nthread=1), TINY_CEM, env=env)
    rewards, lengths = evaluate_policy(
        planner, env, n_eval_episodes=2, deterministic=True, return_episode_rewards=True
    )
    assert lengths == [4, 4] and np.isfinite(rewards).all()
    with pytest.raises(ValueError, match="not the bound environment's"):
        planner.predict(np.zeros((1, 19), np.float32))


def test_planner_refuses_a_model_of_another_scene() -> None:
    env = gym.make("fignet_gym/Push-v1")
    toss_model = gym.make("fignet_gym/Toss-v0").unwrapped.model
    with pytest.raises(ValueError, match="does not match the environment's scene"):
        CEMPlanner(MujocoDynamics(), TINY_CEM, env=env, model=toss_model)
    # the same scene with another friction is fine
    other = gym.make("fignet_gym/Push-v1", friction=0.3).unwrapped.model
    CEMPlanner(MujocoDynamics(), TINY_CEM, env=env, model=other).plan(env)
    with pytest.raises(ValueError, match="cannot plan for TossEnv.*trained on 'push'"):
        CEMPlanner(FIGNetDynamics(zero_simulator("push")), TINY_CEM, env=gym.make("fignet_gym/Toss-v0"))


def test_replan_every_plays_the_plan_between_optimisations() -> None:
    env = running_push("fignet_gym/Push-v1", steps=0)
    cfg = CEMConfig(horizon=4, population=6, elites=2, iterations=1, replan_every=2, seed=0)
    planner = CEMPlanner(MujocoDynamics(nthread=1), cfg, env=env)
    first = planner.plan(env)
    plan = planner.plan_actions.copy()
    env.step(first)
    second = planner.plan(env)
    assert planner.last.evaluated == 0
    np.testing.assert_array_equal(second, plan[1].astype(np.float32))
    env.step(second)
    planner.plan(env)
    assert planner.last.evaluated == cfg.population


def test_whole_state_spec_is_what_planners_take() -> None:
    env = running_push("fignet_gym/Push-v1", steps=2)
    u = env.unwrapped
    assert u.get_state().shape == (mujoco.mj_stateSize(u.model, STATE_SPEC),)
    copy = gym.make("fignet_gym/Push-v1").unwrapped
    copy.reset(seed=0)
    copy.set_state(u.get_state())
    np.testing.assert_array_equal(copy.get_state(), u.get_state())


class CountingRollouts(MujocoDynamics):
    """MuJoCo, counting rollout calls and the candidates in each."""

    def __init__(self) -> None:
        super().__init__(nthread=1)
        self.batches: list[int] = []

    def rollout(self, model: Any, initial_state: Any, control: Any = None, nstep: Any = None,
                *, frame_skip: int = 1) -> np.ndarray:
        out = super().rollout(model, initial_state, control, nstep, frame_skip=frame_skip)
        self.batches.append(out.shape[0])
        return out


@pytest.mark.parametrize("env_id", ["fignet_gym/Push-v1", "fignet_gym/Toss-v0"])
@pytest.mark.parametrize("planner_cls, config", [(CEMPlanner, TINY_CEM), (MPPIPlanner, TINY_MPPI)])
def test_one_batched_rollout_per_iteration(env_id: str, planner_cls: type, config: Any) -> None:
    env = gym.make(env_id, **(TOSS_FAST if "Toss" in env_id else {}))
    env.reset(seed=0)
    dyn = CountingRollouts()
    planner_cls(dyn, config, env=env).plan(env)
    assert dyn.batches == [config.population] * config.iterations


# ----------------------------------------------------------------------------- the plan command
def test_plan_command_writes_summary_rows_and_videos(tmp_path: Any, capsys: Any) -> None:
    import json

    from fignet_gym.cli import main

    out = tmp_path / "plan"
    argv = ["plan", "--env", "fignet_gym/Push-v1", "--planner", "cem", "--episodes", "2",
            "--seed", "5", "--out", str(out), "--videos", "1", "--horizon", "2",
            "--population", "4", "--iterations", "1", "--replan-every", "1"]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [r["seed"] for r in summary["rows"]] == [5, 6]
    for key in ("success_rate", "median_position_error", "median_orientation_error"):
        assert key in summary
    assert set(summary["seconds_per_action"]) == {"wall", "cpu"}
    assert (out / "episode_5.mp4").stat().st_size > 0 and not (out / "episode_6.mp4").exists()
    assert "success" in capsys.readouterr().out
    # --resume skips finished episodes; a wrong id is one error line and exit code 2
    assert main([*argv[:6], "3", *argv[7:], "--resume"]) == 0
    rows = [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]
    assert [r["seed"] for r in rows] == [5, 6, 7]
    capsys.readouterr()  # drop the progress bars
    assert main(["plan", "--env", "fignet_gym/Nope-v0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --env: unknown environment")


class _NoTaskEnv(gym.Env):
    """A registered environment with no task to plan (takes ``plan``'s ``dynamics=``)."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, **kwargs: Any) -> None:
        self.kwargs = kwargs


@pytest.mark.parametrize("planner", ["cem", "random"])
def test_plan_command_refuses_an_env_without_a_planning_task(tmp_path: Any, capsys: Any,
                                                             planner: str) -> None:
    from fignet_gym.cli import main

    if "fignet_gym_test/NoTask-v0" not in gym.registry:
        gym.register("fignet_gym_test/NoTask-v0", entry_point=_NoTaskEnv)
    out = tmp_path / "plan"
    argv = ["plan", "--env", "fignet_gym_test/NoTask-v0", "--planner", planner, "--episodes",
            "1", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --env:") and "no task" in err[0]
    assert not out.exists()


def test_plan_command_checks_planner_settings_before_creating_out(tmp_path: Any,
                                                                  capsys: Any) -> None:
    from fignet_gym.cli import main

    out = tmp_path / "plan"
    assert main(["plan", "--env", "fignet_gym/Push-v1", "--horizon", "0", "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists()


def test_plan_print_table_takes_rows_without_task_keys(capsys: Any) -> None:
    from fignet_gym.tools.plan import print_table, summarize

    rows = [{"seed": 0, "length": 3, "return": 1.5, "plan_seconds": 0.1, "plan_cpu_seconds": 0.1,
             "diverged": False}]
    print_table("random", rows, summarize(rows))
    assert "mean return 1.50" in capsys.readouterr().out


def test_plan_resume_drops_a_partial_last_line(tmp_path: Any) -> None:
    import json

    from fignet_gym.tools.plan import PlanError, read_rows

    path = tmp_path / "episodes.jsonl"
    path.write_text(json.dumps({"seed": 0}) + "\n" + '{"seed": 1, "ret')
    assert read_rows(path) == [{"seed": 0}]
    assert path.read_text() == json.dumps({"seed": 0}) + "\n"
    path.write_text(json.dumps({"seed": 0}) + "\n" + json.dumps({"seed": 1}))  # cut before "\n"
    assert read_rows(path) == [{"seed": 0}, {"seed": 1}]
    assert path.read_text().endswith("}\n")
    path.write_text('{"seed": 0\n' + json.dumps({"seed": 1}) + "\n")  # damage mid-file: refuse
    with pytest.raises(PlanError, match="line 1"):
        read_rows(path)


@pytest.mark.parametrize(("planner_cls", "config"), [(CEMPlanner, TINY_CEM), (MPPIPlanner, TINY_MPPI)])
def test_prediction_is_dropped_when_every_candidate_diverges(planner_cls: type, config: Any) -> None:
    from dataclasses import replace

    env = gym.make("fignet_gym/Push-v1")
    env.reset(seed=0)
    planner = planner_cls(MujocoDynamics(), replace(config, replan_every=1), env=env)
    planner.plan(env)
    assert planner.prediction is not None
    planner.costs = lambda state, actions: (np.full(len(actions), np.inf), None)
    planner.plan(env)
    assert planner.prediction is None
