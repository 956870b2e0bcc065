"""PPO on either dynamics (stable-baselines3): what ``fignet-gym ppo`` runs.

:func:`~fignet_gym.agents.ppo.run.run_ppo` trains in a resumable run folder
(:mod:`~fignet_gym.agents.ppo.rundir`: config, checkpoints, curves, TensorBoard) and evaluates
the policy on both dynamics (:func:`~fignet_gym.agents.ppo.eval.evaluate_policy_on`);
:mod:`~fignet_gym.agents.ppo.table` puts finished runs in the transfer table;
:func:`~fignet_gym.agents.ppo.shipped.load_policy` loads a shipped policy by name
(``"push-ppo"``) or a run folder's; :func:`~fignet_gym.agents.ppo.ship.ship_policy` ships a run.
The names below load stable-baselines3 and TensorBoard when first used, not at import.
"""

import importlib

#: Public names -> the module that defines them, imported on first use (PEP 562), so a module of
#: this package that needs no stable-baselines3 (``config``, ``options``: the command line's
#: ``--help``) can be imported without it.
_NAMES = {
    "PPOConfig": "config", "RunConfig": "config", "EVAL_KEYS": "eval", "evaluate_policy_on": "eval",
    "NormalizedPolicy": "policy", "load_run_policy": "policy", "run_ppo": "run",
    "available_policies": "shipped", "load_policy": "shipped", "ship_policy": "ship",
    "transfer_table": "table",
}

__all__ = sorted(_NAMES)


def __getattr__(name: str) -> object:
    if name not in _NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_NAMES[name]}"), name)
