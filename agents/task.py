"""Planning problems: an environment's own task as the cost of candidate actions under any dynamics.

A planner proposes ``B`` action sequences ``float[B, T, A]``; a :class:`PlanningProblem` turns
them into **one** batched ``Dynamics.rollout`` call from the environment's whole state
(``env.get_state()``: full physics and mocap poses) and scores the predicted states with the
environment's task (:mod:`fignet_gym.envs.tasks`, the functions its ``step`` calls): the cost is
minus the reward ``env.step`` would return for the same states.

* :class:`PushProblem` (Push-v0/v1): ``T`` tip-velocity steps of ``frame_skip`` timesteps each,
  plus an optional shaping term drawing the final tip to the pushing point behind the object.
* :class:`TossProblem` (Toss-v0): one decision per release (``T = 1``); each candidate is the
  release of the next object followed by a whole settle of the scene (``settle_steps`` recorded
  states of ``frame_skip`` timesteps).
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from fignet_gym.dynamics import STATE_SPEC, DivergenceError, Dynamics
from fignet_gym.envs.base import MjDynamicsEnv
from fignet_gym.envs.push import PushEnv
from fignet_gym.envs.toss import TossEnv

#: State layout accepted by planners in place of an environment (``env.get_state()``).
PLAN_STATE_SPEC = STATE_SPEC


def plan_state(env: gym.Env) -> np.ndarray:
    """``float64[nstate]`` :data:`PLAN_STATE_SPEC` state of ``env`` (wrappers allowed)."""
    return _inner(env).get_state()


def _inner(env: gym.Env) -> MjDynamicsEnv:
    inner = getattr(env, "unwrapped", env)
    if not isinstance(inner, MjDynamicsEnv):
        raise TypeError(
            f"planners need a fignet_gym environment (Push-v0/v1, Toss-v0), got {type(inner).__name__}"
        )
    return inner


def check_same_scene(planning: mujoco.MjModel, acting: mujoco.MjModel) -> None:
    """``ValueError`` unless ``planning`` has ``acting``'s bodies, joints and mocap bodies (the
    same state layout), so that the env's states mean the same thing to the planning model."""
    def bodies(m: mujoco.MjModel) -> list[str]:
        return [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) or "" for i in range(m.nbody)]

    problems = []
    for field in ("nq", "nv", "nmocap", "nbody", "njnt"):
        a, b = getattr(planning, field), getattr(acting, field)
        if a != b:
            problems.append(f"{field} {a} vs {b}")
    if not problems and bodies(planning) != bodies(acting):
        problems.append(f"bodies {bodies(planning)} vs {bodies(acting)}")
    if problems:
        raise ValueError(
            "the planner's model does not match the environment's scene "
            f"({'; '.join(problems)}): plan with a model of the same scene"
        )


