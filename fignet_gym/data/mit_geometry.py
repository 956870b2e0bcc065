"""Geometry of the real MIT Pushing objects: outlines, the recorded frame's offset, the contact check.

The outlines (``mit_objects/<shape>_ext.npy``, metres, from the dataset of Yu et al. 2016; see
``mit_objects/README.md``) are drawn in their own frame. The dataset's tracked ``yaw`` uses another
one for some shapes (a quarter turn for butter and ellip3, a twelfth turn for hex), so the offset
between the two is **measured on the data**: while the tip pushes the object, its centre stays
one tip radius (4.75 mm) from the outline. An offset ``(theta, d)`` maps a point ``q`` of the
recorded object frame to the outline frame, ``R(theta) q + d``.

Which frames are "in contact" comes from the motion alone (the object moves), never from the
geometry being estimated.

Shapes: ``T`` samples, ``K`` outline vertices, ``N`` points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

#: Radius (m) of the dataset's cylindrical steel tip.
TIP_RADIUS = 0.00475
#: Thickness (m) of the dataset's objects (its meshes: half an inch).
REAL_THICKNESS = 0.0127
#: The eleven objects of the dataset.
MIT_SHAPES = ("rect1", "rect2", "rect3", "tri1", "tri2", "tri3", "ellip1", "ellip2", "ellip3",
              "hex", "butter")
#: A frame is in contact when the object moves faster than this (m/s): its origin, or a point
#: ``SPEED_ARM`` from it turning. The slowest pushes run at 10 mm/s. The point under the tip is
#: not used: yaw noise at the tip's lever arm reads as several mm/s while the object rests.
CONTACT_SPEED = 0.005
SPEED_ARM = 0.05
#: A noisy track must also move faster than this many times its noise's speed reading.
NOISE_SIGMAS = 4.0
_MAD_TO_SIGMA = 1.4826
#: Half-width (s) of the central difference behind that speed (about 5 samples at 250 Hz).
SPEED_HALF_WINDOW = 0.02
#: A push "moves the object" when some point of its outline ends up this far (m) from where it
#: started, at any time (far above the tracking noise).
STILL_MOTION = 0.001
#: "Tip inside the object" means the tip cylinder overlaps the outline by more than this (m).
INSIDE_TOLERANCE = 0.001
#: Offset search: rotation grid step (deg), then a refinement of rotation and shift.
OFFSET_GRID_DEG = 1.0
#: Largest shift (m) the refinement may find (Vicon marker frames are centred to a few mm).
MAX_OFFSET_SHIFT = 0.003
#: Prior scale (m) keeping the shift at zero along directions the contacts do not constrain.
SHIFT_PRIOR = 0.001
#: Robust loss scale (m) of the refinement (soft L1 on the distance residual).
RESIDUAL_SCALE = 0.0005
#: The estimate needs this many pushes with at least MIN_PUSH_FRAMES contact frames each.
MIN_OFFSET_PUSHES = 2
MIN_PUSH_FRAMES = 10
#: Rotation is "not identifiable" when the best and worst grid rotations' costs differ by less
#: than this fraction (a circular outline centred on the recorded origin).
SYMMETRY_TOLERANCE = 0.05
#: A tip centre closer than a radius is only noise (the tip cannot enter the steel), one farther
#: may also be real (the tip leaving, the object coasting): the closer side weighs this much more.
INSIDE_WEIGHT = 2.0
#: A measured rotation this close (deg) to a quarter turn is rounded to it.
QUARTER_TURN_DEG = 5.0
#: An outline is symmetric under a rotation when its turned vertices stay this close (m) to it.
SYMMETRY_MATCH = 0.0003
#: Frames per push the estimate uses at most (evenly spaced).
MAX_PUSH_FRAMES = 60
#: Distance quantiles reported by the check.
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)


def outline_dir() -> Path:
    """Folder of the shipped outlines (and their README, licence, reference offsets)."""
    return Path(str(resources.files("fignet_gym.data") / "mit_objects"))


@lru_cache(maxsize=64)
def _load_outline(path: str) -> np.ndarray:
    arr = np.load(path, allow_pickle=False)
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 3 or not np.isfinite(arr).all():
        raise ValueError(f"{path}: expected an outline float[K >= 3, 2] in metres, got {arr.shape}")
    arr = np.asarray(arr, float)
    if polygon_area(arr) < 0:  # the dataset's files run clockwise; keep counter-clockwise
        arr = arr[::-1]
    return arr.copy()


def outline(shape: str, folder: str | Path | None = None) -> np.ndarray:
    """``float[K, 2]`` counter-clockwise outline (m) of ``shape`` in the outline frame.

    ``folder`` holds ``<shape>_ext.npy`` files (default: the shipped outlines of the dataset).
    """
    root = Path(folder) if folder is not None else outline_dir()
    path = root / f"{shape}_ext.npy"
    if not path.is_file():
        have = sorted(p.name[: -len("_ext.npy")] for p in root.glob("*_ext.npy"))
        raise ValueError(f"{path}: no outline for shape {shape!r}; outlines in {root}: "
                         f"{', '.join(have) or 'none'}")
    return _load_outline(str(path))


def polygon_area(poly: np.ndarray) -> float:
    """Signed area of ``float[K, 2]`` (positive when counter-clockwise)."""
    x, y = poly[:, 0], poly[:, 1]
    return float((x * np.roll(y, -1) - np.roll(x, -1) * y).sum() / 2)


def signed_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Signed distance ``float[N]`` of ``float[N, 2]`` points to the closed polygon ``float[K, 2]``:
    negative inside (even-odd rule), so a tip centre in contact sits at about ``+TIP_RADIUS``."""
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    ap = points[:, None, :] - a[None]
    t = np.clip((ap * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    dist = np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=1)
    x, y = points[:, :1], points[:, 1:]
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[:, 0] + (y - a[:, 1]) * ab[:, 0] / ab[:, 1]
    inside = (crosses & (x < x_at)).sum(axis=1) % 2 == 1
    return np.where(inside, -dist, dist)


def rotation(theta: float) -> np.ndarray:
    """``float[2, 2]`` rotation by ``theta`` (rad)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def tip_in_object_frame(obj: np.ndarray, tip: np.ndarray) -> np.ndarray:
    """Tip centres ``float[T, 2]`` in the recorded object frame, from object poses ``float[T, 3]``
    (x, y, yaw) and tip positions ``float[T, 2]`` (world)."""
    c, s = np.cos(obj[:, 2]), np.sin(obj[:, 2])
    d = tip - obj[:, :2]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)


def central_speed(times: np.ndarray, track: np.ndarray, arm: float = 0.0) -> np.ndarray:
    """``float[T]`` speed (m/s) of ``track float[T, 2 or 3]`` (x, y[, unwrapped yaw]) by central
    differences over ``+-SPEED_HALF_WINDOW``; rotation counts at ``arm`` (m). Ends: 0."""
    n = len(times)
    k = max(1, int(round(SPEED_HALF_WINDOW / max(float(np.median(np.diff(times))), 1e-6))))
    speed = np.zeros(n)
    if n <= 2 * k:
        return speed
    vel = (track[2 * k:] - track[:-2 * k]) / (times[2 * k:] - times[:-2 * k])[:, None]
    speed[k:-k] = np.linalg.norm(vel[:, :2], axis=1)
    if track.shape[1] > 2:
        speed[k:-k] = np.maximum(speed[k:-k], np.abs(vel[:, 2]) * arm)
    return speed


def track_noise(track: np.ndarray) -> np.ndarray:
    """``float[C]`` white-noise level of each column of ``track float[T, C]`` (its units), from the
    second differences (a robust MAD; real motion adds almost nothing to them at 250 Hz)."""
    if len(track) < 3:
        return np.zeros(track.shape[1])
    second = track[2:] - 2 * track[1:-1] + track[:-2]
    mad = np.median(np.abs(second - np.median(second, axis=0)), axis=0)
    return _MAD_TO_SIGMA * mad / math.sqrt(6.0)  # var(x0 - 2 x1 + x2) = 6 var(x)


def moving_mask(times: np.ndarray, track: np.ndarray, arm: float = 0.0) -> np.ndarray:
    """``bool[T]``: samples where ``track float[T, 2 or 3]`` (x, y[, unwrapped yaw]) moves faster
    than ``CONTACT_SPEED``, or than ``NOISE_SIGMAS`` times the speed its own tracking noise
    would read (noisy tracks: the speed of a resting object is not zero)."""
    n = len(times)
    dt = max(float(np.median(np.diff(times))), 1e-6) if n > 1 else 1.0
    k = max(1, int(round(SPEED_HALF_WINDOW / dt)))
    noise = track_noise(track)
    pos_noise = max(float(noise[:2].max()), float(noise[2]) * arm if len(noise) > 2 else 0.0)
    floor = NOISE_SIGMAS * math.sqrt(2.0) * pos_noise / (2 * k * dt)
    return central_speed(times, track, arm) > max(CONTACT_SPEED, floor)


def contact_mask(times: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """``bool[T]``: frames where the tracked object moves (only the tip moves it).

    ``times float[T]`` (s), ``obj float[T, 3]`` (x, y, unwrapped yaw); a turn counts at
    ``SPEED_ARM`` from the origin.
    """
    return moving_mask(times, obj, SPEED_ARM)


def max_motion(obj: np.ndarray, poly: np.ndarray) -> float:
    """Largest distance (m) any outline vertex travels from its place at the first sample.

    ``obj float[T, 3]`` (x, y, yaw) poses of the recorded frame; ``poly`` in that frame.
    """
    c, s = np.cos(obj[:, 2]), np.sin(obj[:, 2])
    wx = obj[:, None, 0] + c[:, None] * poly[None, :, 0] - s[:, None] * poly[None, :, 1]
    wy = obj[:, None, 1] + s[:, None] * poly[None, :, 0] + c[:, None] * poly[None, :, 1]
    return float(np.hypot(wx - wx[:1], wy - wy[:1]).max())


@dataclass(frozen=True)
class FrameOffset:
    """Offset of one shape: a recorded-frame point ``q`` is at ``R(theta) q + shift`` in the
    outline frame.

    Attributes:
        theta: rad. shift: ``(dx, dy)`` m.
        status: ``"measured"`` (free rotation); ``"quarter"`` (measured within
            ``QUARTER_TURN_DEG`` of a quarter turn, and rounded to it); ``"symmetric"``
            (rotation cannot matter: it is set to 0, the shift is measured); ``"default"`` (too
            few contact frames: no offset, flagged); ``"reference"`` (too few, and the offset
            measured on the ABS pushes is used); ``"given"`` (by the user, e.g. measured on a
            larger folder).
        pushes, frames: how many pushes and contact frames the estimate used.
        refit: how the last robust refit ended: ``"converged"``, ``"at bound"`` (a shift
            component at ``MAX_OFFSET_SHIFT``: weakly determined, e.g. along the one side every
            push touched), ``"not converged"`` (scipy's evaluation limit) or ``""`` (no refit).
        evaluations: residual evaluations of that refit.
    """

    theta: float = 0.0
    shift: tuple[float, float] = (0.0, 0.0)
    status: str = "default"
    pushes: int = 0
    frames: int = 0
    refit: str = ""
    evaluations: int = 0

    def to_outline_frame(self, points: np.ndarray) -> np.ndarray:
        """Recorded-frame points ``float[N, 2]`` in the outline frame."""
        return points @ rotation(self.theta).T + np.asarray(self.shift)

    def outline_in_recorded_frame(self, poly: np.ndarray) -> np.ndarray:
        """The outline ``float[K, 2]`` expressed in the recorded object frame (inverse map)."""
        return (poly - np.asarray(self.shift)) @ rotation(self.theta)

    def as_json(self) -> dict[str, object]:
        return {"theta_deg": math.degrees(self.theta), "shift_mm": [1e3 * v for v in self.shift],
                "status": self.status, "pushes": self.pushes, "frames": self.frames,
                "refit": self.refit, "evaluations": self.evaluations}


def _lopsided(residual: np.ndarray) -> np.ndarray:
    """Residuals (m) with the tip-inside side weighted ``INSIDE_WEIGHT`` times more."""
    return np.where(residual < 0, INSIDE_WEIGHT * residual, residual)


def _robust_cost(residual: np.ndarray, weights: np.ndarray) -> float:
    """Weighted mean soft-L1 cost of lopsided residuals (m), the loss the refinement minimises."""
    z = (_lopsided(residual) / RESIDUAL_SCALE) ** 2
    return float((weights * 2 * (np.sqrt(1 + z) - 1)).sum() / weights.sum())


def _thin(points: np.ndarray) -> np.ndarray:
    """At most ``MAX_PUSH_FRAMES`` evenly spaced rows (a slow push has thousands)."""
    if len(points) <= MAX_PUSH_FRAMES:
        return points
    return points[np.linspace(0, len(points) - 1, MAX_PUSH_FRAMES).astype(int)]


def _refine(pts: np.ndarray, w: np.ndarray, poly: np.ndarray, theta0: float,
            free_theta: bool) -> tuple[float, np.ndarray, float, tuple[str, int]]:
    """Robust fit of the shift (and the rotation, near ``theta0``, if ``free_theta``): rotation,
    shift ``float[2]``, the final cost and how the solver ended (:attr:`FrameOffset.refit`,
    evaluations).

    A fixed rotation is left out of the unknowns rather than boxed in: the bounded solver keeps
    every step strictly inside all bounds at once, so a rotation pinned to ``theta0 +- 1e-9`` near
    a bound (``theta0`` = 4e-16 after rounding) stopped the shift at its start."""
    sw = np.sqrt(w)  # each push's squared residuals weigh as one residual
    prior = RESIDUAL_SCALE / SHIFT_PRIOR  # a shift of SHIFT_PRIOR costs one push's worth

    def residuals(x: np.ndarray) -> np.ndarray:
        theta, shift = (x[0], x[1:]) if free_theta else (theta0, x)
        d = signed_distance(pts @ rotation(theta).T + shift, poly) - TIP_RADIUS
        return np.concatenate([sw * _lopsided(d), prior * shift])

    lo, hi = [-MAX_OFFSET_SHIFT] * 2, [MAX_OFFSET_SHIFT] * 2
    if free_theta:
        step = math.radians(OFFSET_GRID_DEG) * 3
        x0, lo, hi = [theta0, 0.0, 0.0], [theta0 - step, *lo], [theta0 + step, *hi]
    else:
        x0 = [0.0, 0.0]
    fit = least_squares(residuals, x0, loss="soft_l1", f_scale=RESIDUAL_SCALE, bounds=(lo, hi))
    theta, shift = (float(fit.x[0]), fit.x[1:]) if free_theta else (theta0, fit.x)
    if fit.status <= 0:
        ended = "not converged"
    elif np.abs(shift).max() >= MAX_OFFSET_SHIFT * (1 - 1e-3):  # bounded steps stay inside
        ended = "at bound"
    else:
        ended = "converged"
    return theta % (2 * math.pi), shift.copy(), float(fit.cost), (ended, int(fit.nfev))


def estimate_offset(poly: np.ndarray, contacts: Sequence[np.ndarray]) -> FrameOffset:
    """The offset that puts the tip centre ``TIP_RADIUS`` from ``poly`` during contact.

    ``contacts``: per push, ``float[N_i, 2]`` tip centres in the recorded object frame at its
    contact frames. Every push weighs the same (a slow push has many more frames). A rotation
    grid (``OFFSET_GRID_DEG``) scored by the soft-L1 cost of ``distance - TIP_RADIUS`` is
    refined together with a shift (robust least squares, bounded by ``MAX_OFFSET_SHIFT``, with a
    prior that keeps the shift at zero where the contacts say nothing, e.g. along the one side
    every push of a box touched). A rotation within ``QUARTER_TURN_DEG`` of a quarter turn (up
    to the outline's own symmetry) is rounded to it and the shift refitted: the frames differ by
    quarter turns on the 61 ABS pushes (within 0.5 deg), while a free rotation fitted on 3-5
    pushes drifts by 2-5 deg (split halves), enough to put the tip 1 mm inside 10-27% of the
    other half's contact frames. A rotation farther from any quarter turn is kept as measured.
    Too few pushes: :class:`FrameOffset` ``status="default"``.
    """
    used = [_thin(c) for c in contacts if len(c) >= MIN_PUSH_FRAMES]
    frames = int(sum(len(c) for c in contacts if len(c) >= MIN_PUSH_FRAMES))
    if len(used) < MIN_OFFSET_PUSHES:
        return FrameOffset(pushes=len(used), frames=frames)
    pts = np.concatenate(used)
    w = np.concatenate([np.full(len(c), 1.0 / len(c)) for c in used])
    grid = np.deg2rad(np.arange(0.0, 360.0, OFFSET_GRID_DEG))
    score = np.array([_robust_cost(signed_distance(pts @ rotation(a).T, poly) - TIP_RADIUS, w)
                      for a in grid])
    if float(score.max() - score.min()) < SYMMETRY_TOLERANCE * float(score.min()):
        _, shift, _, ended = _refine(pts, w, poly, 0.0, free_theta=False)
        return FrameOffset(0.0, (float(shift[0]), float(shift[1])), "symmetric", len(used), frames,
                           *ended)
    theta, shift, cost, ended = _refine(pts, w, poly, float(grid[int(np.argmin(score))]), True)
    status = "measured"
    sym = symmetry_angle(poly)
    # distance to the nearest quarter turn, counting rotations the outline is invariant under
    off = min(((theta - k * math.pi / 2 + sym / 2) % sym - sym / 2 for k in range(4)), key=abs)
    if abs(off) <= math.radians(QUARTER_TURN_DEG):
        theta, shift, _, ended = _refine(pts, w, poly, (theta - off) % (2 * math.pi), False)
        status = "quarter"
    return FrameOffset(theta, (float(shift[0]), float(shift[1])), status, len(used), frames, *ended)


def symmetry_angle(poly: np.ndarray) -> float:
    """Smallest rotation (rad) of the form ``2 pi / n`` (n <= 12) mapping ``poly float[K, 2]``
    onto itself about the origin within ``SYMMETRY_MATCH``; ``2 pi`` when there is none."""
    for n in range(12, 1, -1):
        turned = poly @ rotation(2 * math.pi / n).T
        if np.abs(signed_distance(turned, poly)).max() < SYMMETRY_MATCH:
            return 2 * math.pi / n
    return 2 * math.pi


@dataclass
class ShapeCheck:
    """The contact check of one shape: tip distance to the outline over its contact frames.

    Attributes:
        shape, offset: the shape and the offset used.
        distances: ``float[N]`` signed distance (m) of the tip centre to the outline.
        pushes: pushes seen. still: names of pushes that never move the object.
    """

    shape: str
    offset: FrameOffset
    distances: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pushes: int = 0
    still: list[str] = field(default_factory=list)

    @property
    def inside_fraction(self) -> float:
        """Fraction of contact frames with the tip more than ``INSIDE_TOLERANCE`` inside."""
        if not len(self.distances):
            return float("nan")
        return float(np.mean(self.distances < TIP_RADIUS - INSIDE_TOLERANCE))

    def as_json(self) -> dict[str, object]:
        q = (np.quantile(self.distances, QUANTILES) * 1e3).tolist() if len(self.distances) else []
        return {"shape": self.shape, "pushes": self.pushes, "contact_frames": len(self.distances),
                "offset": self.offset.as_json(),
                "distance_mm_quantiles": dict(zip([f"q{int(100 * p):02d}" for p in QUANTILES],
                                                  q, strict=False)),
                "inside_fraction": self.inside_fraction, "still_pushes": list(self.still)}
