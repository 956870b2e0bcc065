"""Reliability audit: hostile inputs through the public API and the CLI, classified.

Run as a script (``python scripts/audit_reliability.py [--quick]``) it prints a table of cases per
class and outcome. Outcomes: ``clear`` (a refusal naming the problem: a ``ValueError`` /
``CheckpointError`` / ``RuntimeError`` from the API, or one ``error:`` line and a non-zero exit
from the CLI), ``silent`` (accepted although it is wrong), ``traceback`` (another exception type,
or a CLI traceback), ``nan`` (NaN reached an observation), ``hang`` (killed by the time or memory
limit), ``ok`` (a valid input handled correctly). Used before and after the reliability fixes to
count what changed; the fast checks of the same classes are in ``tests/test_reliability.py``.
"""

from __future__ import annotations

import collections
import io
import json
import math
import os
import subprocess
import sys
import tempfile
import warnings
import zipfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
RESULTS: list[tuple[str, str, str]] = []


def record(cls: str, case: str, outcome: str) -> None:
    RESULTS.append((cls, case, outcome))


def classify_exc(exc: BaseException | None, clear_types: tuple[type, ...]) -> str:
    if exc is None:
        return "silent"
    return "clear" if isinstance(exc, clear_types) else "traceback"


def run_cli(
    argv: list[str], timeout: float = 120, mem_mb: int = 3000, cwd: str | None = None
) -> tuple[int | None, str]:
    """Return code (None: killed by the limits) and stderr of ``fignet-gym argv``."""
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (mem_mb << 20, mem_mb << 20))

    try:
        p = subprocess.run(
            [PY, "-m", "fignet_gym", *argv],
            capture_output=True,
            text=True,
            timeout=timeout,
            preexec_fn=limit,
            cwd=cwd,
            env={**os.environ, "OMP_NUM_THREADS": "1"},
        )
    except subprocess.TimeoutExpired:
        return None, "timeout"
    return p.returncode, p.stderr


def cli_outcome(rc: int | None, err: str, should_fail: bool = True) -> str:
    if rc is None or "MemoryError" in err or rc < 0:
        return "hang"
    if "Traceback" in err:
        return "traceback"
    if rc == 0:
        return "silent" if should_fail else "ok"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    return (
        "clear"
        if lines
        and lines[-1].startswith(("error:", "fignet-gym"))
        or any(ln.startswith("fignet-gym: error:") or ln.startswith("error:") for ln in lines)
        else "traceback"
    )


# ----------------------------------------------------------------------------- class 1
def audit_vector_atomic() -> None:
    import gymnasium as gym

    import fignet_gym  # noqa: F401
    from fignet_gym.envs.sb3 import SB3VecEnvAdapter

    for env_id in ("fignet_gym/Push-v2", "fignet_gym/Toss-v0"):
        for row in range(3):
            for adapter in (False, True):
                v = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
                base = v.unwrapped
                if adapter:
                    sb = SB3VecEnvAdapter(v)
                    sb.seed(0)
                    sb.reset()
                else:
                    v.reset(seed=0)
                before = [
                    (e.data.qpos.copy(), e.data.mocap_pos.copy(), getattr(e, "released", 0))
                    for e in base.envs
                ]
                acts = np.full((3, 2), 0.5)  # non-zero: a tip moved without physics shows
                acts[row, 1] = np.nan
                exc = None
                try:
                    if adapter:
                        sb.step(acts)
                    else:
                        v.step(acts)
                except Exception as e:  # noqa: BLE001
                    exc = e
                after = [
                    (e.data.qpos.copy(), e.data.mocap_pos.copy(), getattr(e, "released", 0))
                    for e in base.envs
                ]
                same = all(
                    np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2]
                    for a, b in zip(before, after, strict=True)
                )
                if exc is None:
                    out = "silent"
                elif not same:
                    out = "silent"  # refused, but state changed
                else:
                    out = "clear" if isinstance(exc, ValueError) else "traceback"
                record("1 atomic vector step", f"{env_id} nan row {row} sb3={adapter}", out)
                v.close()


# ----------------------------------------------------------------------------- classes 2, 3, 5
def _push_blob() -> dict:
    from fignet_gym.pretrained import pretrained_path

    return torch.load(pretrained_path("push"), weights_only=True)


