"""Speed of one learned step against MuJoCo on the same scene (``fignet-gym bench``).

Prints, for a push scene (one MIT prism, a cylindrical pusher, a floor) and a 6-object tossing scene
of MOVi-A-like size: the median milliseconds of a learned step split into collision detection, graph
building, network and shape matching; the number of face-face edges; and MuJoCo's time to advance the
same scene by the same simulated time, as a ratio. Timings on shared cores are noisy: compare the
ratios, measured in one run, rather than absolute numbers.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from fignet_gym.collision import find_face_contacts
from fignet_gym.geometry import kabsch
from fignet_gym.graph import build_graph
from fignet_gym.mjcf import TossObject, push_scene_xml, toss_scene_xml
from fignet_gym.scene import MeshOptions, Scene
from fignet_gym.simulator import LearnedSimulator, SimulatorConfig


@dataclass
class BenchScene:
    """A compiled scene at a contact-rich state: ``history float[H, O, 7]``."""

    name: str
    model: mujoco.MjModel
    data: mujoco.MjData
    scene: Scene
    history: torch.Tensor
    substeps: int
    radius: float


def _settled(name: str, xml: str, substeps: int, settle_steps: int, radius: float,
             opts: MeshOptions, mocap_velocity: np.ndarray | None = None) -> BenchScene:
    """Simulate ``settle_steps`` learned-step lengths in MuJoCo so objects are in contact."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    if model.nkey:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    scene = Scene.from_mjmodel(model, opts)
    poses = []
    dt = model.opt.timestep * substeps
    for _ in range(settle_steps):
        if mocap_velocity is not None:
            data.mocap_pos[0] += mocap_velocity * dt
        mujoco.mj_step(model, data, substeps)
        poses.append(scene.poses_from_data(data))
    hist = torch.tensor(np.stack(poses[-3:]), dtype=torch.float32)
    return BenchScene(name, model, data, scene, hist, substeps, radius)


def push_bench_scene() -> BenchScene:
    """rect1 pushed by the tip at 0.1 m/s, in contact after 1 s."""
    xml = push_scene_xml("rect1", tip_xy=(-0.07, 0.01))
    return _settled("push (rect1 + tip + floor)", xml, 10, 50, 0.02, MeshOptions(),
                    np.array([0.1, 0.0, 0.0]))


