"""Agents: model-predictive planners and PPO helpers (installed as ``fignet_gym.agents``).

Planners (:mod:`~fignet_gym.agents.planners`) plan any environment that exposes its task (Push,
Toss, CubeToss, a user's own) by batched rollouts of any :class:`~fignet_gym.dynamics.Dynamics`.
PPO (:func:`~fignet_gym.agents.ppo_run.run_ppo`, what ``fignet-gym ppo`` runs) trains
stable-baselines3 PPO on either dynamics in a resumable run folder and evaluates the policy on both
(:func:`~fignet_gym.agents.ppo_eval.evaluate_policy_on`); :mod:`~fignet_gym.agents.ppo_table` puts
finished runs in the transfer table; :func:`~fignet_gym.agents.ppo_shipped.load_policy` loads a
shipped policy by name (``"push-ppo"``) or a run folder's.
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
from fignet_gym.agents.policy_agent import PolicyAgent
from fignet_gym.agents.ppo_config import PPOConfig, RunConfig
from fignet_gym.agents.ppo_eval import EVAL_KEYS, evaluate_policy_on
from fignet_gym.agents.ppo_policy import NormalizedPolicy, load_run_policy
from fignet_gym.agents.ppo_run import run_ppo
from fignet_gym.agents.ppo_shipped import available_policies, load_policy
from fignet_gym.agents.ppo_table import transfer_table
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