def crafted_checkpoints(tmp: Path) -> dict[str, Path]:
    """Name -> crafted checkpoint file."""
    from fignet_gym.pretrained import pretrained_path

    src = pretrained_path("push")
    out: dict[str, Path] = {}

    def save(name: str, blob: object) -> None:
        p = tmp / f"{name}.pt"
        torch.save(blob, p)
        out[name] = p

    b = _push_blob()
    save("mps_1e7", {**b, "config": {**b["config"], "message_passing_steps": 10**7}})
    save("latent_2e5", {**b, "config": {**b["config"], "latent_size": 200000}})
    save("latent_wrong", {**b, "config": {**b["config"], "latent_size": 32}})
    save("hidden_neg", {**b, "config": {**b["config"], "hidden_size": -5}})
    save("history_1e6", {**b, "config": {**b["config"], "history": 10**6}})
    save("latent_str", {**b, "config": {**b["config"], "latent_size": "big"}})
    save("dt_nan", {**b, "config": {**b["config"], "dt": float("nan")}})
    save("radius_inf", {**b, "config": {**b["config"], "collision_radius": float("inf")}})
    nan_sd = {
        k: torch.full_like(v, float("nan")) if v.is_floating_point() else v
        for k, v in b["state_dict"].items()
    }
    save("all_nan", {**b, "state_dict": nan_sd})
    one = dict(b["state_dict"])
    k0 = next(k for k, v in one.items() if v.is_floating_point() and v.numel() > 10)
    one[k0] = one[k0].clone()
    one[k0][0] = float("inf")
    save("one_inf", {**b, "state_dict": one})
    save("no_config", {k: v for k, v in b.items() if k != "config"})
    save("config_list", {**b, "config": [1, 2]})
    save("no_state", {k: v for k, v in b.items() if k != "state_dict"})
    save("state_list", {**b, "state_dict": [1, 2]})
    save("state_str_values", {**b, "state_dict": {k: "x" for k in b["state_dict"]}})
    save("meta_list", {**b, "meta": [1]})
    save("mesh_options_bad", {**b, "config": {**b["config"], "mesh_options": {"nope": 1}}})
    save("gravity_str", {**b, "config": {**b["config"], "gravity": "down"}})
    save("not_dict", [1, 2, 3])
    save("extra_key_state", {**b, "state_dict": {**b["state_dict"], "bogus": torch.zeros(3)}})
    # Flipped bytes inside the weights' storage (the zip's data records).
    raw = src.read_bytes()
    with zipfile.ZipFile(src) as z:
        infos = [i for i in z.infolist() if "/data/" in i.filename and i.file_size > 4096]
    rng = np.random.default_rng(0)
    for n_flip in (10, 200, 2000):
        data = bytearray(raw)
        info = infos[0]
        head = raw[info.header_offset : info.header_offset + 30]
        start = (
            info.header_offset
            + 30
            + int.from_bytes(head[26:28], "little")
            + int.from_bytes(head[28:30], "little")
        )
        for pos in rng.integers(start, start + info.file_size - 128, n_flip):
            data[pos] ^= 0xFF
        p = tmp / f"flip_{n_flip}.pt"
        p.write_bytes(bytes(data))
        out[f"flip_{n_flip}"] = p
    (tmp / "truncated.pt").write_bytes(raw[: len(raw) // 2])
    out["truncated"] = tmp / "truncated.pt"
    (tmp / "empty.pt").write_bytes(b"")
    out["empty"] = tmp / "empty.pt"
    (tmp / "text.pt").write_text("hello")
    out["text"] = tmp / "text.pt"

    class Payload:
        def __reduce__(self):  # noqa: ANN204
            return (os.getcwd, ())

    buf = io.BytesIO()
    torch.save({"format": b["format"], "x": Payload()}, buf)
    (tmp / "pickle.pt").write_bytes(buf.getvalue())
    out["pickle"] = tmp / "pickle.pt"
    return out


_LOAD_SNIPPET = """
import sys, warnings
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.checkpoint import CheckpointError
try:
    sim = load_pretrained(sys.argv[1])
except CheckpointError as e:
    msg = str(e)
    print("HINT" if "weights_only=False" in msg else "CLEAR", msg[:300])
    sys.exit(3)
print("LOADED")
"""


def sealed_flips(tmp: Path) -> dict[str, Path]:
    """Flipped bytes in a copy of push.pt re-saved with its content checksum (``add_checksum``)."""
    from fignet_gym.pretrained import pretrained_path
    from fignet_gym.simulator.checkpoint import add_checksum

    src = add_checksum(pretrained_path("push"), tmp / "push_sealed.pt")
    raw = src.read_bytes()
    with zipfile.ZipFile(src) as z:
        info = max((i for i in z.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    head = raw[info.header_offset : info.header_offset + 30]
    start = (
        info.header_offset
        + 30
        + int.from_bytes(head[26:28], "little")
        + int.from_bytes(head[28:30], "little")
    )
    out = {}
    rng = np.random.default_rng(1)
    for n_flip in (10, 200, 2000):
        data = bytearray(raw)
        for pos in rng.integers(start, start + info.file_size, n_flip):
            data[pos] ^= 0xFF
        p = tmp / f"sealed_flip_{n_flip}.pt"
        p.write_bytes(bytes(data))
        out[f"sealed_flip_{n_flip}"] = p
    return out


def audit_checkpoints(tmp: Path, sealed_only: bool = False) -> None:
    import resource

    files = sealed_flips(tmp) if sealed_only else crafted_checkpoints(tmp)
    for name, path in files.items():

        def limit() -> None:
            resource.setrlimit(resource.RLIMIT_AS, (3000 << 20, 3000 << 20))

        try:
            p = subprocess.run(
                [PY, "-c", _LOAD_SNIPPET, str(path)],
                capture_output=True,
                text=True,
                timeout=60,
                preexec_fn=limit,
            )
        except subprocess.TimeoutExpired:
            out = "hang"
        else:
            if p.returncode < 0 or "MemoryError" in p.stderr or "Cannot allocate" in p.stderr:
                out = "hang"
            elif "LOADED" in p.stdout:
                out = "silent"
            elif p.stdout.startswith("HINT"):
                out = "traceback"  # passes on torch's weights_only=False hint
            elif p.stdout.startswith("CLEAR"):
                out = "clear"
            else:
                out = "traceback"
        cls = (
            "2 bounded config"
            if name
            in ("mps_1e7", "latent_2e5", "history_1e6", "hidden_neg", "latent_wrong", "dt_nan", "radius_inf")
            else "3 corrupt weights"
            if name.startswith(("flip", "all_nan", "one_inf"))
            else "3 corrupt weights (sealed copy)"
            if name.startswith("sealed")
            else "5 structural checkpoint"
        )
        record(cls, f"load {name}", out)


# ----------------------------------------------------------------------------- class 6
ENV_ARGS = {
    "fignet_gym/Push-v2": [
        dict(max_speed=float("nan")),
        dict(max_speed=-1.0),
        dict(goal_distance=float("nan")),
        dict(goal_distance=-0.1),
        dict(friction=float("nan")),
        dict(friction=-1.0),
        dict(frame_skip=0),
        dict(frame_skip=-1),
        dict(frame_skip=2.5),
        dict(workspace=0.0),
        dict(success_position=float("nan")),
        dict(position_weight=float("inf")),
        dict(width=0),
        dict(height=-5),
        dict(tip_friction=float("nan")),
        dict(goal_yaw=float("nan")),
        dict(shape="nope"),
    ],
    "fignet_gym/Toss-v0": [
        dict(target_radius=float("nan")),
        dict(target_radius=-1.0),
        dict(settle_frame_skip=0),
        dict(settle_steps=0),
        dict(floor_half_size=-1.0),
        dict(floor_half_size=float("nan")),
        dict(release_position=(0, 0, float("nan"))),
        dict(release_velocity_low=(5.0, 2.0), release_velocity_high=(2.0, -2.0)),
        dict(target_low=(1.0, 1.0), target_high=(0.0, 0.0)),
        dict(distance_weight=float("nan")),
        dict(objects=[]),
    ],
}


def audit_env_args() -> None:
    import gymnasium as gym

    import fignet_gym  # noqa: F401

    for env_id, cases in ENV_ARGS.items():
        for kw in cases:
            out = None
            try:
                env = gym.make(env_id, **kw)
                obs, _ = env.reset(seed=0)
                bad = not np.isfinite(obs).all()
                for _ in range(3):
                    o, r, term, trunc, _ = env.step(env.action_space.sample())
                    bad = bad or not np.isfinite(o).all() or not math.isfinite(r)
                    if term or trunc:
                        break
                out = "nan" if bad else "silent"
            except Exception as e:  # noqa: BLE001
                out = classify_exc(e, (ValueError,))
            record("6 env arguments", f"{env_id} {kw}", out)
    # Step before reset (direct construction: no OrderEnforcing wrapper).
    from fignet_gym.envs.push import PushEnv
    from fignet_gym.envs.toss import TossEnv

    for cls_ in (PushEnv, TossEnv):
        env = cls_()
        try:
            env.step(np.zeros(2))
            out = "silent"
        except Exception as e:  # noqa: BLE001
            out = classify_exc(e, (RuntimeError, gym.error.ResetNeeded))
        record("6 step before reset", cls_.__name__, out)
    v = gym.make_vec("fignet_gym/Push-v2", num_envs=2, vectorization_mode="vector_entry_point")
    try:
        v.step(np.zeros((2, 2)))
        out = "silent"
    except Exception as e:  # noqa: BLE001
        out = classify_exc(e, (RuntimeError, gym.error.ResetNeeded))
    record("6 step before reset", "vector Push", out)
    for seed in (1.5, -1, "a", [1.5, 2]):
        try:
            v.reset(seed=seed)
            out = "silent"
        except Exception as e:  # noqa: BLE001
            out = classify_exc(e, (ValueError,))
        record("8 vec reset seed", repr(seed), out)


FREE_NO_GEOM = """
<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
<body name="cube" pos="0 0 .1"><freejoint/><geom type="box" size=".05 .05 .05"/></body>
<body name="ghost" pos=".5 0 .3"><freejoint/>
  <geom type="sphere" size=".05" contype="0" conaffinity="0"/></body>
<body name="bare" pos="-.5 0 .3"><freejoint/><inertial pos="0 0 0" mass="1" diaginertia=".01 .01 .01"/></body>
</worldbody></mujoco>
"""


def audit_scene() -> None:
    import mujoco

    from fignet_gym.simulator.scene import Scene, UnsupportedSceneError

    m = mujoco.MjModel.from_xml_string(FREE_NO_GEOM)
    try:
        Scene.from_mjmodel(m)
        out = "silent"
    except Exception as e:  # noqa: BLE001
        out = classify_exc(e, (UnsupportedSceneError,))
    record("6 free body without collidable geom", "ghost + bare bodies", out)


def audit_datasets(tmp: Path) -> None:
    from fignet_gym.data.format import TrajectoryFormatError, validate_trajectory
    from fignet_gym.data.generate import iter_trajectories

    base = next(iter(iter_trajectories("push", 1, seed=3)))
    import copy as _copy

    def variant(fn) -> object:  # noqa: ANN001
        t = _copy.deepcopy(base)
        fn(t)
        return t

    dyn = int(np.flatnonzero(np.asarray(base.kinds) == 1)[0])

    def teleport(t) -> None:  # noqa: ANN001
        t.poses[10:, dyn, 0] += 5.0

    def huge(t) -> None:  # noqa: ANN001
        t.poses[5, dyn, :3] = 1e30

    def far(t) -> None:  # noqa: ANN001
        t.poses[:, dyn, 2] += 1e7

    for name, fn in (("teleport 5 m", teleport), ("position 1e30", huge), ("everything at 1e7 m", far)):
        try:
            validate_trajectory(variant(fn))
            out = "silent"
        except Exception as e:  # noqa: BLE001
            out = classify_exc(e, (TrajectoryFormatError,))
        record("6 dataset bounds", name, out)
    # A tiny HDF5 file declaring a 16 GB poses dataset (chunked, never written).
    import h5py

    from fignet_gym.data.format import write_trajectories

    good = tmp / "good.h5"
    write_trajectories(good, [base])
    big = tmp / "big.h5"
    import shutil

    shutil.copy(good, big)
    with h5py.File(big, "a") as f:
        g = f["trajectories"][next(iter(f["trajectories"]))]
        del g["poses"]
        g.create_dataset(
            "poses", shape=(200_000_000, 3, 7), dtype="f4", chunks=(1000, 3, 7), compression="gzip"
        )
    rc, err = run_cli(["show", str(big), "--out", str(tmp / "big.mp4")], timeout=60, mem_mb=2000)
    record("6 dataset bounds", "show: 46 KB file declaring 16 GB poses", cli_outcome(rc, err))
    rc, err = run_cli(
        [
            "evaluate",
            "--checkpoint",
            "push",
            "--data",
            str(big),
            "--out",
            str(tmp / "ev_big"),
            "--videos",
            "0",
        ],
        timeout=60,
        mem_mb=2000,
    )
    record("6 dataset bounds", "evaluate: 16 GB poses declared", cli_outcome(rc, err))
    # Bad datasets through evaluate.
    bads = {}
    for name, fn in (("teleport", teleport), ("1e30", huge)):
        p = tmp / f"bad_{name}.h5"
        t = variant(fn)
        try:
            write_trajectories(p, [t, t])
        except Exception:  # noqa: BLE001
            # The writer validates: write raw with h5py instead.
            write_trajectories(p, [base, base])
            with h5py.File(p, "a") as f:
                for k in f["trajectories"]:
                    f["trajectories"][k]["poses"][...] = t.poses
        bads[name] = p
    for name, p in bads.items():
        rc, err = run_cli(
            [
                "evaluate",
                "--checkpoint",
                "push",
                "--data",
                str(p),
                "--out",
                str(tmp / f"ev_{name}"),
                "--videos",
                "0",
            ],
            timeout=120,
        )
        record("6 dataset bounds", f"evaluate {name} data", cli_outcome(rc, err))


# ----------------------------------------------------------------------------- CLI (5, 7, 8)
def audit_cli(tmp: Path, quick: bool) -> None:
    from fignet_gym.data.format import write_trajectories
    from fignet_gym.data.generate import iter_trajectories

    push = tmp / "push.h5"
    write_trajectories(push, list(iter_trajectories("push", 3, seed=1)))
    toss = tmp / "toss.h5"
    write_trajectories(toss, list(iter_trajectories("toss-simple", 2, seed=1)))
    tiny = json.dumps(
        {
            "simulator.latent_size": 8,
            "simulator.message_passing_steps": 1,
            "training.batch_size": 2,
            "training.steps": 4,
            "training.valid_every": 2,
            "training.valid_trajectories": 1,
            "training.threads": 1,
            "training.checkpoint_every": 2,
        }
    )
    run = tmp / "run"
    rc, err = run_cli(
        ["train", "--data", str(push), "--config", "push-cpu", "--set", tiny, "--out", str(run)], timeout=300
    )
    record("setup", "tiny train", cli_outcome(rc, err, should_fail=False))
    trunc = tmp / "trunc_run"
    trunc.mkdir()
    raw = (run / "last.pt").read_bytes() if (run / "last.pt").is_file() else b"x" * 100
    (trunc / "last.pt").write_bytes(raw[: len(raw) // 2])
    nometa = tmp / "no_movi"
    nometa.mkdir()
    (tmp / "meshes.json").write_text("{}")
    existing = tmp / "exists.h5"
    existing.write_bytes(push.read_bytes())
    cases: list[tuple[str, list[str]]] = [
        ("5 traceback", ["evaluate", "--checkpoint", str(tmp / "missing.pt"), "--data", str(push)]),
        ("5 traceback", ["evaluate", "--checkpoint", "nosuchmodel", "--data", str(push)]),
        ("5 traceback", ["evaluate", "--checkpoint", "push", "--data", str(tmp / "missing.h5")]),
        ("5 traceback", ["evaluate", "--checkpoint", str(trunc / "last.pt"), "--data", str(push)]),
        ("5 traceback", ["train", "--data", str(push), "--set", "{bad json", "--out", str(tmp / "r1")]),
        ("5 traceback", ["train", "--data", str(push), "--set", '{"lr": 0.1}', "--out", str(tmp / "r2")]),
        (
            "5 traceback",
            ["train", "--data", str(push), "--set", '{"training.nope": 1}', "--out", str(tmp / "r3")],
        ),
        ("5 traceback", ["train", "--data", str(push), "--set", "[1, 2]", "--out", str(tmp / "r3b")]),
        ("5 traceback", ["train", "--data", str(push), "--config", "nope", "--out", str(tmp / "r4")]),
        ("5 traceback", ["train", "--data", str(tmp / "missing.h5"), "--out", str(tmp / "r5")]),
        ("5 traceback", ["train", "--data", str(push), "--out", str(trunc), "--resume"]),
        ("5 traceback", ["floor", "--data", str(tmp / "missing.h5")]),
        ("5 traceback", ["floor", "--data", str(tmp / "meshes.json")]),
        (
            "5 traceback",
            [
                "ship",
                "--run",
                str(tmp / "norun"),
                "--name",
                "x",
                "--data",
                str(push),
                "--dest",
                str(tmp / "dest"),
            ],
        ),
        (
            "5 traceback",
            ["ship", "--run", str(trunc), "--name", "x", "--data", str(push), "--dest", str(tmp / "dest")],
        ),
        (
            "7 overwrite",
            ["train", "--data", str(push), "--config", "push-cpu", "--set", tiny, "--out", str(run)],
        ),
        (
            "7 overwrite",
            [
                "train",
                "--data",
                str(push),
                "--config",
                "toss-cpu",
                "--set",
                tiny,
                "--out",
                str(run),
                "--resume",
            ],
        ),
        ("7 overwrite", ["generate", "push", "--num", "1", "--out", str(existing), "--no-progress"]),
        ("8 nonsense value", ["generate", "push", "--num", "-3", "--out", str(tmp / "g1.h5")]),
        (
            "8 nonsense value",
            ["generate", "push", "--num", "1", "--workers", "-2", "--out", str(tmp / "g2.h5")],
        ),
        (
            "8 nonsense value",
            ["generate", "push", "--num", "1", "--duration", "0", "--out", str(tmp / "g3.h5")],
        ),
        ("8 nonsense value", ["generate", "push", "--num", "1", "--seed", "-1", "--out", str(tmp / "g4.h5")]),
        (
            "8 nonsense value",
            [
                "evaluate",
                "--checkpoint",
                "push",
                "--data",
                str(push),
                "--horizon",
                "-1",
                "--out",
                str(tmp / "e1"),
                "--videos",
                "0",
            ],
        ),
        (
            "8 nonsense value",
            [
                "evaluate",
                "--checkpoint",
                "push",
                "--data",
                str(push),
                "--num",
                "0",
                "--out",
                str(tmp / "e2"),
                "--videos",
                "0",
            ],
        ),
        (
            "8 nonsense value",
            [
                "evaluate",
                "--checkpoint",
                "push",
                "--data",
                str(push),
                "--videos",
                "-1",
                "--out",
                str(tmp / "e2b"),
            ],
        ),
        (
            "8 nonsense value",
            [
                "evaluate",
                "--checkpoint",
                "toss",
                "--data",
                str(push),
                "--out",
                str(tmp / "e3"),
                "--videos",
                "0",
            ],
        ),
        ("8 nonsense value", ["floor", "--data", str(push), "--num", "0"]),
        ("8 nonsense value", ["floor", "--data", str(push), "--noise", "-1"]),
        (
            "8 nonsense value",
            ["train", "--data", str(push), "--set", '{"training.lr": 0}', "--out", str(tmp / "t1")],
        ),
        (
            "8 nonsense value",
            ["train", "--data", str(push), "--set", '{"training.valid_every": 0}', "--out", str(tmp / "t2")],
        ),
        (
            "8 nonsense value",
            [
                "train",
                "--data",
                str(push),
                "--set",
                '{"training.checkpoint_every": 0}',
                "--out",
                str(tmp / "t3"),
            ],
        ),
        (
            "8 nonsense value",
            ["train", "--data", str(push), "--set", '{"training.batch_size": -1}', "--out", str(tmp / "t4")],
        ),
        ("8 nonsense value", ["train", "--data", str(push), "--max-train", "-2", "--out", str(tmp / "t5")]),
        (
            "8 nonsense value",
            ["import-movi", str(nometa), "--meshes", str(tmp / "meshes.json"), "--out", str(tmp / "movi.h5")],
        ),
    ]
    if quick:
        cases = cases[::3]
    for cls, argv in cases:
        rc, err = run_cli(argv, timeout=300)
        out = cli_outcome(rc, err)
        if cls.startswith("7") and argv[0] == "train" and "--resume" not in argv and out == "silent":
            out = "silent"
        record(cls, " ".join(a if len(a) < 40 else "..." + a[-25:] for a in argv[:6]), out)


# ----------------------------------------------------------------------------- class 4
_KILL_SNIPPET = """
import os, signal, sys, json
from pathlib import Path
from fignet_gym.train import trainer as training
kill_at = int(sys.argv[3])
orig = training.Trainer.validate
def validate(self, writer=None):
    rec = orig(self, writer)
    if self.state.step == kill_at:
        if writer is not None:
            writer.flush()
        os.kill(os.getpid(), signal.SIGKILL)
    return rec
training.Trainer.validate = validate
overrides = json.loads(sys.argv[4])
training.train_from_files([sys.argv[1]], None, "push-cpu", sys.argv[2], overrides=overrides,
                          resume="--resume" in sys.argv)
"""


def audit_sigkill(tmp: Path) -> None:
    from fignet_gym.data.format import write_trajectories
    from fignet_gym.data.generate import iter_trajectories

    push = tmp / "kpush.h5"
    write_trajectories(push, list(iter_trajectories("push", 3, seed=2)))
    tiny = {
        "simulator.latent_size": 8,
        "simulator.message_passing_steps": 1,
        "training.batch_size": 2,
        "training.steps": 8,
        "training.valid_every": 1,
        "training.valid_trajectories": 1,
        "training.threads": 1,
        "training.checkpoint_every": 4,
        "training.ema_decay": 0.0,
    }
    run = tmp / "krun"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    subprocess.run(
        [PY, "-c", _KILL_SNIPPET, str(push), str(run), "6", json.dumps(tiny)], capture_output=True, env=env
    )
    tmp_left = (run / "last.pt.tmp").exists()
    subprocess.run(
        [PY, "-c", _KILL_SNIPPET, str(push), str(run), "-1", json.dumps(tiny), "--resume"],
        capture_output=True,
        env=env,
    )
    steps = [json.loads(line)["step"] for line in (run / "curve.jsonl").read_text().splitlines()]
    dup = len(steps) - len(set(steps))
    record("4 resume after SIGKILL", f"curve steps {steps}", "silent" if dup else "ok")
    best = torch.load(run / "best.pt", weights_only=True)["meta"]["valid"]
    recs = [json.loads(line) for line in (run / "curve.jsonl").read_text().splitlines()]
    final = {r["step"]: r for r in recs}
    ok = final.get(best["step"], {}).get("score") == best["score"] and best["score"] <= min(
        r["score"] for r in final.values()
    )
    record("4 resume after SIGKILL", "best.pt matches the final curve", "ok" if ok else "silent")
    record(
        "4 resume after SIGKILL",
        "stale last.pt.tmp",
        "silent" if tmp_left and (run / "last.pt.tmp").exists() else "ok",
    )


def main() -> None:
    quick = "--quick" in sys.argv
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for name, fn in (
            ("vector", audit_vector_atomic),
            ("checkpoints", lambda: audit_checkpoints(tmp)),
            ("env", audit_env_args),
            ("scene", audit_scene),
            ("datasets", lambda: audit_datasets(tmp)),
            ("cli", lambda: audit_cli(tmp, quick)),
            ("sigkill", lambda: audit_sigkill(tmp)),
            ("sealed", lambda: audit_checkpoints(tmp, sealed_only=True)),
        ):
            if (
                len(sys.argv) > 1
                and sys.argv[-1] not in ("--quick",)
                and sys.argv[-1] != name
                and sys.argv[-1] != "all"
            ):
                continue
            try:
                fn()
            except Exception as e:  # noqa: BLE001
                record(name, f"audit crashed: {type(e).__name__}: {e}"[:120], "traceback")
            print(f"[{name} done]", file=sys.stderr, flush=True)
    for cls, case, out in RESULTS:
        print(f"{cls:38s} {out:10s} {case}")
    table = collections.Counter((c, o) for c, _, o in RESULTS)
    classes = sorted({c for c, _, _ in RESULTS})
    outs = ["clear", "ok", "silent", "traceback", "nan", "hang"]
    print("\n| class | cases | " + " | ".join(outs) + " |")
    print("|---|---|" + "---|" * len(outs))
    for c in classes:
        n = sum(v for (cc, _), v in table.items() if cc == c)
        print(f"| {c} | {n} | " + " | ".join(str(table.get((c, o), 0)) for o in outs) + " |")


if __name__ == "__main__":
    main()
