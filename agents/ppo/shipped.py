"""PPO policies shipped inside the package, and :func:`load_policy`: a shipped name or a folder to a
policy acting on the env's raw observations.

A shipped policy is a folder ``fignet_gym/pretrained/policies/<name>/`` written by
``fignet-gym ppo-ship`` from a finished run: the run's ``policy.zip``, ``vecnormalize.pkl``,
``config.json``, ``final_eval.json`` and ``eval.csv``, and the card ``<name>.md`` generated from
them. It has a finished run folder's layout, so anything that reads run folders (``ppo-table``,
:func:`~fignet_gym.agents.load_run_policy`) reads it too.
"""

from __future__ import annotations

import os
from pathlib import Path

from fignet_gym.agents.ppo.policy import NormalizedPolicy, load_run_policy
from fignet_gym.agents.ppo.rundir import POLICY, RunError
from fignet_gym.pretrained import pretrained_dir

#: Sub-folder of ``fignet_gym/pretrained/`` holding one folder per shipped policy.
POLICIES = "policies"


def policies_dir() -> Path:
    """Folder of the shipped policies (one sub-folder each)."""
    return pretrained_dir() / POLICIES


def available_policies() -> list[str]:
    """Names of the shipped policies accepted by :func:`load_policy`."""
    root = policies_dir()
    return sorted(p.name for p in root.iterdir() if (p / POLICY).is_file()) if root.is_dir() else []


def policy_folder(name_or_path: str | os.PathLike) -> Path:
    """The folder a user means: a finished run folder or shipped-policy folder (it holds a
    ``policy.zip``), else a shipped name; ``RunError`` listing the shipped names otherwise."""
    text = os.fspath(name_or_path)
    path = Path(text)
    if (path / POLICY).is_file():
        return path
    if text in available_policies():
        return policies_dir() / text
    names = ", ".join(available_policies()) or "none shipped"
    if path.is_dir():
        raise RunError(f"{text}: no {POLICY} (not a finished `fignet-gym ppo` run), and not a "
                       f"shipped policy name ({names})")
    raise RunError(f"{text}: no such run folder, and not a shipped policy name ({names})")


def load_policy(name_or_path: str | os.PathLike) -> NormalizedPolicy:
    """A trained PPO policy by shipped name (:func:`available_policies`, e.g. ``"push-ppo"``; its
    card ``<name>.md`` gives recipe, budget and scores) or by run / shipped-policy folder.

    The policy acts on the env's raw observations (its normaliser and observation transform
    inside) through SB3's ``predict``, so ``stable_baselines3.common.evaluation.evaluate_policy``
    and :func:`~fignet_gym.agents.evaluate_policy_on` take it as is; ``policy.env_id`` and
    ``policy.env_kwargs`` are the env it was trained for, ``policy.config`` the whole run.

    Raises:
        RunError: neither a folder with a ``policy.zip`` nor a shipped name (one line listing
            the shipped names).
    """
    return load_run_policy(policy_folder(name_or_path))
