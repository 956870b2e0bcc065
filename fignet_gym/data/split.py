"""Seeded train / validation / test splits of a trajectory file (``fignet-gym split``).

The split is stated, not implied, and made by recording: trajectories whose metadata share a
``"file"`` value (:data:`GROUP_KEY`: the windows an importer cut from one recorded push) form one
group, any other trajectory a group of its own, in order of first appearance. Group ``g`` of
``m`` goes to the split its position takes in ``numpy.random.default_rng(seed).permutation(m)``
(the first ``round(f_train m)`` positions train, the next ``round(f_valid m)`` validation, the
rest test), so no recording has trajectories on two sides; with no shared ``"file"`` this is the
same rule on trajectories. The chosen indices and names are written next to the split files
(``split.json``). Training subsets of size ``k`` are the first ``k`` training trajectories of
that order (a group's trajectories in file order), so a smaller subset is always inside a larger
one.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Hashable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fignet_gym.data.format import TrajectoryFile, TrajectoryWriter
from fignet_gym.data.guards import check_single_scene_type

#: Default fractions (train, validation, test).
DEFAULT_FRACTIONS = (0.6, 0.2, 0.2)
SPLITS = ("train", "valid", "test")
#: Trajectory metadata key naming the recording a trajectory was cut from (``import-mit``'s windows
#: of one push, ``import-contactnets``' tosses): equal values go to the same split.
GROUP_KEY = "file"


class SplitError(ValueError):
    """Too few trajectories for the requested split (the message names the file)."""


@dataclass(frozen=True)
class Split:
    """Indices into a trajectory file. ``train`` is in the seeded order (subsets: its prefixes).

    Attributes:
        train, valid, test: trajectory indices. seed: the permutation's seed. fractions: as asked.
        total: trajectories in the file. groups: recordings they were grouped into (``None``:
        every trajectory its own).
    """

    train: tuple[int, ...]
    valid: tuple[int, ...]
    test: tuple[int, ...]
    seed: int
    fractions: tuple[float, float, float]
    total: int
    groups: int | None = None

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
                  min_sizes: Sequence[int] = (1, 1, 1), where: str = "",
                  groups: Sequence[Hashable | None] | None = None) -> Split:
    """Seeded split of ``n`` trajectories into train / validation / test (see the module doc).

    ``fractions``: three non-negative numbers summing to 1, of the groups. ``groups``: one key
    per trajectory (``str | None``[n]); trajectories with the same key go to the same split,
    ``None`` (or no ``groups``) is a group of its own. ``min_sizes``: the fewest groups each split
    may have; fewer raises :class:`SplitError` naming ``where`` (the file).
    """
    f = tuple(float(x) for x in fractions)
    if len(f) != 3 or not all(math.isfinite(x) and x >= 0 for x in f) or abs(sum(f) - 1) > 1e-6:
        raise SplitError(f"--fractions: split fractions must be three finite non-negative numbers "
                         f"summing to 1 (train, valid, test), got {f}")
    members = group_members(n, groups)
    m = len(members)
    unit = "trajectories" if m == n else f"recordings (metadata {GROUP_KEY!r})"
    sizes = _sizes(m, f)
    short = [f"{s} ({k} < {mn})" for s, k, mn in zip(SPLITS, sizes, min_sizes, strict=True) if k < mn]
    if short:
        need = fewest_trajectories(f, min_sizes)
        enough = (f"these fractions need at least {need} {unit}" if need is not None else
                  f"no number of {unit} is enough: raise the zero fraction")
        count = f"{n} trajectories" if m == n else f"{n} trajectories from {m} {unit}"
        raise SplitError(f"{where or '<data>'}: {count} are too few for the split {f} "
                         f"(too small: {', '.join(short)}); {enough}")
    n_train, n_valid, _ = sizes
    order = np.random.default_rng(seed).permutation(m).tolist()

    def take(positions: list[int]) -> tuple[int, ...]:
        return tuple(i for g in positions for i in members[g])

    return Split(take(order[:n_train]), take(order[n_train:n_train + n_valid]),
                 take(order[n_train + n_valid:]), int(seed), f, int(n),  # type: ignore[arg-type]
                 None if m == n else m)


def group_members(n: int, groups: Sequence[Hashable | None] | None) -> list[list[int]]:
    """Trajectory indices of each group, groups in order of first appearance (``int[m][*]``);
    a ``None`` key (or no ``groups``) is a group of its own. Used by the split and by the
    bootstrap over recordings (``train.stats``)."""
    if groups is None:
        return [[i] for i in range(n)]
    if len(groups) != n:
        raise ValueError(f"groups: {len(groups)} keys for {n} trajectories")
    members: list[list[int]] = []
    index: dict[Hashable, int] = {}
    for i, key in enumerate(groups):
        if key is None:
            members.append([i])
        elif key in index:
            members[index[key]].append(i)
        else:
            index[key] = len(members)
            members.append([i])
    return members


def trajectory_groups(f: Any) -> list[str | None]:
    """The :data:`GROUP_KEY` of each trajectory of an open ``TrajectoryFile`` or a list of
    trajectories (``None`` where its metadata has none): what :func:`write_split` groups by, and
    what bootstrap intervals resample (``train.stats``)."""
    keys: list[str | None] = []
    for i in range(len(f)):
        key = f[i].metadata.get(GROUP_KEY)
        keys.append(None if key is None else str(key))
    return keys


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


def file_split(data: str | os.PathLike, fractions: Sequence[float] = DEFAULT_FRACTIONS,
               seed: int = 0, min_sizes: Sequence[int] = (1, 1, 1)) -> Split:
    """The split :func:`write_split` would write for the file ``data``, writing nothing
    (:class:`SplitError` naming the file if it has too few recordings)."""
    with TrajectoryFile(data) as f:
        return split_indices(len(f), fractions, seed, min_sizes, where=str(data),
                             groups=trajectory_groups(f))


def write_split(data: str | os.PathLike, out: str | os.PathLike,
                fractions: Sequence[float] = DEFAULT_FRACTIONS, seed: int = 0,
                min_sizes: Sequence[int] = (1, 1, 1), force: bool = False) -> dict[str, Path]:
    """Write ``out/{train,valid,test}.h5`` and ``out/split.json`` from one trajectory file,
    grouped by recording (:data:`GROUP_KEY`, see the module doc).

    Returns the paths by split name (plus ``"json"``). The files are in split order (training
    file: the seeded order, so ``train --max-train k`` takes :meth:`Split.subset` ``(k)``).
    ``FileExistsError`` if ``out`` already holds a split and ``force`` is not set. The files are
    written into a temporary sibling folder first, so a killed run leaves no partial split.
    """
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
        groups = trajectory_groups(f)
        split = split_indices(len(f), fractions, seed, min_sizes, where=str(data), groups=groups)
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
            if split.groups is not None:
                info["grouped_by"] = GROUP_KEY
                info["recordings"] = {s: sorted({str(groups[i]) for i in getattr(split, s)
                                                     if groups[i] is not None})
                                      for s in SPLITS}
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
