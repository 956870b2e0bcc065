"""Agents: model-predictive planners and PPO helpers (installed as ``fignet_gym.agents``).

Planners (:mod:`~fignet_gym.agents.planners`) plan Push-v0 tip motions by batched rollouts of any
:class:`~fignet_gym.dynamics.Dynamics`; the PPO helpers (:mod:`~fignet_gym.agents.ppo`) train
stable-baselines3 PPO on either dynamics and check a policy on another.
"""

from fignet_gym.agents.planners import (
    CEMConfig,
    CEMPlanner,
    MPPIConfig,
    MPPIPlanner,
    PlanInfo,
    SamplingPlanner,
    run_episode,
)
from fignet_gym.agents.ppo import (
    EVAL_KEYS,
    PPOConfig,
    evaluate_policy_on,
    load_policy,
    save_policy,
    train_ppo,
)
from fignet_gym.agents.task import PLAN_STATE_SPEC, PushTask, plan_state

__all__ = [
    "EVAL_KEYS",
    "PLAN_STATE_SPEC",
    "CEMConfig",
    "CEMPlanner",
    "MPPIConfig",
    "MPPIPlanner",
    "PPOConfig",
    "PlanInfo",
    "PushTask",
    "SamplingPlanner",
    "evaluate_policy_on",
    "load_policy",
    "plan_state",
    "run_episode",
    "save_policy",
    "train_ppo",
]
