"""The windows ``push-real`` was trained and scored on (until ``import-mit`` cuts windows itself).

Usage: ``python scripts/push_real_windows.py WHOLE.h5 OUT.h5``, where ``WHOLE.h5`` is
``fignet-gym import-mit <folder> --out WHOLE.h5 --duration 0`` (whole pushes, dt 0.02 s).
One window per push: from ``LEAD`` frames before the object first moves (more than ``MOVE_M``
from its first position or turned more than ``MOVE_DEG``; frame 0 if it never does or already
moves) to at most ``MAX_S`` seconds (plus the 3 given poses) later.
"""
import dataclasses
import sys

import numpy as np

from fignet_gym.data.format import load_trajectories, write_trajectories

src, dst = sys.argv[1], sys.argv[2]
MAX_S, MOVE_M, MOVE_DEG, LEAD = 1.5, 1e-3, 1.0, 2
out, report = [], []
for t in load_trajectories(src):
    obj = t.poses[:, 1]
    d = np.linalg.norm(obj[:, :2] - obj[0, :2], axis=1)
    yaw = 2 * np.arctan2(obj[:, 6], obj[:, 3])
    dy = np.rad2deg(np.abs(np.angle(np.exp(1j * (yaw - yaw[0])))))
    moving = np.nonzero((d > MOVE_M) | (dy > MOVE_DEG))[0]
    start = max(0, int(moving[0]) - LEAD) if len(moving) else 0
    end = min(t.num_steps, start + int(round(MAX_S / t.dt)) + 3)
    sl = slice(start, end)
    meta = dict(t.metadata, window_start_s=start * t.dt, moved=bool(len(moving)))
    out.append(dataclasses.replace(t, poses=t.poses[sl].copy(), metadata=meta,
                                   extras={k: v[sl] for k, v in t.extras.items()}))
    report.append((t.name, start, end - start, float(d[-1])))
write_trajectories(dst, out)
print(f"{len(out)} windows; never moving: {sum(1 for r in report if r[1]==0)}; "
      f"frames {min(r[2] for r in report)}-{max(r[2] for r in report)}")
