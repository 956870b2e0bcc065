"""Sampling-based model-predictive control (CEM, MPPI) of any task through any :class:`Dynamics`.

Every call of :meth:`SamplingPlanner.plan` scores ``population`` action sequences of ``horizon``
steps with **one** ``dynamics.rollout`` call per iteration (all candidates as one batch: one
batched graph per learned step for FIGNet, ``mujoco.rollout``'s threads for MuJoCo), refits the
sampling distribution and returns the first action (receding horizon). The next call starts from
the previous plan shifted by one step (warm start). Candidates are sampled in ``[-1, 1]^A`` and
mapped onto the env's ``action_space``. On one-shot tasks (Toss-v0, CubeToss-v0: the task's
``plan_horizon`` is 1) a plan is one release and each candidate's rollout its whole settle.

The cost of a candidate is minus the environment's own reward over the predicted states (through
:mod:`~fignet_gym.agents.task`, which calls the env's task functions), plus on Push an optional
shaping term that draws the tip towards the pushing point behind the object (``approach_weight``,
cost per metre). Candidates whose rollout diverged (NaN rows, or a :class:`DivergenceError`) cost
``inf`` and are never chosen; if every candidate diverged the planner keeps its previous plan.

Planners follow stable-baselines3's policy interface: ``predict(obs, state, episode_start,
deterministic) -> (action, state)``, so ``stable_baselines3.common.evaluation.evaluate_policy``
runs them; they plan from the bound environment's whole state, not from ``obs``. As in SB3,
``deterministic=True`` returns the plan's action (the mode) and ``False`` (SB3's default) a draw
from the planner's final sampling distribution around it.

    planner = CEMPlanner(FIGNetDynamics("push"), CEMConfig(horizon=8, population=48))
    stats = run_episode(gym.make("fignet_gym/Push-v1"), planner, seed=0)  # plan learned, act MuJoCo

Why not ``pytorch-mppi``: its ``MPPI`` calls a one-step ``dynamics(state[K, nx], action[K, nu])``
``horizon`` times per iteration. A FIGNet step needs the object's pose history, which a state
vector would carry only as velocities (reseeding the history every step changes the model's
predictions), and one rollout call per iteration (not per step) is what makes MuJoCo's threaded
rollout and FIGNet's batched graph cheap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from fignet_gym.agents.task import PlanningProblem, problem_for
from fignet_gym.checks import Range, SettingError, check_settings
from fignet_gym.dynamics import STATE_SPEC, Dynamics

#: Allowed values of the sampling settings both planner configs share (and ``replan_every`` at
#: most ``horizon``).
SAMPLING_RANGES: dict[str, Range] = {
    "horizon": Range("int", low=1),
    "population": Range("int", low=2),
    "iterations": Range("int", low=1),
    "replan_every": Range("int", low=1),
    "noise_std": Range("float", low=0, low_open=True),
    "noise_correlation": Range("float", 0, 1, high_open=True),
}
#: :class:`CEMConfig`'s (and ``elites`` at most ``population``).
CEM_RANGES: dict[str, Range] = {**SAMPLING_RANGES, "elites": Range("int", low=1),
                                "min_std": Range("float", low=0)}
#: :class:`MPPIConfig`'s.
MPPI_RANGES: dict[str, Range] = {**SAMPLING_RANGES, "temperature": Range("float", low=0, low_open=True)}


@dataclass(frozen=True)
class CEMConfig:
    """Cross-entropy method settings.

    Args:
        horizon: planned steps ``T`` (environment steps of ``frame_skip`` timesteps; 1 on Toss).
        population: candidate sequences ``B`` per iteration (one of them is the current mean).
        elites: best candidates the Gaussian is refitted to.
        iterations: refits per planning step.
        noise_std: initial standard deviation (action units) of every step and axis.
        noise_correlation: correlation ``rho`` of the sampling noise between consecutive steps
            (AR(1): smooth candidates that keep pushing one way, as iCEM's coloured noise).
        min_std: floor of the refitted standard deviation (keeps exploring).
        approach_weight: cost per metre between the final tip and the pushing point (0: the
            environment's reward alone).
        terminal_weight: the last predicted step's cost counted this many more times (as if the
            final state were held that long): a short horizon otherwise prefers not to start a
            push whose first steps turn the object.
        replan_every: optimise every this many actions and play the plan's next actions in
            between (1: classic receding horizon); divides the planning cost per action.
        seed: of the sampling generator (``reset`` restarts it).
    """

    horizon: int = 10
    population: int = 48
    elites: int = 6
    iterations: int = 2
    noise_std: float = 0.5
    noise_correlation: float = 0.0
    min_std: float = 0.05
    approach_weight: float = 100.0
    terminal_weight: float = 0.0
    replan_every: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        check_settings(self, CEM_RANGES)
        _check_replan(self)
        if self.elites > self.population:
            raise SettingError("elites", f"must be in [1, population], got {self.elites}")


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
        noise_correlation: correlation of the perturbations between consecutive steps (AR(1)).
        approach_weight: cost per metre between the final tip and the pushing point.
        terminal_weight: the last predicted step's cost counted this many more times.
        replan_every: optimise every this many actions (see :class:`CEMConfig`).
        seed: of the sampling generator.
    """

    horizon: int = 10
    population: int = 48
    iterations: int = 2
    temperature: float = 0.05
    noise_std: float = 0.5
    noise_correlation: float = 0.0
    approach_weight: float = 100.0
    terminal_weight: float = 0.0
    replan_every: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        check_settings(self, MPPI_RANGES)
        _check_replan(self)


def _check_replan(config: CEMConfig | MPPIConfig) -> None:
    """:class:`~fignet_gym.checks.SettingError` unless ``replan_every`` is at most ``horizon``."""
    if config.replan_every > config.horizon:
        raise SettingError("replan_every", f"must be in [1, horizon], got {config.replan_every}")


@dataclass(frozen=True)
class PlanInfo:
    """What the last :meth:`SamplingPlanner.plan` did.

    Attributes:
        cost: cheapest candidate cost of the call (CEM: the returned plan's; ``inf`` if every
            candidate diverged).
        diverged: candidates (over all iterations) whose rollout diverged.
        evaluated: candidates evaluated.
        seconds: wall time of the call. cpu_seconds: CPU time of the process during the call
            (every thread).
    """

    cost: float
    diverged: int
    evaluated: int
    seconds: float
    cpu_seconds: float


class SamplingPlanner:
    """Shared machinery of :class:`CEMPlanner` and :class:`MPPIPlanner`.

    Args:
        dynamics: predicts the candidates' outcomes (any :class:`Dynamics`; it need not be the
            acting environment's).
        config: the algorithm's settings.
        env: optionally, the environment to plan for (else bound by the first ``plan``).
        model: optionally, the ``MjModel`` to roll out (default: the env's); it must have the
            env's bodies and joints (``ValueError`` otherwise), e.g. the same scene with other
            friction.

    Attributes:
        plan_actions: ``float64[T, A]`` the current plan (after ``plan``: its first row was
            returned); the next ``plan`` starts from it shifted by one step.
        prediction: ``float64[T', nstate]`` the planning model's predicted states of the chosen
            candidate (``None`` before a plan or when every candidate of the last optimisation
            diverged). MPPI: the lowest-cost sample's, not the executed weighted-mean plan's.
        last: :class:`PlanInfo` of the last call.
    """

    #: The settings type of a subclass (its default configuration when none is given).
    config_class: type[CEMConfig] | type[MPPIConfig]

    def __init__(
        self,
        dynamics: Dynamics,
        config: CEMConfig | MPPIConfig | None = None,
        env: gym.Env | None = None,
        model: mujoco.MjModel | None = None,
    ) -> None:
        self.dynamics = dynamics
        self.config = config or self.config_class()
        self.model = model
        self.problem: PlanningProblem | None = None
        self.last: PlanInfo | None = None
        self.prediction: np.ndarray | None = None
        self._horizon = self.config.horizon
        self._action_dim = 0  # known once bound: the env's action space
        self.reset()
        if env is not None:
            self.bind(env)

    @property
    def horizon(self) -> int:
        """Planned steps ``T`` (the config's, or the problem's own: 1 on Toss)."""
        return self._horizon

    def reset(self, seed: int | None = None) -> None:
        """Forget the plan (new episode) and restart the generator (``seed``: else the config's)."""
        self.rng = np.random.default_rng(self.config.seed if seed is None else seed)
        self.plan_actions = np.zeros((self._horizon, self._action_dim))
        self.action_std = np.full_like(self.plan_actions, self.config.noise_std)
        self.prediction = None
        self._fresh = True
        self._played = 0  # actions of the current plan already returned

    def bind(self, env: gym.Env) -> None:
        """Plan for ``env`` (any env exposing its task, wrappers allowed) from now on.

        Raises ``ValueError`` if the planning dynamics or model do not fit the env's scene.
        """
        inner = getattr(env, "unwrapped", env)
        if self.problem is None or self.problem.env is not inner:
            problem = problem_for(inner, self.model)
            problem.validate(self.dynamics)
            self.problem = problem
            horizon = problem.horizon or self.config.horizon
            if (horizon, problem.action_dim) != (self._horizon, self._action_dim):
                self._horizon, self._action_dim = horizon, problem.action_dim
                self.reset()

    def plan(self, env_or_state: gym.Env | np.ndarray) -> np.ndarray:
        """The first action of a new plan.

        Args:
            env_or_state: the environment (plans from its current state and binds it), or a
                ``float64[nstate]`` state (``env.get_state()``, ``fignet_gym.agents.plan_state``)
                of the bound environment's model; the goal is the bound environment's.

        Returns:
            ``float32[A]`` action in the env's ``action_space``, always finite.
        """
        start, cpu = time.perf_counter(), time.process_time()
        if isinstance(env_or_state, np.ndarray):
            if self.problem is None:
                raise RuntimeError("plan(state) needs an environment first: bind(env) or plan(env)")
            state = np.asarray(env_or_state, dtype=np.float64)
            expected = mujoco.mj_stateSize(self.problem.env.model, STATE_SPEC)
            if state.shape != (expected,):
                raise ValueError(
                    f"state must be float64[{expected}] (STATE_SPEC: env.get_state()), "
                    f"got shape {state.shape}"
                )
        else:
            self.bind(env_or_state)
            assert self.problem is not None
            state = self.problem.env.get_state()
        every = min(self.config.replan_every, self._horizon)
        if self._fresh or self._played >= every:
            if not self._fresh:  # warm start: the previous plan shifted, its last step repeated
                n = self._played
                self.plan_actions = np.concatenate(
                    [self.plan_actions[n:], np.repeat(self.plan_actions[-1:], n, axis=0)]
                )
            self._fresh = False
            self._played = 0
            cost, diverged, evaluated = self._optimise(state)
        else:  # play the plan on: no optimisation this step
            cost, diverged, evaluated = self.last.cost if self.last else np.inf, 0, 0
        action = self.problem.to_action(self.plan_actions[self._played]).astype(np.float32)
        self._played += 1
        self.last = PlanInfo(
            cost, diverged, evaluated, time.perf_counter() - start, time.process_time() - cpu
        )
        return action

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """stable-baselines3's policy interface: the action for the bound environment's state.

        Args:
            observation: ``float[D]`` or ``float[1, D]`` (one environment): must be the bound
                environment's current observation (``ValueError`` otherwise: a planner plans
                from the environment's whole state, which the observation only summarises).
            state: passed through (no recurrent state).
            episode_start: ``bool[1]``; true resets the plan (a new episode).
            deterministic: ``True``: the plan's action; ``False`` (SB3's default): a draw from
                the planner's last sampling distribution around it (per-dimension ``std``:
                CEM's refitted one, MPPI's ``noise_std``), clipped to the action space.

        Returns:
            ``float32[A]`` or ``float32[1, A]`` (as ``observation``), and ``state``.
        """
        if self.problem is None:
            raise RuntimeError("predict needs an environment: pass env= or call bind(env) first")
        obs = np.asarray(observation, dtype=np.float32)
        batched = obs.ndim == 2
        if batched and obs.shape[0] != 1:
            raise ValueError(f"planners control one environment, got {obs.shape[0]} observations")
        if episode_start is not None and bool(np.asarray(episode_start).ravel()[0]):
            self.reset()
        current = self.problem.env.observe()
        if obs.reshape(-1).shape != current.shape or not np.allclose(
            obs.reshape(-1), current, atol=1e-5
        ):
            raise ValueError(
                "predict: the observation is not the bound environment's current one "
                "(bind the planner to the environment being evaluated)"
            )
        action = self.plan(self.problem.env)
        if not deterministic:
            std = self.action_std[min(self._played - 1, len(self.action_std) - 1)]
            u = self.plan_actions[self._played - 1] + std * self.rng.standard_normal(std.shape)
            action = self.problem.to_action(u).astype(np.float32)
        return (action[None] if batched else action), state

    def _optimise(self, state: np.ndarray) -> tuple[float, int, int]:
        """Update :attr:`plan_actions`; returns its cost, diverged and evaluated candidates."""
        raise NotImplementedError

    def _sample(self, mean: np.ndarray, std: np.ndarray | float) -> np.ndarray:
        """``float64[B, T, A]`` candidates in ``[-1, 1]``: ``mean`` first, then Gaussian samples."""
        cfg = self.config
        noise = self.rng.standard_normal((cfg.population - 1, *mean.shape))
        rho = cfg.noise_correlation
        for t in range(1, mean.shape[0]):  # AR(1) along the horizon, unit variance per step
            noise[:, t] = rho * noise[:, t - 1] + np.sqrt(1.0 - rho**2) * noise[:, t]
        samples = np.clip(mean + std * noise, -1.0, 1.0)
        return np.concatenate([mean[None], samples])

    def costs(self, state: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Cost ``float64[B]`` of candidates ``float[B, T, A]`` from ``state float64[nstate]``,
        from one batched rollout, and the predicted states (``inf`` / ``None``: diverged)."""
        assert self.problem is not None
        cfg = self.config
        return self.problem.evaluate(
            self.dynamics, state, actions, cfg.approach_weight, cfg.terminal_weight
        )


class CEMPlanner(SamplingPlanner):
    """Cross-entropy method: refit a diagonal Gaussian to the ``elites`` cheapest candidates.

    Returns the first action of the cheapest candidate seen in this call (the previous plan is
    always among the candidates, so a plan never gets worse under the model by replanning).

    Args:
        dynamics: any :class:`Dynamics`. config: :class:`CEMConfig`. env, model: see
            :class:`SamplingPlanner`.
    """

    config: CEMConfig
    config_class = CEMConfig

    def _optimise(self, state: np.ndarray) -> tuple[float, int, int]:
        cfg = self.config
        self.prediction = None  # a call where every candidate diverges predicts nothing
        mean = self.plan_actions.copy()
        std = np.full_like(mean, cfg.noise_std)
        best, best_cost, diverged = mean, np.inf, 0
        for _ in range(cfg.iterations):
            actions = self._sample(mean, std)
            cost, states = self.costs(state, actions)
            ok = np.flatnonzero(np.isfinite(cost))
            diverged += len(cost) - len(ok)
            if not len(ok):
                continue  # nothing to learn from: resample around the same distribution
            order = ok[np.argsort(cost[ok], kind="stable")]
            if cost[order[0]] < best_cost:
                best, best_cost = actions[order[0]], float(cost[order[0]])
                self.prediction = None if states is None else states[order[0]]
            elite = actions[order[: cfg.elites]]
            mean, std = elite.mean(0), np.maximum(elite.std(0), cfg.min_std)
        self.plan_actions = best.copy()
        self.action_std = std
        return best_cost, diverged, cfg.iterations * cfg.population


class MPPIPlanner(SamplingPlanner):
    """Model-predictive path integral control: the plan is the exponentially weighted mean.

    Weights are ``exp(-(cost - min cost) / temperature)`` over the finite-cost candidates; the
    returned action is the first step of the weighted mean (clipped to ``[-1, 1]``).
    ``prediction`` is the best sample's predicted states (the weighted mean is not rolled out).

    Args:
        dynamics: any :class:`Dynamics`. config: :class:`MPPIConfig`. env, model: see
            :class:`SamplingPlanner`.
    """

    config: MPPIConfig
    config_class = MPPIConfig

    def _optimise(self, state: np.ndarray) -> tuple[float, int, int]:
        cfg = self.config
        self.prediction = None  # a call where every candidate diverges predicts nothing
        mean, best_cost, diverged = self.plan_actions.copy(), np.inf, 0
        for _ in range(cfg.iterations):
            actions = self._sample(mean, cfg.noise_std)
            cost, states = self.costs(state, actions)
            ok = np.isfinite(cost)
            diverged += int((~ok).sum())
            if not ok.any():
                continue
            lowest = float(cost[ok].min())
            if lowest < best_cost and states is not None:
                self.prediction = states[int(np.argmin(np.where(ok, cost, np.inf)))]
            best_cost = min(best_cost, lowest)
            # Shifting by the minimum keeps exp() in range; diverged candidates get weight 0.
            w = np.zeros(len(cost))
            w[ok] = np.exp(-(cost[ok] - lowest) / cfg.temperature)
            mean = np.einsum("b,btk->tk", w / w.sum(), actions)
        self.plan_actions = np.clip(mean, -1.0, 1.0)
        self.action_std = np.full_like(mean, cfg.noise_std)
        return best_cost, diverged, cfg.iterations * cfg.population


#: Planning budgets per scene (the benchmark's, ``experiments/README.md``, "Planning"): Push plans 20
#: steps (0.4 s) ahead with smooth, saturating candidates and re-plans every 2 actions (to keep the
#: learned model's cost per action affordable on one core: experiments/README.md, Planning,
#: "The planner"); Toss plans one release.
PRESETS: dict[str, dict[str, Any]] = {
    "push": {"horizon": 20, "population": 20, "iterations": 2, "noise_std": 1.0,
             "noise_correlation": 0.8, "terminal_weight": 10.0, "replan_every": 2,
             "approach_weight": 30.0},
    "toss": {"horizon": 1, "population": 16, "iterations": 3, "noise_std": 1.0,
             "approach_weight": 0.0},
    "cube-real": {"horizon": 1, "population": 24, "iterations": 3, "noise_std": 0.7,
                  "approach_weight": 0.0},
}


def planner_config(planner: str, scene_type: str, **overrides: Any) -> CEMConfig | MPPIConfig:
    """The preset configuration of ``planner`` (``"cem"`` or ``"mppi"``) for ``scene_type``
    (``"push"``, ``"toss"``), with ``overrides`` (``None`` values ignored)."""
    if planner not in ("cem", "mppi"):
        raise ValueError(f"unknown planner {planner!r}: use 'cem' or 'mppi'")
    args = {**PRESETS.get(scene_type, {}), **{k: v for k, v in overrides.items() if v is not None}}
    if planner == "cem":
        args.setdefault("elites", max(2, args.get("population", 48) // 6))
        return CEMConfig(**args)
    return MPPIConfig(**args)


def make_planner(
    planner: str, dynamics: Dynamics, scene_type: str, env: gym.Env | None = None,
    model: mujoco.MjModel | None = None, **overrides: Any
) -> SamplingPlanner:
    """A :class:`CEMPlanner` or :class:`MPPIPlanner` with :func:`planner_config`'s settings
    (``model``: the planning model, default the env's; see :class:`SamplingPlanner`)."""
    config = planner_config(planner, scene_type, **overrides)
    cls = CEMPlanner if planner == "cem" else MPPIPlanner
    return cls(dynamics, config, env=env, model=model)
