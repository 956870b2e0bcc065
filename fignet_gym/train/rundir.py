"""A training run's folder: never overwritten by accident, rewound exactly on ``--resume``.

A run folder holds ``config.json``, ``last.pt``, ``best.pt``, ``curve.jsonl`` and ``tb/``
(TensorBoard). ``last.pt`` is written every ``checkpoint_every`` steps; validation records and a new
best model come in between. A process killed without warning (SIGKILL, power loss) therefore
leaves records of steps after ``last.pt``, which the resumed run computes again. On resume:

* ``curve.jsonl`` keeps only the records of steps up to ``last.pt``'s step;
* TensorBoard events after that step are purged (``SummaryWriter(purge_step=...)``, which hides
  them from every TensorBoard reader);
* a new best model is first written to ``best.new.pt`` and becomes ``best.pt`` only once a
  ``last.pt`` at or after its step exists (:func:`promote_best`), so ``best.pt`` never comes
  from steps a kill discarded; a leftover ``best.new.pt`` is promoted or deleted by its step;
* stale ``*.tmp`` files of an interrupted atomic write are deleted.

SIGINT / SIGTERM lose nothing: the trainer checkpoints before exiting.
"""

from __future__ import annotations

import json
import shutil
import warnings
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

from fignet_gym.atomic import write_text
from fignet_gym.simulator.checkpoint import CheckpointWarning, load
from fignet_gym.simulator.config import SimulatorConfig

#: What a run writes (``--force`` removes exactly these).
RUN_FILES = ("last.pt", "best.pt", "best.new.pt", "curve.jsonl", "config.json", "tb")
PENDING_BEST = "best.new.pt"
#: Training settings that may change on ``--resume`` (they do not change what is optimised).
RESUMABLE_CHANGES = frozenset({"steps", "threads", "checkpoint_every"})


class RunFolderError(ValueError):
    """A run folder cannot be used as asked (it holds another run, or a different config)."""


def remove_stale_temporaries(out: Path) -> None:
    """Delete ``*.tmp`` files an interrupted atomic write left behind in ``out``."""
    for tmp in out.glob("*.tmp"):
        tmp.unlink(missing_ok=True)


def prepare_run_folder(out: Path, resume: bool, force: bool = False) -> None:
    """Refuse to start a new run over an existing one unless ``force`` (then remove its files).

    With ``resume`` an existing run is continued (see :func:`check_resume_config`).
    """
    existing = [f for f in RUN_FILES if (out / f).exists()]
    if existing and not resume:
        if not force:
            raise RunFolderError(
                f"{out}: already holds a run ({', '.join(existing)}): pass --resume to continue "
                "it, --force to replace it, or choose another --out")
        for f in existing:
            p = out / f
            shutil.rmtree(p) if p.is_dir() else p.unlink()
    if out.is_dir():
        remove_stale_temporaries(out)


def check_resume_config(out: Path, sim_cfg: dict[str, Any], training: dict[str, Any]) -> None:
    """On ``--resume``, refuse a config other than the run's: the simulator config requested
    (``sim_cfg``, as before data-derived fields are filled in) against ``last.pt``'s, the
    training settings against ``config.json``'s (except :data:`RESUMABLE_CHANGES`)."""
    last = out / "last.pt"
    if not last.is_file():
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CheckpointWarning)
        stored = load(last)[0].config
    try:
        asked = SimulatorConfig.from_dict({**sim_cfg, "dt": stored.dt})
    except (TypeError, ValueError) as exc:
        raise RunFolderError(f"simulator config: {exc}") from None
    diffs = []
    names = sorted((f.name for f in fields(SimulatorConfig)), key=lambda n: n != "scene_type")
    for name in names:  # the scene type first: the likeliest mix-up
        a, s = getattr(asked, name), getattr(stored, name)
        if name == "noise_std" and a == 0:
            continue  # measured from the data when the config leaves it at 0
        if a != s:
            diffs.append(f"simulator.{name}: run {s!r}, asked {a!r}")
    cfg_file = out / "config.json"
    if cfg_file.is_file():
        try:
            ran = json.loads(cfg_file.read_text()).get("training", {})
        except (OSError, ValueError, AttributeError):
            ran = {}
        for key, value in training.items():
            if key in ran and key not in RESUMABLE_CHANGES and _norm(ran[key]) != _norm(value):
                diffs.append(f"training.{key}: run {ran[key]!r}, asked {value!r}")
    if diffs:
        raise RunFolderError(
            f"{last}: --resume with a config other than the run's ({'; '.join(diffs[:4])}"
            f"{' ...' if len(diffs) > 4 else ''}); resume without --config to use the run's own, "
            "or start a new run (--init to start from its weights)")


def _norm(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def rewind(out: Path, step: int) -> None:
    """Make the run's records agree with a resumed ``last.pt`` at ``step`` (module docstring)."""
    remove_stale_temporaries(out)
    curve = out / "curve.jsonl"
    if curve.is_file():
        kept = []
        for line in curve.read_text().splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue  # a line cut by the kill
            if isinstance(rec, dict) and rec.get("step", step + 1) <= step:
                kept.append(json.dumps(rec))
        write_text(curve, "".join(k + "\n" for k in kept))
    pending = out / PENDING_BEST
    if pending.is_file():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", CheckpointWarning)
                meta = load(pending)[1]
            at = int(meta.get("valid", {}).get("step", step + 1))
        except (ValueError, TypeError):
            at = step + 1
        if at <= step:
            pending.replace(out / "best.pt")
        else:
            pending.unlink()


def promote_best(out: Path) -> None:
    """After ``last.pt`` is written: a pending best model becomes ``best.pt``."""
    pending = out / PENDING_BEST
    if pending.is_file():
        pending.replace(out / "best.pt")


def training_dict(cfg: Any) -> dict[str, Any]:
    """A training config dataclass as a plain dictionary."""
    return asdict(cfg)
