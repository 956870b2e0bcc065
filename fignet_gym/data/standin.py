"""A stand-in for the MIT Pushing Dataset, in its raw file format (``fignet-gym mit-standin``).

The real pushes cannot be downloaded here; these exercise the same path (``import-mit``, then
``sim2real``) with the troubles real data has, so that an analytic model fitted to them is not
handed the truth:

* contact parameters outside the fitted family: every push draws its own object-floor and
  tip-object friction (``sim2real`` fits one value of each to the whole set), and the tip's
  contact is softer than the object's (one ``solref`` is fitted for all geoms);
* tracking noise: Gaussian on every tracked sample (object x, y, yaw; tip x, y), three
  unsynchronised ~250 Hz streams as in the real files;
* pusher penetration: the simulated tip is ``penetration`` thinner than the 4.75 mm tip of the
  importer's scene, so in contact the recorded tip overlaps the object by about that much.

Files are written as ``motion_surface=abs_shape=<shape>_a=0_v=<mm/s>_i=<side>_s=<pos>_t=<rad>
_rep=<k>.json`` with ``tip_pose``, ``object_pose`` and ``ft_wrench`` (zeros plus noise: forces
are not simulated) rows of (unix time, ...).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from fignet_gym.data.generate import PushConfig, generate_push

#: Sample period (s) of the simulated tracks (the real streams are ~250 Hz).
STANDIN_PERIOD = 0.004
#: The stand-in files (``--force`` replaces exactly these).
STANDIN_GLOB = "motion_surface=*.json"
#: Tip radius (m) of the importer's scene (``push_scene_xml``) and of the real pusher.
TIP_RADIUS = 0.00475


def _yaw(quat: np.ndarray) -> np.ndarray:
    """Yaw (rad) of quaternions ``float[T, 4]`` (w x y z) of planar motion."""
    w, x, y, z = quat.T
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def write_mit_standin(out: str | os.PathLike, num: int = 120, seed: int = 0, *,
                      position_noise: float = 5e-4, yaw_noise_deg: float = 0.5,
                      tip_noise: float = 3e-4, penetration: float = 1e-3,
                      friction_range: tuple[float, float] = (0.1, 0.4),
                      tip_friction_range: tuple[float, float] = (0.1, 0.5),
                      duration: float = 0.8, force: bool = False) -> list[Path]:
    """Write ``num`` stand-in pushes into ``out`` (see the module docstring); returns the files.

    Push ``i`` uses ``numpy.random.default_rng([seed, i])`` for the push and its noise. A
    folder that is not empty is refused (``import-mit`` would import its pushes together with
    these), unless ``force``, which first deletes the stand-in pushes (``motion_surface=*.json``)
    already there.
    """
    if not 0 <= penetration < TIP_RADIUS:
        raise ValueError(f"penetration must be in [0, {TIP_RADIUS}) m, got {penetration}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"--out {out}: is a file; --out must be a folder")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            first = min(p.name for p in out.iterdir())
            raise FileExistsError(f"--out {out}: is not empty ({first}, ...): its pushes would be "
                                  "imported with these; pass --force to replace the stand-in "
                                  "pushes in it, or choose an empty folder")
        for old in out.glob(STANDIN_GLOB):
            old.unlink()
    out.mkdir(parents=True, exist_ok=True)
    cfg = replace(PushConfig(), substeps=int(round(STANDIN_PERIOD / PushConfig().timestep)),
                  duration=duration, tip_radius=TIP_RADIUS - penetration,
                  friction_range=friction_range, tip_friction_range=tip_friction_range)
    files = []
    for i in range(num):
        rng = np.random.default_rng([seed, i])
        traj = generate_push(rng, cfg)
        t_sim = np.arange(traj.num_steps) * traj.dt
        obj = traj.poses[:, 1]
        tip = traj.poses[:, 2]
        obj_xyyaw = np.column_stack([obj[:, :2], np.unwrap(_yaw(obj[:, 3:]))])
        t0 = 1.46e9 + 100.0 * i
        streams = {}
        for key, offset, values, noise in (
                ("object_pose", 0.0011, obj_xyyaw, [position_noise, position_noise,
                                                    math.radians(yaw_noise_deg)]),
                ("tip_pose", 0.0023, np.column_stack([tip[:, :2], np.zeros(len(tip))]),
                 [tip_noise, tip_noise, 0.0]),
                ("ft_wrench", 0.0031, np.zeros((len(tip), 3)), [0.05, 0.05, 0.002])):
            times = np.arange(offset, t_sim[-1], STANDIN_PERIOD * rng.uniform(0.97, 1.03))
            rows = np.column_stack([np.interp(times, t_sim, values[:, c]) for c in range(3)])
            rows += rng.normal(size=rows.shape) * np.asarray(noise)
            if key == "object_pose":  # stored wrapped, like the real files
                rows[:, 2] = (rows[:, 2] + np.pi) % (2 * np.pi) - np.pi
            streams[key] = np.column_stack([t0 + times, rows]).tolist()
        m = traj.metadata
        name = (f"motion_surface=abs_shape={m['shape']}_a=0_v={m['speed_mm_s']:.0f}"
                f"_i={m['side']:.3f}_s={m['position']:.3f}_t={math.radians(m['angle_deg']):.3f}"
                f"_rep={i:04d}.json")
        path = out / name
        path.write_text(json.dumps({**streams, "standin": {
            "friction": m["friction"], "tip_friction": m["tip_friction"], "seed": seed,
            "penetration_m": penetration, "position_noise_m": position_noise,
            "yaw_noise_deg": yaw_noise_deg, "tip_noise_m": tip_noise}}))
        files.append(path)
    return files
