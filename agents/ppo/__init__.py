"""PPO on either dynamics (stable-baselines3): what ``fignet-gym ppo`` runs.

:func:`~fignet_gym.agents.ppo.run.run_ppo` trains in a resumable run folder
(:mod:`~fignet_gym.agents.ppo.rundir`: config, checkpoints, curves, TensorBoard) and evaluates
the policy on both dynamics (:func:`~fignet_gym.agents.ppo.eval.evaluate_policy_on`);
:mod:`~fignet_gym.agents.ppo.table` puts finished runs in the transfer table;
:func:`~fignet_gym.agents.ppo.shipped.load_policy` loads a shipped policy by name
(``"push-ppo"``) or a run folder's. Importing this package loads stable-baselines3 and
TensorBoard; :mod:`fignet_gym.agents` alone (the planners) does not.
"""

from fignet_gym.agents.ppo.config import PPOConfig, RunConfig
from fignet_gym.agents.ppo.eval import EVAL_KEYS, evaluate_policy_on
from fignet_gym.agents.ppo.policy import NormalizedPolicy, load_run_policy
from fignet_gym.agents.ppo.run import run_ppo
from fignet_gym.agents.ppo.shipped import available_policies, load_policy
from fignet_gym.agents.ppo.table import transfer_table

__all__ = ["EVAL_KEYS", "NormalizedPolicy", "PPOConfig", "RunConfig", "available_policies",
           "evaluate_policy_on", "load_policy", "load_run_policy", "run_ppo", "transfer_table"]
