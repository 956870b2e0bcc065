"""Agents: model-predictive planners and PPO helpers (installed as ``fignet_gym.agents``).

Planners (:mod:`~fignet_gym.agents.planners`) plan any environment that exposes its task (Push,
Toss, CubeToss, a user's own) by batched rollouts of any :class:`~fignet_gym.dynamics.Dynamics`;
the PPO helpers (:mod:`~fignet_gym.agents.ppo`) train stable-baselines3 PPO on either dynamics
and check a policy on another; :mod:`~fignet_gym.agents.ppo_run` is ``fignet-gym ppo``
(resumable run folders, evaluation on both dynamics, the transfer table).
"""

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
from fignet_gym.agents.ppo import (
    EVAL_KEYS,
    PPOConfig,
    evaluate_policy_on,
    load_policy,
    save_policy,
    train_ppo,
)
from fignet_gym.agents.ppo_run import (
    NormalizedPolicy,
    RunConfig,
    load_run_policy,
    run_ppo,
    transfer_table,
)
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
    "PPOConfig",
    "PlanInfo",
    "PlanningProblem",
    "PushProblem",
    "RunConfig",
    "TossProblem",
    "check_same_scene",
    "SamplingPlanner",
    "evaluate_policy_on",
    "load_run_policy",
    "load_policy",
    "plan_state",
    "problem_for",
    "run_episode",
    "run_ppo",
    "save_policy",
    "train_ppo",
    "transfer_table",
]
