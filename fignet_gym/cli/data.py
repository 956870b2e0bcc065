"""Data subcommands of ``fignet-gym``: ``generate``, ``show``, ``import-mit``, ``check-mit``,
``import-movi``, ``import-contactnets``, ``mit-standin``, ``split``.

:func:`register` adds them to the main parser's subparsers; each sets ``func`` to a callable that
takes the parsed arguments and returns an exit code. Known bad input (malformed files, unknown
shapes, a trajectory index beyond the file) raises the library's ``ValueError`` subclasses naming
the file, trajectory and field, which :func:`fignet_gym.cli.errors.run_command` prints as one
``error:`` line.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from fignet_gym.atomic import output_lock, write_text
from fignet_gym.cli.options import int_at_least, nonnegative_float, positive_float
from fignet_gym.data.format import TrajectoryFile
from fignet_gym.data.generate import KINDS, TossConfig, default_config, generate
from fignet_gym.data.importers import import_movi, load_mesh_map
from fignet_gym.data.mit import (
    MitProtocol,
    MitReport,
    MitSelection,
    check_mit,
    import_mit,
    offsets_from_report,
)
from fignet_gym.data.mit_files import MODEL_DT
from fignet_gym.data.mit_geometry import INSIDE_TOLERANCE
from fignet_gym.data.scene_generator import SceneConfig
from fignet_gym.data.split import write_split
from fignet_gym.data.standin import write_mit_standin
from fignet_gym.data.tracked import import_contactnets
from fignet_gym.data.viewer import Camera, render_trajectory_record
from fignet_gym.mjcf.assets import CONES, DEFAULT_CONE
from fignet_gym.simulator.scene import MeshOptions


def _refuse_overwrite(out: str | os.PathLike, force: bool) -> None:
    """``FileExistsError`` if ``out`` exists and ``force`` is not set (outputs are never silently
    replaced); a directory is never replaced."""
    path = Path(out)
    if path.is_dir():
        raise FileExistsError(f"{path}: is a directory; --out must be a file")
    if path.exists() and not force:
        raise FileExistsError(f"{path}: already exists; pass --force to replace it")


@contextlib.contextmanager
def _writing(out: str | os.PathLike, force: bool) -> Iterator[None]:
    """Refuse an existing ``out`` unless ``force`` (before anything is written), then hold the
    lock of ``out`` for the block (one writer), checking again under it."""
    _refuse_overwrite(out, force)
    with output_lock(out):
        _refuse_overwrite(out, force)  # another process may have written it in between
        yield


def _refuse_empty(n: int, out: str | os.PathLike) -> None:
    if n == 0:
        Path(out).unlink(missing_ok=True)
        raise ValueError(f"{out}: no trajectory was imported (every input was skipped); nothing written")


def _generate(args: argparse.Namespace) -> int:
    if args.kind == "scene":
        return _generate_scene(args)
    if args.mjcf is not None:
        raise ValueError(f"--mjcf is for `generate scene`, not {args.kind}")
    cfg = default_config(args.kind)
    if isinstance(cfg, TossConfig):
        mo = MeshOptions(sphere_subdivisions=args.sphere_subdivisions,
                         cylinder_sections=args.cylinder_sections,
                         box_subdivisions=args.box_subdivisions)
        cfg = replace(cfg, mesh_options=mo)
    if args.duration is not None:
        cfg = replace(cfg, duration=args.duration)
    if args.substeps is not None:
        cfg = replace(cfg, substeps=args.substeps)
    cfg = replace(cfg, cone=args.cone or DEFAULT_CONE)
    with _writing(args.out, args.force):
        stats = generate(args.kind, args.num, args.seed, args.out, workers=args.workers,
                         config=cfg, progress=not args.no_progress)
    print(f"wrote {stats['num']} {args.kind} trajectories to {args.out} in "
          f"{stats['seconds']:.1f} s ({stats['traj_per_s']:.2f} traj/s, {args.workers} workers)")
    return 0


def _generate_scene(args: argparse.Namespace) -> int:
    if args.mjcf is None:
        raise ValueError("generate scene: pass the scene's MJCF (--mjcf FILE)")
    if args.cone is not None:
        raise ValueError("generate scene keeps the scene's own friction cone: set <option "
                         "cone=...> in the MJCF instead of --cone")
    extra = {k: v for k, v in (("duration", args.duration), ("dt", args.dt), ("target", args.target),
                               ("speed", args.speed and tuple(args.speed)),
                               ("offset", args.offset and tuple(args.offset)),
                               ("position_jitter", args.position_jitter),
                               ("yaw_range", args.yaw_range), ("segments", args.segments))
             if v is not None}
    cfg = SceneConfig.from_file(args.mjcf, **extra)
    with _writing(args.out, args.force):
        stats = generate("scene", args.num, args.seed, args.out, workers=args.workers, config=cfg,
                         progress=not args.no_progress)
    print(f"wrote {stats['num']} trajectories of {args.mjcf} to {args.out} in "
          f"{stats['seconds']:.1f} s ({stats['traj_per_s']:.2f} traj/s, {args.workers} workers)")
    return 0


def _show(args: argparse.Namespace) -> int:
    with TrajectoryFile(args.file) as f:
        traj = f[args.traj]
    out = args.out or Path(args.file).with_name(f"{Path(args.file).stem}_traj{args.traj}.mp4")
    cam = Camera(distance=args.distance, azimuth=args.azimuth, elevation=args.elevation)
    path = render_trajectory_record(traj, out, fps=args.fps, camera=cam, width=args.width,
                                    height=args.height)
    print(f"rendered trajectory {args.traj} ({traj.name}, {traj.num_steps} poses) to {path}")
    return 0


def _mit_selection(args: argparse.Namespace) -> MitSelection:
    return MitSelection(
        surfaces=None if "any" in args.surface else tuple(args.surface),
        shapes=tuple(args.shape) if args.shape else None,
        velocities=tuple(args.velocity) if args.velocity else None,
        accelerations=None if args.any_acceleration else tuple(args.acceleration))


def _mit_protocol(args: argparse.Namespace) -> MitProtocol:
    if args.outlines is not None and not Path(args.outlines).is_dir():
        raise FileNotFoundError(f"--outlines {args.outlines}: no such folder (it holds "
                                "<shape>_ext.npy outlines)")
    if args.offsets is not None and not Path(args.offsets).is_file():
        raise FileNotFoundError(f"--offsets {args.offsets}: no such file (a --report / --json "
                                "of import-mit or check-mit)")
    return MitProtocol(dt=getattr(args, "dt", MitProtocol.dt),
                       window=getattr(args, "duration", MitProtocol.window),
                       start=getattr(args, "start", MitProtocol.start),
                       keep_still=getattr(args, "keep_still", False),
                       friction=getattr(args, "friction", MitProtocol.friction),
                       outlines=args.outlines,
                       offsets=offsets_from_report(args.offsets) if args.offsets else None)


def _write_report(report: MitReport, path: str | None) -> None:
    print(report.table())
    for c in report.shapes.values():
        for name in c.still:
            print(f"still (never moves the object): {name}")
    if path:
        write_text(path, json.dumps(report.as_json(), indent=1))
        print(f"wrote the check to {path}")


def _import_mit(args: argparse.Namespace) -> int:
    protocol = _mit_protocol(args)
    with _writing(args.out, args.force):
        report = import_mit(args.paths, args.out, _mit_selection(args), protocol,
                            skip_bad=args.skip_bad)
        _refuse_empty(report.windows, args.out)
    _write_report(report, args.report)
    kept = "kept" if protocol.keep_still else "not imported"
    still = sum(len(c.still) for c in report.shapes.values())
    surfaces = ", ".join(f"{k} {v}" for k, v in sorted(report.surfaces.items()))
    moved = report.pushes - (0 if protocol.keep_still else still)
    print(f"imported {report.windows} windows of {moved} MIT pushes ({surfaces}) into {args.out} "
          f"({still} still pushes {kept}; dt {protocol.dt} s, window "
          f"{protocol.window or 'whole push'} s from {protocol.start})")
    return 0


def _check_mit(args: argparse.Namespace) -> int:
    report = check_mit(args.paths, _mit_selection(args), _mit_protocol(args),
                       skip_bad=args.skip_bad)
    if not report.shapes:
        raise ValueError(f"{', '.join(args.paths)}: no MIT push file found")
    _write_report(report, args.json)
    checked = [c for c in report.shapes.values() if len(c.distances)]
    if checked:
        worst = max(checked, key=lambda c: c.inside_fraction)
        print(f"worst: {worst.shape}, tip more than {INSIDE_TOLERANCE * 1e3:g} mm inside in "
              f"{100 * worst.inside_fraction:.1f}% of its contact frames")
    return 0


def _import_movi(args: argparse.Namespace) -> int:
    with _writing(args.out, args.force):
        n = import_movi(args.paths, load_mesh_map(args.meshes), args.out, skip_bad=args.skip_bad,
                        frame_rate=args.frame_rate, floor_half_size=args.floor_half_size)
        _refuse_empty(n, args.out)
    print(f"imported {n} MOVi scenes into {args.out}")
    return 0


def _import_contactnets(args: argparse.Namespace) -> int:
    with _writing(args.out, args.force):
        n = import_contactnets(args.directory, args.out, length_unit=args.length_unit,
                               floor_half_size=args.floor_half_size, skip_bad=args.skip_bad)
    print(f"imported {n} ContactNets tosses into {args.out}")
    return 0


def _split(args: argparse.Namespace) -> int:
    with output_lock(args.out):
        paths = write_split(args.data, args.out, args.fractions, args.seed, force=args.force)
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    return 0


def _mit_standin(args: argparse.Namespace) -> int:
    with output_lock(args.out):
        files = write_mit_standin(args.out, args.num, args.seed, penetration=args.penetration,
                                  position_noise=args.noise, force=args.force)
    print(f"wrote {len(files)} stand-in MIT pushes (raw JSON) into {args.out}")
    return 0


def _mit_selection_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--surface", nargs="+", default=["any"],
                   help="surfaces (default: any; the paper trained on abs)")
    p.add_argument("--shape", nargs="+", default=None, help="shapes (default: all)")
    p.add_argument("--velocity", nargs="+", type=float, default=None, help="mm/s (default: all)")
    p.add_argument("--acceleration", nargs="+", type=float, default=[0.0],
                   help="the file name's 'a' (default: 0, constant speed)")
    p.add_argument("--any-acceleration", action="store_true")
    p.add_argument("--outlines", default=None,
                   help="folder of <shape>_ext.npy outlines (default: the shipped ones)")
    p.add_argument("--offsets", default=None,
                   help="use the frame offsets of this report (--report / --json of an earlier "
                   "import-mit or check-mit) instead of measuring them; other shapes are measured")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the data subcommands to ``subparsers`` (of the ``fignet-gym`` parser)."""
    g = subparsers.add_parser("generate", help="generate MuJoCo training trajectories",
                              description="Generate trajectories with MuJoCo into an HDF5 file.")
    g.add_argument("kind", choices=KINDS)
    g.add_argument("--num", type=int_at_least(1), required=True, help="number of trajectories")
    g.add_argument("--seed", type=int_at_least(0), default=0, help="base seed (non-negative)")
    g.add_argument("--out", required=True, help="output .h5 file (written atomically)")
    g.add_argument("--force", action="store_true", help="replace OUT if it exists (default: refuse)")
    g.add_argument("--workers", type=int_at_least(1), default=min(2, os.cpu_count() or 1),
                   help="processes (results do not depend on it)")
    g.add_argument("--duration", type=positive_float, default=None,
                   help="seconds per trajectory (default: 1.0 push, 2.0 toss)")
    g.add_argument("--substeps", type=int_at_least(1), default=None,
                   help="MuJoCo steps of 2 ms per stored pose (default 10: dt = 0.02 s)")
    g.add_argument("--cone", choices=CONES, default=None,
                   help="MuJoCo friction cone (default elliptic: isotropic friction; pyramidal: "
                        "the data of Push-v1, Toss-v0 and the first shipped models); a scene "
                        "keeps its own")
    g.add_argument("--sphere-subdivisions", type=int_at_least(0), default=1,
                   help="toss: icosphere level of spheres (1: 42 nodes)")
    g.add_argument("--cylinder-sections", type=int_at_least(3), default=12,
                   help="toss: cylinder facets")
    g.add_argument("--box-subdivisions", type=int_at_least(0), default=0,
                   help="toss: cube subdivisions (0: 8 corner nodes)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    sc = g.add_argument_group("scene (a user's MJCF: free bodies pushed by mocap bodies; "
                              "docs/data.md)")
    sc.add_argument("--mjcf", default=None, help="the scene's MJCF file")
    sc.add_argument("--dt", type=positive_float, default=None,
                    help="learned step, a multiple of the MJCF's timestep (default 0.02 s)")
    sc.add_argument("--target", default=None,
                    help="free body every stroke aims at (default: one drawn per stroke)")
    sc.add_argument("--speed", type=positive_float, nargs=2, metavar=("MIN", "MAX"), default=None,
                    help="stroke speed range, m/s (default 0.05 0.15)")
    sc.add_argument("--offset", type=float, nargs=2, metavar=("MIN", "MAX"), default=None,
                    help="lateral offset of a stroke from the target's centre, m (default -0.02 0.02)")
    sc.add_argument("--position-jitter", type=nonnegative_float, default=None,
                    help="free bodies' start: horizontal shift up to this, m (default 0)")
    sc.add_argument("--yaw-range", type=nonnegative_float, default=None,
                    help="free bodies' start: heading turned by up to this, rad (default pi)")
    sc.add_argument("--segments", type=int_at_least(1), default=None,
                    help="straight pieces per stroke (default 1)")
    g.set_defaults(func=_generate)

    s = subparsers.add_parser("show", help="render a stored trajectory to MP4 or GIF")
    s.add_argument("file")
    s.add_argument("--traj", type=int, default=0, help="trajectory index in the file")
    s.add_argument("--out", default=None, help=".mp4 or .gif (default: <file>_traj<K>.mp4)")
    s.add_argument("--fps", type=positive_float, default=None, help="default: 1 / dt (real time)")
    s.add_argument("--width", type=int_at_least(1), default=480)
    s.add_argument("--height", type=int_at_least(1), default=480)
    s.add_argument("--azimuth", type=float, default=90.0)
    s.add_argument("--elevation", type=float, default=-45.0)
    s.add_argument("--distance", type=float, default=None, help="default: fitted to the motion")
    s.set_defaults(func=_show)

    m = subparsers.add_parser(
        "import-mit", help="import MIT Pushing raw or pdproc files (windows from first contact)",
        description="Import MIT Pushing pushes: the real outlines with each shape's frame offset "
        "measured on the pushes given, 0.5 s windows from first contact every 20 ms (the "
        "FIGNet paper's protocol at the shipped models' step, docs/sim2real.md); prints the "
        "per-shape contact check.")
    m.add_argument("paths", nargs="+", help="files or directories (searched recursively)")
    m.add_argument("--out", required=True)
    _mit_selection_args(m)
    m.add_argument("--dt", type=positive_float, default=MODEL_DT,
                   help=f"pose step (s; default {MODEL_DT:g}: the shipped push models' step; 0.012 "
                   "is the FIGNet paper's, every 3rd sample of the 250 Hz streams)")
    m.add_argument("--duration", type=nonnegative_float, default=0.5,
                   help="window length (s; a long push gives several); 0: one window per push")
    m.add_argument("--start", choices=("contact", "file"), default="contact",
                   help="windows start at first contact (default) or at the file's first sample")
    m.add_argument("--keep-still", action="store_true",
                   help="also import pushes that never move the object (always reported)")
    m.add_argument("--friction", type=nonnegative_float, default=0.25,
                   help="friction written into the MJCF (the real one is unknown)")
    m.add_argument("--report", default=None, help="also write the check as JSON here")
    m.add_argument("--force", action="store_true", help="replace OUT if it exists (default: refuse)")
    m.add_argument("--skip-bad", action="store_true", help="warn and skip malformed files")
    m.set_defaults(func=_import_mit)

    ck = subparsers.add_parser(
        "check-mit", help="check MIT pushes against the real outlines (tip distance in contact)",
        description="Per shape: the frame offset measured on these pushes, the tip centre's "
        "distance to the outline in contact frames (the object moving), and the fraction of "
        "those frames with the 4.75 mm tip more than 1 mm inside the object. Writes nothing "
        "unless --json.")
    ck.add_argument("paths", nargs="+", help="files or directories (searched recursively)")
    _mit_selection_args(ck)
    ck.add_argument("--json", default=None, help="write the check as JSON here")
    ck.add_argument("--skip-bad", action="store_true", help="warn and skip malformed files")
    ck.set_defaults(func=_check_mit)

    v = subparsers.add_parser("import-movi", help="import Kubric MOVi metadata.json records")
    v.add_argument("paths", nargs="+", help="metadata.json files or directories")
    v.add_argument("--meshes", required=True,
                   help="JSON object {shape_label or asset_id: mesh file}")
    v.add_argument("--out", required=True)
    v.add_argument("--frame-rate", type=positive_float, default=None,
                   help="default: the record's metadata.frame_rate, else 12")
    v.add_argument("--floor-half-size", type=positive_float, default=20.0)
    v.add_argument("--skip-bad", action="store_true", help="warn and skip malformed files")
    v.add_argument("--force", action="store_true", help="replace OUT if it exists (default: refuse)")
    v.set_defaults(func=_import_movi)

    c = subparsers.add_parser("import-contactnets",
                              help="import the DAIRLab ContactNets real cube tosses")
    c.add_argument("directory", help="folder with params_processed/experiment.json and "
                   "tosses_processed/*.pt")
    c.add_argument("--out", required=True)
    c.add_argument("--length-unit", type=positive_float, default=None,
                   help="metres per data unit (default: 9.81 / the file's g, the half-width)")
    c.add_argument("--floor-half-size", type=positive_float, default=2.0, help="floor plane half-size (m)")
    c.add_argument("--skip-bad", action="store_true", help="warn and skip malformed files")
    c.add_argument("--force", action="store_true", help="replace OUT if it exists (default: refuse)")
    c.set_defaults(func=_import_contactnets)

    ms = subparsers.add_parser("mit-standin", help="stand-in MIT Pushing raw files (MuJoCo pushes "
                               "with per-push friction, tracking noise and pusher penetration)")
    ms.add_argument("--out", required=True, help="folder for the raw .json pushes")
    ms.add_argument("--num", type=int_at_least(1), default=120)
    ms.add_argument("--seed", type=int_at_least(0), default=0)
    ms.add_argument("--noise", type=nonnegative_float, default=5e-4, help="object tracking noise (m)")
    ms.add_argument("--penetration", type=nonnegative_float, default=1e-3,
                    help="how much thinner the simulated tip is than the imported scene's (m)")
    ms.add_argument("--force", action="store_true",
                    help="replace the stand-in pushes already in OUT (default: refuse)")
    ms.set_defaults(func=_mit_standin)

    sp = subparsers.add_parser("split", help="seeded train/valid/test split of a trajectory file, by "
                                   "recording (windows sharing metadata \"file\" stay together)")
    sp.add_argument("data")
    sp.add_argument("--out", required=True, help="folder for train.h5, valid.h5, test.h5, split.json")
    sp.add_argument("--fractions", type=nonnegative_float, nargs=3, default=[0.6, 0.2, 0.2],
                    metavar=("TRAIN", "VALID", "TEST"))
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--force", action="store_true", help="replace a split already in OUT")
    sp.set_defaults(func=_split)
