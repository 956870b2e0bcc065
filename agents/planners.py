"""Sampling-based model-predictive control for Push-v0 through any :class:`Dynamics`.

Every call of :meth:`SamplingPlanner.plan` scores ``population`` tip-velocity sequences of
``horizon`` steps with **one** ``dynamics.rollout`` call per iteration (all candidates as one batch:
one batched graph per learned step for FIGNet, ``mujoco.rollout``'s threads for MuJoCo), refits the
sampling distribution and returns the first action (receding horizon). The next call starts from
the previous plan shifted by one step (warm start).

The cost of a candidate is minus the environment's own reward summed over the predicted steps
(through :class:`~fignet_gym.agents.task.PushTask`), plus an optional shaping term that draws the
tip towards the pushing point behind the object (``approach_weight``, cost per metre). Candidates
whose rollout diverged (NaN rows, or a :class:`DivergenceError`) cost ``inf`` and are never chosen;
if every candidate diverged the planner keeps its previous plan.

    planner = CEMPlanner(FIGNetDynamics("push"), CEMConfig(horizon=10, population=64))
    stats = run_episode(gym.make("fignet_gym/Push-v0"), planner, seed=0)  # plan learned, act MuJoCo
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from fignet_gym.agents.task import PushTask, push_env_of
from fignet_gym.dynamics import DivergenceError, Dynamics


@dataclass(frozen=True)
class CEMConfig:
    """Cross-entropy method settings.

    Args:
        horizon: planned steps ``T`` (environment steps of ``frame_skip`` timesteps).
        population: candidate sequences ``B`` per iteration (one of them is the current mean).
        elites: best candidates the Gaussian is refitted to.
        iterations: refits per planning step.
        noise_std: initial standard deviation (action units) of every step and axis.
        min_std: floor of the refitted standard deviation (keeps exploring).
        approach_weight: cost per metre between the final tip and the pushing point (0: the
            environment's reward alone).
        seed: of the sampling generator (``reset`` restarts it).
    """

    horizon: int = 10
    population: int = 64
    elites: int = 8
    iterations: int = 3
    noise_std: float = 0.5
    min_std: float = 0.05
    approach_weight: float = 100.0
    seed: int = 0

    def __post_init__(self) -> None:
        _check_common(self.horizon, self.population, self.iterations, self.noise_std)
        if not 1 <= self.elites <= self.population:
            raise ValueError(f"elites must be in [1, population], got {self.elites}")
        if self.min_std < 0:
            raise ValueError(f"min_std must be >= 0, got {self.min_std}")


@dataclass(frozen=True)
class MPPIConfig:
    """Model-predictive path integral settings.

    Args:
        horizon: planned steps ``T``.
        population: candidate sequences ``B`` per iteration (one of them is the current plan).
        iterations: weighted updates per planning step.
        temperature: ``lambda`` of the weights ``exp(-(cost - min cost) / lambda)``, in cost
            units (minus summed reward; one centimetre of position error for one step is 0.1).
        noise_std: standard deviation (action units) of the perturbations.
        approach_weight: cost per metre between the final tip and the pushing point.
        seed: of the sampling generator.
    """

    horizon: int = 10
    population: int = 64
    iterations: int = 2
    temperature: float = 0.05
    noise_std: float = 0.5
    approach_weight: float = 100.0
    seed: int = 0

    def __post_init__(self) -> None:
        _check_common(self.horizon, self.population, self.iterations, self.noise_std)
        if self.temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {self.temperature}")


def _check_common(horizon: int, population: int, iterations: int, noise_std: float) -> None:
    if horizon < 1 or population < 2 or iterations < 1:
        raise ValueError(
            f"need horizon >= 1, population >= 2, iterations >= 1; got {horizon}, {population}, {iterations}"
        )
    if noise_std <= 0:
        raise ValueError(f"noise_std must be > 0, got {noise_std}")


@dataclass(frozen=True)
class PlanInfo:
    """What the last :meth:`SamplingPlanner.plan` did.

    Attributes:
        cost: cheapest candidate cost of the call (CEM: the returned plan's; ``inf`` if every
            candidate diverged).
        diverged: candidates (over all iterations) whose rollout diverged.
        evaluated: candidates evaluated.
        seconds: wall time of the call.
    """

    cost: float
    diverged: int
    evaluated: int
    seconds: float


class SamplingPlanner:
    """Shared machinery of :class:`CEMPlanner` and :class:`MPPIPlanner`.

    Args:
        dynamics: predicts the candidates' outcomes (any :class:`Dynamics`; it need not be the
            acting environment's).
        config: the algorithm's settings.
        env: optionally, the Push-v0 environment to plan for (else bound by the first ``plan``).

    Attributes:
        plan_actions: ``float64[T, 2]`` the current plan (after ``plan``: its first row was
            returned); the next ``plan`` starts from it shifted by one step.
        last: :class:`PlanInfo` of the last call.
    """

    #: The settings type of a subclass (its default configuration when none is given).
    config_class: type[CEMConfig] | type[MPPIConfig]

    def __init__(
        self, dynamics: Dynamics, config: CEMConfig | MPPIConfig | None = None,
        env: gym.Env | None = None,
    ) -> None:
        self.dynamics = dynamics
        self.config = config or self.config_class()
        self.task: PushTask | None = None
        self.last: PlanInfo | None = None
        self.reset()
        if env is not None:
            self.bind(env)

    def reset(self, seed: int | None = None) -> None:
        """Forget the plan (new episode) and restart the generator (``seed``: else the config's)."""
        self.rng = np.random.default_rng(self.config.seed if seed is None else seed)
        self.plan_actions = np.zeros((self.config.horizon, 2))
        self._fresh = True

    def bind(self, env: gym.Env) -> None:
        """Plan for ``env`` (a Push-v0 environment, wrappers allowed) from now on."""
        push = push_env_of(env)
        if self.task is None or self.task.env is not push:
            self.dynamics.validate(push.model, push.nstep, push.scene_type)
            self.task = PushTask(push)

    def plan(self, env_or_state: gym.Env | np.ndarray) -> np.ndarray:
        """The first action of a new plan.

        Args:
            env_or_state: the environment (plans from its current state and binds it), or a
                ``float64[nstate]`` ``mjSTATE_INTEGRATION`` state (``fignet_gym.agents.plan_state``)
                of the bound environment's model; the goal is the bound environment's.

        Returns:
            ``float32[2]`` tip-velocity action in ``[-1, 1]``, always finite.
        """
        start = time.perf_counter()
        if isinstance(env_or_state, np.ndarray):
            if self.task is None:
                raise RuntimeError("plan(state) needs an environment first: bind(env) or plan(env)")
            state = env_or_state
        else:
            self.bind(env_or_state)
            state = None
        assert self.task is not None
        phys, mocap = self.task.load(state)
        if not self._fresh:  # warm start: the previous plan, one step on, its last step repeated
            self.plan_actions = np.concatenate([self.plan_actions[1:], self.plan_actions[-1:]])
        self._fresh = False
        cost, diverged, evaluated = self._optimise(phys, mocap)
        self.last = PlanInfo(cost, diverged, evaluated, time.perf_counter() - start)
        return self.plan_actions[0].astype(np.float32)

    def _optimise(self, phys: np.ndarray, mocap: np.ndarray) -> tuple[float, int, int]:
        """Update :attr:`plan_actions`; returns its cost, diverged and evaluated candidates."""
        raise NotImplementedError

    def _sample(self, mean: np.ndarray, std: np.ndarray | float) -> np.ndarray:
        """``float64[B, T, 2]`` candidates in ``[-1, 1]``: ``mean`` first, then Gaussian samples."""
        cfg = self.config
        noise = self.rng.standard_normal((cfg.population - 1, cfg.horizon, 2))
        samples = np.clip(mean + std * noise, -1.0, 1.0)
        return np.concatenate([mean[None], samples])

    def _scored_samples(self, mean: np.ndarray, std: np.ndarray | float, phys: np.ndarray,
                        mocap: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Candidates around ``mean``, their costs and which are finite:
        ``(float64[B, T, 2], float64[B], bool[B])``."""
        actions = self._sample(mean, std)
        cost = self.costs(phys, mocap, actions)
        return actions, cost, np.isfinite(cost)

    def costs(self, phys: np.ndarray, mocap: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Cost of candidate action sequences, from one batched rollout.

        Args:
            phys: ``float64[nphys]`` initial ``mjSTATE_FULLPHYSICS`` state.
            mocap: ``float64[nmocap * 7]`` initial mocap poses.
            actions: ``float[B, T, 2]``.

        Returns:
            ``float64[B]``: minus the summed environment reward, plus ``approach_weight`` times
            the final tip's distance to the pushing point; ``inf`` for diverged rollouts.
        """
        assert self.task is not None
        task = self.task
        control, applied = task.controls(mocap, actions)
        try:
            states = self.dynamics.rollout(task.model, phys[None], control, frame_skip=task.nstep)
        except DivergenceError:  # a user Dynamics may raise instead of returning NaN rows
            return np.full(len(actions), np.inf)
        cost = -task.rewards(states, control, applied).sum(axis=1)
        if self.config.approach_weight:
            cost += self.config.approach_weight * task.approach_distance(states, control)
        cost[~np.isfinite(cost)] = np.inf
        return cost


class CEMPlanner(SamplingPlanner):
    """Cross-entropy method: refit a diagonal Gaussian to the ``elites`` cheapest candidates.

    Returns the first action of the cheapest candidate seen in this call (the previous plan is
    always among the candidates, so a plan never gets worse under the model by replanning).

    Args:
        dynamics: any :class:`Dynamics`. config: :class:`CEMConfig`. env: optional Push-v0 env.
    """

    config: CEMConfig
    config_class = CEMConfig

    def _optimise(self, phys: np.ndarray, mocap: np.ndarray) -> tuple[float, int, int]:
        cfg = self.config
        mean = self.plan_actions.copy()
        std = np.full_like(mean, cfg.noise_std)
        best, best_cost, diverged = mean, np.inf, 0
        for _ in range(cfg.iterations):
            actions, cost, finite = self._scored_samples(mean, std, phys, mocap)
            ok = np.flatnonzero(finite)
            diverged += len(cost) - len(ok)
            if not len(ok):
                continue  # nothing to learn from: resample around the same distribution
            order = ok[np.argsort(cost[ok], kind="stable")]
            if cost[order[0]] < best_cost:
                best, best_cost = actions[order[0]], float(cost[order[0]])
            elite = actions[order[: cfg.elites]]
            mean, std = elite.mean(0), np.maximum(elite.std(0), cfg.min_std)
        self.plan_actions = best.copy()
        return best_cost, diverged, cfg.iterations * cfg.population


class MPPIPlanner(SamplingPlanner):
    """Model-predictive path integral control: the plan is the exponentially weighted mean.

    Weights are ``exp(-(cost - min cost) / temperature)`` over the finite-cost candidates; the
    returned action is the first step of the weighted mean (clipped to ``[-1, 1]``).

    Args:
        dynamics: any :class:`Dynamics`. config: :class:`MPPIConfig`. env: optional Push-v0 env.
    """

    config: MPPIConfig
    config_class = MPPIConfig

    def _optimise(self, phys: np.ndarray, mocap: np.ndarray) -> tuple[float, int, int]:
        cfg = self.config
        mean, best_cost, diverged = self.plan_actions.copy(), np.inf, 0
        for _ in range(cfg.iterations):
            actions, cost, ok = self._scored_samples(mean, cfg.noise_std, phys, mocap)
            diverged += int((~ok).sum())
            if not ok.any():
                continue
            lowest = float(cost[ok].min())
            best_cost = min(best_cost, lowest)
            # Shifting by the minimum keeps exp() in range; diverged candidates get weight 0.
            w = np.zeros(len(cost))
            w[ok] = np.exp(-(cost[ok] - lowest) / cfg.temperature)
            mean = np.einsum("b,btk->tk", w / w.sum(), actions)
        self.plan_actions = np.clip(mean, -1.0, 1.0)
        return best_cost, diverged, cfg.iterations * cfg.population


def run_episode(
    env: gym.Env, planner: SamplingPlanner, seed: int | None = None, max_steps: int | None = None
) -> dict[str, Any]:
    """One Push-v0 episode acted in ``env`` with ``planner`` replanning every step.

    The planner's dynamics may differ from the environment's (plan with FIGNet, act with MuJoCo).

    Args:
        env: a Push-v0 environment (``gym.make`` adds the 50-step limit).
        planner: reset (with its config's seed) and bound to ``env`` first.
        seed: of ``env.reset``.
        max_steps: stop after this many steps even if the episode has not ended.

    Returns:
        ``{"return", "length", "is_success", "position_error" (m), "orientation_error" (rad),
        "diverged" (the acting env's dynamics blew up), "plan_seconds" (mean per step),
        "diverged_candidates" (fraction of planned rollouts that diverged)}``.
    """
    env.reset(seed=seed)
    planner.reset()
    planner.bind(env)
    total, length, seconds, bad, evaluated = 0.0, 0, 0.0, 0, 0
    info: dict[str, Any] = {}
    done = False
    while not done and (max_steps is None or length < max_steps):
        action = planner.plan(env)
        assert planner.last is not None
        seconds += planner.last.seconds
        bad += planner.last.diverged
        evaluated += planner.last.evaluated
        _, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        length += 1
        done = terminated or truncated
    return {
        "return": total,
        "length": length,
        "is_success": bool(info.get("is_success", False)),
        "position_error": float(info.get("position_error", np.nan)),
        "orientation_error": float(info.get("orientation_error", np.nan)),
        "diverged": "diverged" in info,
        "plan_seconds": seconds / max(length, 1),
        "diverged_candidates": bad / max(evaluated, 1),
    }
