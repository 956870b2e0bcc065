"""Seeded train / validation / test splits of a trajectory file (``fignet-gym split``).

The split is stated, not implied: trajectory ``i`` of a file of ``n`` goes to the split its
position takes in ``numpy.random.default_rng(seed).permutation(n)`` (the first
``round(f_train n)`` positions train, the next ``round(f_valid n)`` validation, the rest test),
and the chosen indices and names are written next to the split files (``split.json``). Training
subsets of size ``k`` are the first ``k`` training trajectories of that order, so a smaller
subset is always inside a larger one.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: Default fractions (train, validation, test).
DEFAULT_FRACTIONS = (0.6, 0.2, 0.2)
SPLITS = ("train", "valid", "test")


class SplitError(ValueError):
    """Too few trajectories for the requested split (the message names the file)."""


@dataclass(frozen=True)
class Split:
    """Indices into a trajectory file. ``train`` is in the seeded order (subsets: its prefixes).

    Attributes:
        train, valid, test: trajectory indices. seed: the permutation's seed. fractions: as asked.
        total: trajectories in the file.
    """

    train: tuple[int, ...]
    valid: tuple[int, ...]
    test: tuple[int, ...]
    seed: int
    fractions: tuple[float, float, float]
    total: int

    def subset(self, size: int | None) -> tuple[int, ...]:
        """The first ``size`` training indices (all if ``None``); :class:`SplitError` if too few."""
        if size is None:
            return self.train
        if not 1 <= size <= len(self.train):
            raise SplitError(f"a training subset of {size} trajectories needs 1 to "
                             f"{len(self.train)} (the training split has {len(self.train)})")
        return self.train[:size]

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def split_indices(n: int, fractions: Sequence[float] = DEFAULT_FRACTIONS, seed: int = 0,
                  min_sizes: Sequence[int] = (1, 1, 1), where: str = "") -> Split:
    """Seeded split of ``n`` trajectories into train / validation / test (see the module doc).

    ``fractions``: three non-negative numbers summing to 1. ``min_sizes``: the fewest trajectories
    each split may have; fewer raises :class:`SplitError` naming ``where`` (the file).
    """
    f = tuple(float(x) for x in fractions)
    if len(f) != 3 or not all(math.isfinite(x) and x >= 0 for x in f) or abs(sum(f) - 1) > 1e-6:
        raise SplitError(f"--fractions: split fractions must be three finite non-negative numbers "
                         f"summing to 1 (train, valid, test), got {f}")
    sizes = _sizes(n, f)
    short = [f"{s} ({k} < {m})" for s, k, m in zip(SPLITS, sizes, min_sizes, strict=True) if k < m]
    if short:
        need = fewest_trajectories(f, min_sizes)
        enough = (f"these fractions need at least {need} trajectories" if need is not None else
                  "no number of trajectories is enough: raise the zero fraction")
        raise SplitError(f"{where or '<data>'}: {n} trajectories are too few for the split {f} "
                         f"(too small: {', '.join(short)}); {enough}")
    n_train, n_valid, _ = sizes
    order = np.random.default_rng(seed).permutation(n).tolist()
    return Split(tuple(order[:n_train]), tuple(order[n_train:n_train + n_valid]),
                 tuple(order[n_train + n_valid:]), int(seed), f, int(n))  # type: ignore[arg-type]


def _sizes(n: int, f: tuple[float, ...]) -> tuple[int, int, int]:
    """Train, validation and test sizes of ``n`` trajectories split by fractions ``f``."""
    n_train = int(round(f[0] * n))
    n_valid = int(round(f[1] * n))
    return n_train, n_valid, n - n_train - n_valid


def fewest_trajectories(fractions: Sequence[float], min_sizes: Sequence[int] = (1, 1, 1)
                        ) -> int | None:
    """The fewest trajectories whose split by ``fractions`` gives every split its minimum size
    (``None`` if none does: a zero fraction with a positive minimum)."""
    f = tuple(float(x) for x in fractions)
    if any(x == 0 and m > 0 for x, m in zip(f, min_sizes, strict=True)):
        return None
    # Rounding gives split i at least m_i once n f_i >= m_i + 1/2 (and the test split takes the
    # rounding's remainder, off by at most 1): the search ends by this bound.
    bound = max(math.ceil((m + 1.5) / x) for x, m in zip(f, min_sizes, strict=True) if x > 0)
    for n in range(sum(min_sizes), bound + sum(min_sizes) + 1):
        if all(k >= m for k, m in zip(_sizes(n, f), min_sizes, strict=True)):
            return n
    return None


def write_split(data: str | os.PathLike, out: str | os.PathLike,
                fractions: Sequence[float] = DEFAULT_FRACTIONS, seed: int = 0,
                min_sizes: Sequence[int] = (1, 1, 1), force: bool = False) -> dict[str, Path]:
    """Write ``out/{train,valid,test}.h5`` and ``out/split.json`` from one trajectory file.

    Returns the paths by split name (plus ``"json"``). The files are in split order (training
    file: the seeded order, so ``train --max-train k`` takes :meth:`Split.subset` ``(k)``).
    ``FileExistsError`` if ``out`` already holds a split and ``force`` is not set. The files are
    written into a temporary sibling folder first, so a killed run leaves no partial split.
    """
    from fignet_gym.data.format import TrajectoryFile, TrajectoryWriter
    from fignet_gym.data.guards import check_single_scene_type

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"--out {out}: is a file; --out must be a folder")
    files = [f"{s}.h5" for s in SPLITS] + ["split.json"]
    existing = [name for name in files if (out / name).exists()]
    if existing and not force:
        raise FileExistsError(f"{out}: already holds a split ({', '.join(existing)}); "
                              "pass --force to replace it")
    tmp = out.with_name(f".{out.name}.tmp")
    with TrajectoryFile(data) as f:
        split = split_indices(len(f), fractions, seed, min_sizes, where=str(data))
        check_single_scene_type(data)
        names = f.names
        if tmp.exists():  # left by a killed run
            shutil.rmtree(tmp)
        tmp.mkdir(parents=True)
        try:
            for s in SPLITS:
                with TrajectoryWriter(tmp / f"{s}.h5", {**f.metadata, "split": s,
                                                        "split_seed": seed,
                                                        "split_of": str(data)}) as w:
                    for i in getattr(split, s):
                        w.add(f[i])
            info = {"data": str(data), **split.to_json(),
                    "names": {s: [names[i] for i in getattr(split, s)] for s in SPLITS}}
            (tmp / "split.json").write_text(json.dumps(info, indent=1))
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    try:
        if not out.exists():
            os.rename(tmp, out)
        else:  # an existing folder (maybe holding other files): move the files, split.json last
            for name in files:
                os.replace(tmp / name, out / name)
            tmp.rmdir()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    paths = {s: out / f"{s}.h5" for s in SPLITS}
    paths["json"] = out / "split.json"
    return paths
