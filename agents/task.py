"""Planning problems: an environment's own task as the cost of candidate actions under any dynamics.

A planner proposes ``B`` action sequences ``float[B, T, A]`` in ``[-1, 1]``; a
:class:`PlanningProblem` maps them onto the environment's ``action_space``, turns them into **one**
batched ``Dynamics.rollout`` call from the environment's whole state (``env.get_state()``: full
physics, mocap poses and the pose history) and scores the predicted states with the environment's
task (``env.task``, a :class:`fignet_gym.envs.tasks.Task`: the functions its ``step`` calls): the
cost is minus the reward ``env.step`` would return for the same states.

Nothing here knows an environment: any environment with ``task`` (a ``Task``),
``task_context()``, ``get_state()``, ``model`` and a ``Box`` ``action_space`` plans, the fignet_gym
ones (Push, Toss, CubeToss) and a user's own alike.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

from fignet_gym.dynamics import STATE_SPEC, DivergenceError, Dynamics
from fignet_gym.envs.tasks import Task

#: State layout accepted by planners in place of an environment (``env.get_state()``).
PLAN_STATE_SPEC = STATE_SPEC


def plan_state(env: gym.Env) -> np.ndarray:
    """``float64[nstate]`` :data:`PLAN_STATE_SPEC` state of ``env`` (wrappers allowed)."""
    return _inner(env).get_state()


def _inner(env: gym.Env) -> gym.Env:
    inner = getattr(env, "unwrapped", env)
    missing = [m for m in ("task", "task_context", "get_state", "model", "action_space")
               if not hasattr(inner, m)]
    if missing or not isinstance(getattr(inner, "task", None), Task):
        raise TypeError(
            f"planners need an environment that exposes its task (env.task: a "
            f"fignet_gym.envs.tasks.Task, env.task_context(), env.get_state(), env.model): "
            f"{type(inner).__name__} lacks {', '.join(missing) or 'a Task as env.task'}"
        )
    if not isinstance(inner.action_space, gym.spaces.Box) or len(inner.action_space.shape) != 1:
        raise TypeError(f"planners need a 1-D Box action space, got {inner.action_space}")
    return inner


def check_same_scene(planning: mujoco.MjModel, acting: mujoco.MjModel) -> None:
    """``ValueError`` unless ``planning`` has ``acting``'s bodies, joints and mocap bodies (the
    same state layout), so that the env's states mean the same thing to the planning model."""
    def bodies(m: mujoco.MjModel) -> list[str]:
        return [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) or "" for i in range(m.nbody)]

    problems = []
    for field in ("nq", "nv", "nmocap", "nbody", "njnt", "nuserdata"):
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
        env: the environment to plan for (wrappers allowed; see the module docstring).
        model: the model to roll out (default: the env's); it must have the env's state layout.

    Attributes:
        env: the unwrapped environment. model: the planning model. task: ``env.task``.
        action_dim: ``A``, from ``env.action_space``. horizon: the planned steps ``T`` (``None``:
        the planner's choice; the task's ``plan_horizon``).
    """

    def __init__(self, env: gym.Env, model: mujoco.MjModel | None = None) -> None:
        self.env = _inner(env)
        self.model = self.env.model if model is None else model
        if model is not None:
            check_same_scene(model, self.env.model)
        self.task: Task = self.env.task
        space = self.env.action_space
        self.action_dim = int(space.shape[0])
        self.horizon = self.task.plan_horizon
        self.low = np.asarray(space.low, dtype=np.float64)
        self.high = np.asarray(space.high, dtype=np.float64)
        if not (np.isfinite(self.low).all() and np.isfinite(self.high).all()):
            raise TypeError(f"planners need a bounded action space, got {space}")

    def validate(self, dynamics: Dynamics) -> None:
        """``ValueError`` naming the env if ``dynamics`` cannot roll out this problem's model."""
        scene = getattr(self.env, "scene_type", "")
        try:
            dynamics.validate(self.model, self.frame_skip, scene)
        except ValueError as err:
            raise ValueError(
                f"the planner's dynamics cannot plan for {type(self.env).__name__} "
                f"('{scene}' scene): {err}"
            ) from None

    @property
    def frame_skip(self) -> int:
        """MuJoCo timesteps per environment step."""
        return int(self.env.task_context()["frame_skip"])

    def to_action(self, u: np.ndarray) -> np.ndarray:
        """Planner space ``float[..., A]`` in ``[-1, 1]`` -> the env's action box."""
        u = np.clip(np.asarray(u, dtype=np.float64), -1.0, 1.0)
        return self.low + (u + 1.0) / 2.0 * (self.high - self.low)

    def rollout(self, dynamics: Dynamics, state: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Predicted states ``float64[B, T', nstate]`` of candidates ``float[B, T, A]`` (planner
        space) from ``state float64[nstate]``, in one ``dynamics.rollout`` call."""
        return self.task.plan_rollout(dynamics, self.model, state, self.to_action(actions),
                                      **self.env.task_context())

    def costs(self, state: np.ndarray, states: np.ndarray, actions: np.ndarray, shaping: float,
              terminal: float) -> np.ndarray:
        """``float64[B]`` cost of predicted states (see ``Task.plan_cost``)."""
        return self.task.plan_cost(state, states, self.to_action(actions), shaping, terminal,
                                   **self.env.task_context())

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
        with np.errstate(invalid="ignore"):
            cost = np.asarray(self.costs(state, states, actions, shaping, terminal), dtype=float)
        cost[~np.isfinite(cost)] = np.inf
        return cost, states


#: Former per-environment problems: every environment now has the one generic problem.
PushProblem = TossProblem = PlanningProblem


def problem_for(env: gym.Env, model: mujoco.MjModel | None = None) -> PlanningProblem:
    """The planning problem of an environment that exposes its task (``TypeError`` otherwise)."""
    return PlanningProblem(env, model)
