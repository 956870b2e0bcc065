"""A PPO run's logs: ``progress.csv`` / ``eval.csv`` and TensorBoard, each step once across resumes.

SB3 records ``train/*`` inside an update and writes them with the next iteration's row; a
checkpoint taken between the two carries those pending values (:func:`pending_records`) so a
resumed run writes them (:func:`restore_records`) instead of losing one update's metrics.
"""

from __future__ import annotations

import csv
import io
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.logger import (
    HumanOutputFormat,
    KVWriter,
    Logger,
    TensorBoardOutputFormat,
    filter_excluded_keys,
)
from torch.utils.tensorboard import SummaryWriter

from fignet_gym.atomic import write_text


class CSVRows(KVWriter):
    """SB3 logger output: one CSV row per dump, keyed by step, rewritten whole on every dump.

    SB3's own CSV writer truncates its file when it opens it; this one starts from the rows of an
    earlier process, keeps those up to ``keep_until`` (a resumed run's checkpoint) and drops the
    rest, so a resumed log has every step once. Columns are the union of all keys seen.

    Args:
        path: the CSV file.
        keep_until: keep existing rows whose ``step`` is at most this (``None``: start empty).
    """

    def __init__(self, path: Path, keep_until: int | None = None) -> None:
        self.path = path
        self.rows: list[dict[str, Any]] = []
        if keep_until is not None and path.exists():
            with path.open(newline="") as f:
                self.rows = [r for r in csv.DictReader(f) if int(r["step"]) <= keep_until]
        self._flush()

    def add(self, step: int, values: Mapping[str, Any]) -> None:
        """Append one row (``values`` must not contain ``step``)."""
        self.rows.append({"step": int(step), **values})
        self._flush()

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        """SB3's ``KVWriter`` hook: the numeric values of one dump as the row of ``step``."""
        values = filter_excluded_keys(key_values, key_excluded, "csv")
        self.add(step, {k: v for k, v in values.items() if isinstance(v, (int, float, np.number))})

    def _flush(self) -> None:
        columns = list(dict.fromkeys(k for r in self.rows for k in r)) or ["step"]
        buf = io.StringIO(newline="")
        writer = csv.DictWriter(buf, fieldnames=columns)
        writer.writeheader()
        writer.writerows(self.rows)
        write_text(self.path, buf.getvalue())

    def close(self) -> None:
        """Nothing to release: every row is on disk already."""


class _TensorBoard(TensorBoardOutputFormat):
    """SB3's TensorBoard output whose writer hides earlier events from ``purge_step`` on."""

    def __init__(self, folder: Path, purge_step: int | None) -> None:
        # Events at steps after a checkpoint were written by a killed process and are redone
        # from it: SummaryWriter(purge_step=...) tells TensorBoard to drop them.
        self.writer = SummaryWriter(str(folder), purge_step=purge_step)
        self._is_closed = False


def read_csv(path: str | os.PathLike) -> list[dict[str, str]]:
    """Rows of a run's ``progress.csv`` / ``eval.csv``."""
    with Path(path).open(newline="") as f:
        return list(csv.DictReader(f))


def make_logger(root: Path, resume_step: int | None, verbose: bool) -> Logger:
    """SB3 logger writing TensorBoard (``tb/``) and ``progress.csv``; resumed: purge after the step."""
    tb = _TensorBoard(root / "tb", None if resume_step is None else resume_step + 1)
    outputs: list[KVWriter] = [tb, CSVRows(root / "progress.csv", keep_until=resume_step)]
    if verbose:
        outputs.append(HumanOutputFormat(sys.stdout))
    return Logger(str(root), outputs)


def pending_records(logger: Logger) -> dict[str, dict[str, Any]]:
    """Values recorded since the last dump (SB3's ``train/*`` of the last update), as recorded
    (NumPy scalars kept: a resumed run writes exactly what the stopped one would have)."""
    return {
        "values": dict(logger.name_to_value),
        "counts": dict(logger.name_to_count),
        "excluded": dict(logger.name_to_excluded),
    }


def restore_records(logger: Logger, pending: Mapping[str, Mapping[str, Any]]) -> None:
    """Record :func:`pending_records`' values again, to be written by the next dump."""
    logger.name_to_value.update(pending["values"])
    logger.name_to_count.update(pending["counts"])
    logger.name_to_excluded.update(pending["excluded"])