def toss_bench_scene() -> BenchScene:
    """Six MOVi-A-sized objects (about 60 nodes each) dropped in a cluster, after landing."""
    opts = MeshOptions(sphere_subdivisions=1, cylinder_sections=30, box_subdivisions=1)
    objs = [TossObject(s, 0.7, m) for s, m in
            [("cube", "metal"), ("sphere", "rubber"), ("cylinder", "metal"),
             ("sphere", "metal"), ("cylinder", "rubber"), ("cube", "rubber")]]
    rng = np.random.default_rng(0)
    poses = []
    for i in range(6):
        q = rng.normal(size=4)
        poses.append([1.5 * (i % 3) - 1.5, 1.6 * (i // 3) - 0.8, 1.0 + 0.4 * i, *(q / np.linalg.norm(q))])
    xml = toss_scene_xml(objs, mesh_options=opts, poses=np.array(poses),
                         velocities=np.zeros((6, 6)))
    return _settled("toss (6 objects + floor)", xml, 10, 60, 0.1, opts)


def _median_ms(samples: list[float]) -> float:
    return 1000.0 * statistics.median(samples)


@torch.no_grad()
def time_learned_step(sim: LearnedSimulator, b: BenchScene, repeats: int, batch: int = 1) -> dict[str, float]:
    """Median ms of each phase of a learned step on ``batch`` copies of the scene."""
    scene = b.scene.repeat(batch) if batch > 1 else b.scene
    hist = b.history.repeat(1, batch, 1)
    nxt = hist[-1]
    parts: dict[str, list[float]] = {"collision": [], "graph": [], "network": [], "shape_match": [],
                                     "total": []}
    edges = []
    for _ in range(repeats + 2):
        t0 = time.perf_counter()
        node_hist = scene.node_positions(hist)
        contacts = find_face_contacts(node_hist[-1], scene.faces, scene.face_object,
                                      scene.collision_pairs, sim.config.collision_radius)
        t1 = time.perf_counter()
        graph = build_graph(scene, node_hist, scene.com_positions(hist), scene.node_positions(nxt),
                            scene.com_positions(nxt), contacts)
        t2 = time.perf_counter()
        acc = sim.predict_acceleration(graph)
        t3 = time.perf_counter()
        pred = 2 * node_hist[-1] - node_hist[-2] + acc
        kabsch(scene.ref_vertices, pred, scene.node_object, scene.num_objects)
        t4 = time.perf_counter()
        for k, v in zip(parts, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t4 - t0)):
            v_list = parts[k]
            v_list.append(v)
        edges.append(contacts.sender_face.shape[0])
    out = {k: _median_ms(v[2:]) for k, v in parts.items()}
    out["face_edges"] = float(statistics.median(edges)) / batch
    return out


def time_mujoco(b: BenchScene, repeats: int) -> float:
    """Median ms for MuJoCo to advance the scene by one learned step (``substeps`` mj_steps)."""
    samples = []
    for _ in range(repeats):
        d = mujoco.MjData(b.model)
        d.qpos[:], d.qvel[:] = b.data.qpos, b.data.qvel
        d.mocap_pos[:], d.mocap_quat[:] = b.data.mocap_pos, b.data.mocap_quat
        t0 = time.perf_counter()
        mujoco.mj_step(b.model, d, b.substeps)
        samples.append(time.perf_counter() - t0)
    return _median_ms(samples)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print one table per scene."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    run(p.parse_args(argv))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the ``bench`` command."""
    p.add_argument("--repeats", type=int, default=20, help="timed repetitions (median reported)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    p.add_argument("--batch", type=int, nargs="*", default=[1, 16], help="scene batch sizes")


def run(args: argparse.Namespace) -> None:
    """Benchmark paper-size and CPU-size models on the push and toss scenes."""
    if args.threads:
        torch.set_num_threads(args.threads)
    configs = {
        "paper (latent 128, 10 MP, mesh edges)": dict(latent_size=128, message_passing_steps=10),
        "cpu (latent 64, 5 MP, no mesh edges)": dict(latent_size=64, message_passing_steps=5,
                                                     mesh_edges=False),
    }
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; mujoco {mujoco.__version__}")
    for b in (push_bench_scene(), toss_bench_scene()):
        mj = time_mujoco(b, args.repeats * 5)
        print(f"\n== {b.name}: {b.scene.num_objects} objects, {b.scene.num_nodes} nodes, "
              f"{b.scene.faces.shape[0]} faces, d_c = {b.radius} m; MuJoCo {b.substeps} substeps: "
              f"{mj:.3f} ms per learned-step length")
        print(f"{'model':40s} {'B':>3s} {'total':>8s} {'collide':>8s} {'graph':>7s} {'network':>8s} "
              f"{'kabsch':>7s} {'ff-edges':>8s} {'x MuJoCo':>9s} {'coll+graph':>10s}")
        for label, kw in configs.items():
            sim = LearnedSimulator(SimulatorConfig(collision_radius=b.radius, **kw)).eval()
            for batch in args.batch:
                r = time_learned_step(sim, b, args.repeats, batch)
                per = r["total"] / batch
                share = (r["collision"] + r["graph"]) / r["total"]
                print(f"{label:40s} {batch:3d} {r['total']:8.2f} {r['collision']:8.2f} "
                      f"{r['graph']:7.2f} {r['network']:8.2f} {r['shape_match']:7.2f} "
                      f"{r['face_edges']:8.0f} {per / mj:9.1f} {share:10.0%}")
    print("\nms are medians per step (for B > 1: for all B scenes at once); 'x MuJoCo' is the "
          "per-scene learned step over MuJoCo's time for the same simulated time.")


if __name__ == "__main__":
    main()