class PlanningProblem:
    """What a planner needs from an environment: its state, its action box, a batched cost.

    Args:
        env: the environment to plan for (wrappers allowed).
        model: the model to roll out (default: the env's); it must have the env's state layout.

    Attributes:
        env: the unwrapped environment. model: the planning model.
        action_dim: ``A``. horizon: the planned steps ``T`` (``None``: the planner's choice).
    """

    action_dim = 2
    horizon: int | None = None

    def __init__(self, env: gym.Env, model: mujoco.MjModel | None = None) -> None:
        self.env = _inner(env)
        self.model = self.env.model if model is None else model
        if model is not None:
            check_same_scene(model, self.env.model)

    def validate(self, dynamics: Dynamics) -> None:
        """``ValueError`` naming the env if ``dynamics`` cannot roll out this problem's model."""
        try:
            dynamics.validate(self.model, self.frame_skip, self.env.scene_type)
        except ValueError as err:
            raise ValueError(
                f"the planner's dynamics cannot plan for {type(self.env).__name__} "
                f"('{self.env.scene_type}' scene): {err}"
            ) from None

    @property
    def frame_skip(self) -> int:
        """MuJoCo timesteps per recorded rollout state."""
        return self.env.nstep

    def rollout(self, dynamics: Dynamics, state: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Predicted states ``float64[B, T', nstate]`` of candidates ``float[B, T, A]`` from
        ``state float64[nstate]``, in one ``dynamics.rollout`` call (NaN rows: diverged)."""
        raise NotImplementedError

    def costs(
        self, states: np.ndarray, actions: np.ndarray, shaping: float, terminal: float
    ) -> np.ndarray:
        """``float64[B]`` cost of predicted states ``float64[B, T', nstate]`` (non-finite where
        they are): minus their reward, ``terminal`` more times the last step's, plus ``shaping``
        times a task-specific shaping term."""
        raise NotImplementedError

    def evaluate(
        self,
        dynamics: Dynamics,
        state: np.ndarray,
        actions: np.ndarray,
        shaping: float = 0.0,
        terminal: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Costs ``float64[B]`` of candidates and their predicted states (``None`` when the
        dynamics raised :class:`DivergenceError`: every cost is then ``inf``)."""
        try:
            states = self.rollout(dynamics, state, actions)
        except DivergenceError:  # a user Dynamics may raise instead of returning NaN rows
            return np.full(len(actions), np.inf), None
        cost = self.costs(states, actions, shaping, terminal)
        cost[~np.isfinite(cost)] = np.inf
        return cost, states


class PushProblem(PlanningProblem):
    """Push-v0/v1: minus the env's reward summed over the predicted steps (``env.task``), plus
    ``shaping`` times the final tip's distance (m) to the pushing point behind the object."""

    env: PushEnv

    def __init__(self, env: gym.Env, model: mujoco.MjModel | None = None) -> None:
        super().__init__(env, model)
        if not isinstance(self.env, PushEnv):
            raise TypeError(f"PushProblem needs a Push environment, got {type(self.env).__name__}")

    def rollout(self, dynamics: Dynamics, state: np.ndarray, actions: np.ndarray) -> np.ndarray:
        control = self.env.task.controls(state[None], actions)
        return dynamics.rollout(self.model, state[None], control, frame_skip=self.frame_skip)

    def costs(
        self, states: np.ndarray, actions: np.ndarray, shaping: float, terminal: float
    ) -> np.ndarray:
        task, goal = self.env.task, self.env.goal
        reward = task.reward(states, goal, actions)
        cost = -reward.sum(axis=1) - terminal * reward[:, -1]
        if shaping:
            cost = cost + shaping * task.approach_distance(states[:, -1], goal)
        return cost


class TossProblem(PlanningProblem):
    """Toss-v0: one release per decision; the cost is minus the reward of that step (distance of
    the tossed object to the target, objects brought into or knocked out of it) after a whole
    settle, predicted from the released state."""

    env: TossEnv
    horizon = 1

    def __init__(self, env: gym.Env, model: mujoco.MjModel | None = None) -> None:
        super().__init__(env, model)
        if not isinstance(self.env, TossEnv):
            raise TypeError(f"TossProblem needs a Toss environment, got {type(self.env).__name__}")

    @property
    def frame_skip(self) -> int:
        return self.env.frame_skip

    def rollout(self, dynamics: Dynamics, state: np.ndarray, actions: np.ndarray) -> np.ndarray:
        env = self.env
        k = env.released
        if k >= env.task.num_objects:
            raise RuntimeError("every object was tossed: reset the environment")
        released = env.task.release(state[None], k, float(env.release_yaws[k]), actions[:, 0])
        # Only the settled state counts (a learned model still steps every 0.02 s).
        return dynamics.rollout(
            self.model, released, None, nstep=env.settle_steps * self.frame_skip,
            frame_skip=self.frame_skip,
        )[:, -1:]

    def costs(
        self, states: np.ndarray, actions: np.ndarray, shaping: float, terminal: float
    ) -> np.ndarray:
        env = self.env
        k = env.released
        before = env.task.in_target(env.get_state(), env.target, k)
        terms = env.task.reward_terms(states[:, -1], env.target, k, before)
        return -(terms["reward_distance"] + terms["reward_in_target"])


def problem_for(env: gym.Env, model: mujoco.MjModel | None = None) -> PlanningProblem:
    """The planning problem of a Push or Toss environment (``TypeError`` for another one)."""
    inner = _inner(env)
    if isinstance(inner, PushEnv):
        return PushProblem(inner, model)
    if isinstance(inner, TossEnv):
        return TossProblem(inner, model)
    raise TypeError(f"no planning problem for {type(inner).__name__}: Push or Toss environments")
