"""Zero-shot or trained? The shipped push models on shapes they never saw (issue 41, item 6).

    python scripts/pusht_generalisation.py --out runs/generalisation            # the whole table
    python scripts/pusht_generalisation.py --out runs/g --num 40 --steps 20     # a smoke run

For each shape below (none is an MIT Pushing object, none is the T) it writes a push scene with
the T's settings (:func:`fignet_gym.mjcf.push_scene_text`: 13 mm steel prisms, the tip, contacts),
generates seeded MuJoCo pushes with ``generate("scene")`` (the T's stroke distribution), trains
one model on all of them (``push-finetune`` from ``push``, as ``pusht`` was trained) and scores
``push``, ``pusht`` and that model on each shape's held-out pushes, plus the T's test pushes if
``--pusht-test`` names them: errors at each push's last frame (1.5 s) as % of no motion
(``fignet-gym evaluate``; at 0.5 s most strokes have not reached the body yet). A rerun reuses
the data, the trained model and every score already written.
Writes ``table.md`` and ``table.json`` in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

import numpy as np

from fignet_gym.mjcf import prism_mesh, push_scene_text
from fignet_gym.mjcf.assets import mesh_asset
from fignet_gym.mjcf.push import _polygon_moments
from fignet_gym.mjcf.pusht import PUSHT_DENSITY, pusht_scene_xml

THICKNESS = 0.013


def _box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def _pebble() -> np.ndarray:
    """A seeded irregular convex polygon (the hull of 12 random points), about 9 cm across."""
    from scipy.spatial import ConvexHull

    pts = np.random.default_rng(41).normal(0.0, 0.025, (12, 2))
    return pts[ConvexHull(pts).vertices]


#: Shapes as convex CCW pieces (m), before centring on their area centroid.
SHAPES: dict[str, list[np.ndarray]] = {
    "L": [_box(0.0, 0.0, 0.09, 0.025), _box(0.0, 0.025, 0.025, 0.07)],
    "triangle": [np.array([[0.0, 0.0], [0.11, 0.0], [0.055, 0.11 * math.sqrt(3) / 2]])],
    "big box": [_box(0.0, 0.0, 0.16, 0.10)],
    "pebble": [_pebble()],
}


def shape_xml(name: str) -> str:
    """The push scene of ``SHAPES[name]``: each piece a mesh geom, the frame at the centroid;
    MuJoCo computes mass and inertia from the meshes at the T's density."""
    pieces = SHAPES[name]
    moments = [_polygon_moments(p)[:2] for p in pieces]
    total = sum(a for a, _ in moments)
    centroid = sum(a * c for a, c in moments) / total
    meshes, geoms = [], []
    for k, piece in enumerate(pieces):
        verts, faces = prism_mesh(piece - centroid, THICKNESS)
        meshes.append(mesh_asset(f"piece{k}", verts, faces))
        geoms.append(f'<geom type="mesh" mesh="piece{k}" density="{PUSHT_DENSITY}" '
                     f'friction="0.25 0.005 0.0001" solref="0.005 1"/>')
    return push_scene_text(
        name.replace(" ", "_"), timestep=0.002, meshes="\n    ".join(meshes),
        geoms="\n      ".join(geoms), mass=None, com=None, inertia=None,
        thickness=THICKNESS, object_pose=(0.0, 0.0, 0.0), tip_xy=(-0.15, 0.0), tip_z=0.021,
        tip_radius=0.00475, tip_half_height=0.02, floor_half_size=0.5, friction=0.25,
        tip_friction=0.25, contact_timeconst=0.005, tip_dampratio=0.5, cone="elliptic")


def main(argv: list[str] | None = None) -> dict[str, dict[str, list[float]]]:
    """Build, generate, train and score (module docstring); returns the table as a dict."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="runs/generalisation")
    p.add_argument("--num", type=int, default=600, help="training pushes per shape")
    p.add_argument("--test", type=int, default=100, help="held-out pushes per shape")
    p.add_argument("--steps", type=int, default=6000, help="optimiser steps of the trained model")
    p.add_argument("--pusht", default="pusht", help="the T model (name or checkpoint)")
    p.add_argument("--pusht-test", help="the T's held-out pushes, scored too (HDF5)")
    p.add_argument("--train-only", action="store_true", help="stop after training")
    args = p.parse_args(argv)

    from fignet_gym.data.format import load_trajectories, write_trajectories
    from fignet_gym.data.generate import generate
    from fignet_gym.data.scene_generator import SceneConfig
    from fignet_gym.train.evaluation import evaluate
    from fignet_gym.train.trainer import train_from_files

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "T.xml").write_text(pusht_scene_xml())
    train, valid, tests = [], [], {}
    for k, name in enumerate(SHAPES):
        slug = name.replace(" ", "_")
        xml = out / f"{slug}.xml"
        xml.write_text(shape_xml(name))
        # The T's stroke distribution (docs/envs.md, PushT-v0).
        cfg = SceneConfig.from_file(xml, target="object", speed=(0.03, 0.14),
                                    offset=(-0.05, 0.05), segments=3, duration=1.5)
        splits = (("train", args.num, 100 + k), ("valid", max(1, args.test // 4), 900 + k),
                  ("test", args.test, 500 + k))
        for split, num, seed in splits:
            path = out / f"{slug}_{split}.h5"
            if not path.exists():
                generate("scene", num, seed, path, config=cfg)
        train.append(str(out / f"{slug}_train.h5"))
        valid.extend(load_trajectories(out / f"{slug}_valid.h5"))
        tests[name] = str(out / f"{slug}_test.h5")
    if args.pusht_test:
        tests["T"] = args.pusht_test
    run = out / "run"
    if not (run / "best.pt").exists():
        write_trajectories(out / "valid.h5", valid)  # every shape's validation pushes, pooled
        tiny = args.steps < 50
        overrides = {"training.steps": args.steps, "simulator.canonical_frame": True,
                     "training.valid_every": max(1, min(1000, args.steps // 3))}
        if tiny:
            overrides.update({"training.batch_size": 2, "training.unroll_steps": 1,
                              "training.valid_trajectories": 1})
        train_from_files(train, str(out / "valid.h5"), "push-finetune", str(run), overrides=overrides,
                         init="push", force=True)
    if args.train_only:
        return {}
    models = {"push (zero-shot)": "push", "pusht (zero-shot)": args.pusht,
              "trained on the four shapes": str(run / "best.pt")}
    table: dict[str, dict[str, list[float]]] = {}
    for shape, data in tests.items():
        for label, ckpt in models.items():
            where = out / "eval" / f"{shape}_{label.split()[0]}"
            if (where / "metrics.json").exists():  # scored before: a rerun only rebuilds the table
                m = json.loads((where / "metrics.json").read_text())
            else:
                m = evaluate(ckpt, data, str(where), num=args.test, horizon=25, videos=0)
            # At each push's last frame (1.5 s): at 0.5 s most strokes have not reached the body.
            table.setdefault(shape, {})[label] = [100 * m["translation_rmse_last_ratio_still"],
                                                  100 * m["rotation_deg_last_ratio_still"]]
    head = "| shape | " + " | ".join(models) + " |"
    lines = [head, "|---" * (len(models) + 1) + "|"]
    for shape, row in table.items():
        cells = [f"{t:.0f}% / {r:.0f}%" for t, r in row.values()]
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "table.json").write_text(json.dumps(table, indent=1))
    print("\n".join(lines))
    return table


if __name__ == "__main__":
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    main()
