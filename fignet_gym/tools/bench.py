"""Speed of one learned step against MuJoCo on the same scene (``fignet-gym bench step``).

Prints, for a push scene (one MIT prism, a cylindrical pusher, a floor) and a 6-object tossing scene
of MOVi-A-like size: the median milliseconds of ``LearnedSimulator.step`` (the code path users run)
split into collision detection, graph building, network and shape matching; the number of face-face
edges; and MuJoCo's time to advance the same scene by the same simulated time, as a ratio. Timings on
shared cores are noisy: compare the ratios, measured in one run, rather than absolute numbers. On a
machine whose cores are busy, use ``--threads 1``: OpenMP threads spin-waiting for a descheduled peer
make more threads much slower (``OMP_WAIT_POLICY=PASSIVE`` limits the damage).

``bench shipped``: the shipped models at each ``--batch`` size, stepped as ``FIGNetDynamics``
does, with the network's analytic FLOPs and its GFLOP/s next to plain ``torch.mm`` on the same
shapes (:mod:`fignet_gym.tools.bench_limits`). ``bench rollout``: ``Dynamics.rollout`` scene-steps
per second, learned against ``mujoco.rollout``. ``bench ppo``: env steps per CPU-second of the whole
PPO loop on MuJoCo and on FIGNet (:mod:`fignet_gym.agents.ppo.bench`; ``--repeats`` is its number
of repetitions). ``--json PATH`` writes their figures. Timings are CPU seconds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from fignet_gym.dynamics.learned import CHUNK_NODES, batched_step
from fignet_gym.mjcf import TossObject, push_scene_xml, toss_scene_xml
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.model import LearnedSimulator, SimulatorConfig
from fignet_gym.simulator.scene import MeshOptions, Scene
from fignet_gym.tools.bench_limits import matmul_rate, network_flops, time_rollouts


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


class _PhaseTimer:
    """Times the phases of the simulator's own ``step``: while active, the instance's
    ``collide``, ``build_inputs`` and ``predict_acceleration`` are wrapped by timers (instance
    attributes shadow the methods), so the step measured is exactly the one users run."""

    PHASES = ("collide", "build_inputs", "predict_acceleration")

    def __init__(self, sim: LearnedSimulator) -> None:
        self.sim = sim
        self.seconds: dict[str, float] = {}
        self.face_edges = 0

    def _wrap(self, name: str) -> Callable[..., Any]:
        method = getattr(self.sim, name)

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.process_time()
            out = method(*args, **kwargs)
            # Summed: a chunked batch calls each phase once per chunk.
            self.seconds[name] = self.seconds.get(name, 0.0) + time.process_time() - t0
            if name == "collide" and out[0] is not None:
                self.face_edges += out[0].num_contacts
            return out

        return timed

    def __enter__(self) -> _PhaseTimer:
        for name in self.PHASES:
            setattr(self.sim, name, self._wrap(name))
        return self

    def __exit__(self, *exc: object) -> None:
        for name in self.PHASES:
            delattr(self.sim, name)


def time_learned_step(sim: LearnedSimulator, b: BenchScene, repeats: int, batch: int = 1,
                      chunked: bool = False) -> dict[str, float]:
    """Median CPU ms of each phase of ``sim.step`` on ``batch`` copies of the scene (``chunked``:
    through :func:`~fignet_gym.dynamics.learned.batched_step`, as ``FIGNetDynamics`` steps them).

    Phases: ``collision`` (:meth:`LearnedSimulator.collide`), ``graph`` (the rest of
    :meth:`LearnedSimulator.build_inputs`: poses to node positions and features), ``network``
    (:meth:`LearnedSimulator.predict_acceleration`: normalisation and the graph network),
    ``shape_match`` (the rest of the step: integration and shape matching).
    """
    scene = b.scene.repeat(batch) if batch > 1 else b.scene
    hist = b.history.repeat(1, batch, 1)
    nxt = hist[-1]
    parts: dict[str, list[float]] = {k: [] for k in ("collision", "graph", "network", "shape_match", "total")}
    edges = []
    with _PhaseTimer(sim) as timer:
        for _ in range(repeats + 2):
            timer.seconds, timer.face_edges = {}, 0
            t0 = time.process_time()
            if chunked:
                batched_step(sim, b.scene, batch, hist, nxt)
            else:
                sim.step(scene, hist, nxt)
            total = time.process_time() - t0
            sec = timer.seconds
            parts["collision"].append(sec["collide"])
            parts["graph"].append(sec["build_inputs"] - sec["collide"])
            parts["network"].append(sec["predict_acceleration"])
            parts["shape_match"].append(total - sec["build_inputs"] - sec["predict_acceleration"])
            parts["total"].append(total)
            edges.append(timer.face_edges)
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
        t0 = time.process_time()
        mujoco.mj_step(b.model, d, b.substeps)
        samples.append(time.process_time() - t0)
    return _median_ms(samples)


def shipped_table(args: argparse.Namespace, dtype: torch.dtype, scenes: list[BenchScene]
                  ) -> list[dict[str, Any]]:
    """Per-scene cost of batched steps of the shipped models, with FLOPs and the matmul limit."""
    rows = []
    print(f"\n== shipped models, steps batched as FIGNetDynamics does (chunks of <= {CHUNK_NODES} "
          "nodes); CPU ms per scene")
    print(f"{'scene':6s} {'B':>5s} {'total':>7s} {'network':>8s} {'x B=1':>6s} {'MFLOP':>7s} "
          f"{'GFLOP/s':>8s} {'mm limit':>8s} {'of limit':>8s} {'floor':>6s}"
          + ("" if dtype == torch.float32 else f" {'x f32 B=1':>9s}"))
    for b in scenes:
        name = b.name.split()[0]
        sim = load_pretrained(name).eval()
        # A faster precision is measured against what users get by default: one float32 scene
        # (in float32, the first row's own single scene).
        f32_single = None if dtype == torch.float32 else \
            time_learned_step(sim, b, args.repeats, 1, chunked=True)["total"]
        sim.inference_dtype = dtype
        flops, _ = network_flops(sim, b.scene, b.history)
        per_scene = sum(flops.values())
        single = None
        for batch in args.batch:
            r = time_learned_step(sim, b, max(2, args.repeats // max(1, batch // 16)), batch, chunked=True)
            chunk = max(1, min(batch, CHUNK_NODES // b.scene.num_nodes))
            _, shapes = network_flops(sim, b.scene.repeat(chunk), b.history.repeat(1, chunk, 1))
            limit = matmul_rate(shapes, repeats=3, dtype=dtype)
            achieved = per_scene * batch / (r["network"] / 1000) / 1e9
            total, net = r["total"] / batch, r["network"] / batch
            single = single or total
            f32_single = f32_single or single
            # The per-scene ms of the matmuls alone at the measured rate: no batching can go below it.
            floor_ms = per_scene / (limit * 1e9) * 1000
            rows.append({"scene": name, "batch": batch, "ms_per_scene": total,
                         "network_ms_per_scene": net, "ratio_to_single": total / single,
                         "mflop_per_scene_step": per_scene / 1e6,
                         "mflop_per_block": {k: v / 1e6 for k, v in flops.items()},
                         "gflops": achieved, "matmul_gflops_same_shapes": limit,
                         "fraction_of_limit": achieved / limit,
                         "matmul_floor_ms_per_scene": floor_ms,
                         "ratio_floor": floor_ms / single,
                         "ratio_to_float32_single": total / f32_single})
            print(f"{name:6s} {batch:5d} {total:7.3f} {net:8.3f} {total / single:6.2f} "
                  f"{per_scene / 1e6:7.1f} {achieved:8.1f} {limit:8.1f} {achieved / limit:8.0%} "
                  f"{floor_ms / single:6.2f}"
                  + ("" if dtype == torch.float32 else f" {total / f32_single:9.2f}"))
    print("'x B=1': per-scene cost over the first batch size's; 'mm limit': plain torch.mm GFLOP/s "
          "in the network's precision on exactly its matmul shapes (one chunk), measured now; "
          "'floor': the lowest 'x B=1' these FLOPs allow, the matmuls alone at that rate"
          + ("" if dtype == torch.float32 else "; 'x f32 B=1': per-scene cost over one float32 "
             "scene's (the default mode)"))
    return rows


def rollout_table(args: argparse.Namespace, scenes: list[BenchScene]) -> dict[str, Any]:
    """Dynamics.rollout throughput of the shipped models against mujoco.rollout."""
    out: dict[str, Any] = {}
    for b in scenes:
        name = b.name.split()[0]
        vel = np.array([0.1, 0.0, 0.0]) if b.model.nmocap else None
        rows = time_rollouts(b.model, b.data, b.substeps, name, args.rollout_batch,
                             args.rollout_steps, vel, precision=args.dtype)
        out[name] = rows
        print(f"\n== Dynamics.rollout, {name}, {args.rollout_steps} steps: scene-steps per second "
              "(learned: CPU s of this process)")
        keys = [k for k in rows[0] if k not in ("batch", "steps")]
        print(f"{'B':>5s} " + " ".join(f"{k:>18s}" for k in keys) + f" {'learned s':>10s}")
        for r in rows:
            print(f"{r['batch']:5d} " + " ".join(f"{r[k]['scene_steps_per_s']:18.0f}" for k in keys)
                  + f" {r['learned']['seconds']:10.2f}")
    return out


def _report_header(args: argparse.Namespace) -> dict[str, Any]:
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device cpu, network "
          f"in {args.dtype}; mujoco {mujoco.__version__}; cuda available: "
          f"{torch.cuda.is_available()} (not benchmarked)")
    return {"torch": torch.__version__, "threads": torch.get_num_threads(), "device": "cpu",
            "dtype": args.dtype}


def _write_json(path: str | None, report: dict[str, Any]) -> None:
    if path:
        Path(path).write_text(json.dumps(report, indent=1))
        print(f"wrote {path}")


def run_ppo(args: argparse.Namespace) -> None:
    """``bench ppo``: env steps per CPU-second of the PPO loop on MuJoCo and on FIGNet."""
    # deferred: stable-baselines3 and TensorBoard; `fignet-gym --help` imports this module
    from fignet_gym.agents.ppo.bench import ppo_throughput_table

    table, rows = ppo_throughput_table(args.ppo_env, *args.ppo_setting, repeats=args.repeats)
    print(table)
    _write_json(args.json, {"ppo": rows})


def run_shipped(args: argparse.Namespace) -> None:
    """``bench shipped``: the shipped models' batched step against the machine's matmul rate."""
    report = _report_header(args)
    report["shipped"] = shipped_table(args, getattr(torch, args.dtype),
                                      [push_bench_scene(), toss_bench_scene()])
    _write_json(args.json, report)


def run_rollout(args: argparse.Namespace) -> None:
    """``bench rollout``: ``Dynamics.rollout`` scene-steps per second, learned vs ``mujoco.rollout``."""
    report = _report_header(args)
    report["rollout"] = rollout_table(args, [push_bench_scene(), toss_bench_scene()])
    _write_json(args.json, report)


def run_step(args: argparse.Namespace) -> None:
    """``bench step``: paper-size and CPU-size models against MuJoCo on the push and toss scenes."""
    configs = {
        "paper (latent 128, 10 MP, mesh edges)": dict(latent_size=128, message_passing_steps=10),
        "cpu (latent 64, 5 MP, no mesh edges)": dict(latent_size=64, message_passing_steps=5,
                                                     mesh_edges=False),
    }
    dtype = getattr(torch, args.dtype)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, network in {args.dtype}; "
          f"mujoco {mujoco.__version__}")
    rows: list[dict[str, Any]] = []
    for b in (push_bench_scene(), toss_bench_scene()):
        mj = time_mujoco(b, args.repeats * 5)
        print(f"\n== {b.name}: {b.scene.num_objects} objects, {b.scene.num_nodes} nodes, "
              f"{b.scene.faces.shape[0]} faces, d_c = {b.radius} m; MuJoCo {b.substeps} substeps: "
              f"{mj:.3f} ms per learned-step length")
        print(f"{'model':40s} {'B':>3s} {'total':>8s} {'collide':>8s} {'graph':>7s} {'network':>8s} "
              f"{'shape':>7s} {'ff-edges':>8s} {'x MuJoCo':>9s} {'coll+graph':>10s}")
        for label, kw in configs.items():
            sim = LearnedSimulator(SimulatorConfig(collision_radius=b.radius, **kw)).eval()
            sim.inference_dtype = dtype
            for batch in args.batch:
                r = time_learned_step(sim, b, args.repeats, batch)
                per = r["total"] / batch
                share = (r["collision"] + r["graph"]) / r["total"]
                rows.append({"scene": b.name, "model": label, "batch": batch, "mujoco_ms": mj,
                             "x_mujoco": per / mj, **r})
                print(f"{label:40s} {batch:3d} {r['total']:8.2f} {r['collision']:8.2f} "
                      f"{r['graph']:7.2f} {r['network']:8.2f} {r['shape_match']:7.2f} "
                      f"{r['face_edges']:8.0f} {per / mj:9.1f} {share:10.0%}")
    print("\nms are medians per step (for B > 1: for all B scenes at once); 'shape' is integration and "
          "shape matching; 'x MuJoCo' is the per-scene learned step over MuJoCo's time for the same "
          "simulated time.")
    _write_json(args.json, {"step": rows})

