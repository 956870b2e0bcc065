"""Micro-benchmark of :func:`fignet_gym.simulator.collision.find_face_contacts` on two typical scenes.

``fignet-gym bench collision [--radii 0.005 0.01 0.02] [--repeats 100] [--threads 1]``

* ``pile``: 6 objects of 60 nodes (116 faces) each, in a 3 x 2 block resting on a 2-triangle
  floor, each touching (1 mm overlap) its neighbours: 8 cm objects, so ``d_c = 0.01`` is 12 %;
* ``push x64``: 64 batched push scenes: a 10-sided prism (20 nodes, 13 mm thick) on the floor and
  a 12-sided 4.75 mm pusher tip touching it.

Prints, per scene and radius, the median wall and CPU (this thread) time of ``repeats`` calls. On
shared cores wall time includes waiting for the CPU; thread CPU time does not.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch
import trimesh

from fignet_gym.simulator.collision import find_face_contacts
from fignet_gym.simulator.scene import Scene

_FLOOR = trimesh.Trimesh([[-20, -20, 0], [20, -20, 0], [20, 20, 0], [-20, 20, 0]],
                         [[0, 1, 2], [0, 2, 3]], process=False)


def _scene(meshes: list[np.ndarray], faces: list[np.ndarray], kinds: list[int]) -> Scene:
    props = np.tile([1.0, 0.5, 0.0], (len(meshes), 1))
    return Scene.from_meshes(meshes, faces, kinds, props)


def pile_scene(rng: np.random.Generator) -> Scene:
    """6 random convex objects (60 nodes each), a 3 x 2 block on the floor, neighbours touching."""
    verts, faces = [], []
    for k in range(6):
        d = rng.normal(size=(60, 3))
        hull = trimesh.convex.convex_hull(d / np.linalg.norm(d, axis=1, keepdims=True) * 0.04)
        v = hull.vertices - hull.bounds.mean(0)
        pitch = 0.08 - 0.001  # 1 mm overlap between neighbours
        v = v + [pitch * (k % 3), pitch * (k // 3), -v[:, 2].min() - 0.0005]
        verts.append(v)
        faces.append(hull.faces)
    return _scene(verts + [_FLOOR.vertices], faces + [_FLOOR.faces], [0] * 6 + [1])


def push_scene() -> Scene:
    """A 10-sided 13 mm thick prism on the floor and a 4.75 mm pusher tip touching its side."""
    prism = trimesh.creation.cylinder(radius=0.05, height=0.013, sections=10)
    prism = trimesh.Trimesh(prism.vertices[np.abs(prism.vertices[:, 2]) > 0],  # drop cap centres
                            process=False).convex_hull
    tip = trimesh.creation.cylinder(radius=0.00475, height=0.03, sections=12)
    pv = prism.vertices + [0, 0, 0.0065 - 0.0002]
    tv = tip.vertices + [0.05 + 0.00475 + 0.0005, 0, 0.017]
    return _scene([pv, tv, _FLOOR.vertices], [prism.faces, tip.faces, _FLOOR.faces], [0, 2, 1])


def _time(fn, repeats: int) -> tuple[float, float]:
    """Median wall and thread-CPU seconds of ``fn()``."""
    for _ in range(5):
        fn()
    wall, cpu = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.thread_time()
        fn()
        cpu.append(time.thread_time() - c)
        wall.append(time.perf_counter() - w)
    return statistics.median(wall), statistics.median(cpu)


def run(args: argparse.Namespace) -> None:
    """``fignet-gym bench collision``: face-contact detection timings at each radius."""
    rng = np.random.default_rng(0)
    pile = pile_scene(rng)
    push = push_scene().repeat(64)
    jitter = torch.tensor(rng.normal(size=(push.num_nodes, 3)) * 2e-4, dtype=torch.float32)
    cases = [("pile", pile, pile.ref_vertices), ("push x64", push, push.ref_vertices + jitter)]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    for name, scene, pos in cases:
        pairs = scene.collision_pairs
        for radius in args.radii:
            def detect(scene=scene, pos=pos, pairs=pairs, radius=radius):
                return find_face_contacts(pos, scene.faces, scene.face_object, pairs, radius)

            contacts = detect()
            wall, cpu = _time(detect, args.repeats)
            print(f"{name:9s} ({scene.faces.shape[0]:5d} faces, {pairs.shape[0]:3d} object pairs) "
                  f"d_c {radius:5.3f}: {contacts.num_contacts:6d} contacts, "
                  f"wall {wall * 1e3:6.2f} ms, cpu {cpu * 1e3:6.2f} ms")

