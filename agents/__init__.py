"""Agents: model-predictive planners, and PPO in :mod:`fignet_gym.agents.ppo` (installed as
``fignet_gym.agents``).

Planners (:mod:`~fignet_gym.agents.planners`) plan any environment that exposes its task (Push,
Toss, CubeToss, a user's own) by batched rollouts of any :class:`~fignet_gym.dynamics.Dynamics`.
PPO (:mod:`fignet_gym.agents.ppo`: ``run_ppo``, what ``fignet-gym ppo`` runs, evaluation on both
dynamics, the transfer table, ``load_policy`` for shipped policies) needs stable-baselines3 and
TensorBoard; importing this package for the planners loads neither: the PPO names below are
imported from :mod:`fignet_gym.agents.ppo` when first used.
"""

from fignet_gym import check_same_install

check_same_install(__file__, "agents")  # before anything else of this copy is imported

from fignet_gym.agents import ppo  # its names load stable-baselines3 only when first used
from fignet_gym.agents.baselines import IdleAgent, RandomAgent
from fignet_gym.agents.episode import run_episode
from fignet_gym.agents.planners import (
    PRESETS,
    CEMConfig,
    CEMPlanner,
    MPPIConfig,
    MPPIPlanner,
    PlanInfo,
    SamplingPlanner,
    make_planner,
    planner_config,
)
from fignet_gym.agents.policy_agent import PolicyAgent
from fignet_gym.agents.task import (
    PLAN_STATE_SPEC,
    PlanningProblem,
    PushProblem,
    TossProblem,
    check_same_scene,
    plan_state,
    problem_for,
)

__all__ = [
    "EVAL_KEYS",
    "PRESETS",
    "IdleAgent",
    "RandomAgent",
    "make_planner",
    "planner_config",
    "PLAN_STATE_SPEC",
    "CEMConfig",
    "CEMPlanner",
    "MPPIConfig",
    "MPPIPlanner",
    "NormalizedPolicy",
    "PolicyAgent",
    "PPOConfig",
    "PlanInfo",
    "PlanningProblem",
    "PushProblem",
    "RunConfig",
    "TossProblem",
    "check_same_scene",
    "SamplingPlanner",
    "available_policies",
    "evaluate_policy_on",
    "load_policy",
    "load_run_policy",
    "plan_state",
    "problem_for",
    "run_episode",
    "run_ppo",
    "transfer_table",
]

def __getattr__(name: str) -> object:
    # PPO names resolve through the subpackage's own lazy table (PEP 562): the PPO stack
    # (stable-baselines3, TensorBoard) loads only for those who use it.
    if name in ppo.__all__:
        return getattr(ppo, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
