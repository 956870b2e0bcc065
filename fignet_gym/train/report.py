"""What ``fignet-gym evaluate`` shows: the printed table, error plots and side-by-side videos."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import torch
from PIL import Image, ImageDraw

from fignet_gym.data.format import Trajectory, build_scene
from fignet_gym.data.viewer import (
    Camera,
    fit_camera,
    render_frames,
    side_by_side,
    trajectory_model,
    write_video,
)
from fignet_gym.simulator.model import LearnedSimulator
from fignet_gym.train.data_checks import truth_label
from fignet_gym.train.rollouts import batched_rollout

#: Width and height (pixels) of each half of a comparison video.
VIDEO_SIZE = 360
#: Resolution (dots per inch) of the saved plots.
PLOT_DPI = 100
#: Label box of a video frame: text inset and glyph width (pixels) of PIL's default font.
LABEL_INSET, LABEL_GLYPH_WIDTH, LABEL_HEIGHT = 4, 7, 20


def _pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend.

    Imported here, not at the top: it adds about a second to every import of the training loop,
    which scores rollouts but draws no plot.
    """
    import matplotlib  # deferred: about a second, and the backend choice, on plotting only (above)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the backend is chosen

    return plt


def _against_label(ag: dict[str, Any]) -> str:
    """What ``--against`` was: a checkpoint, or MuJoCo with parameters that are fitted, or that
    change nothing in the data's own MJCF (nominal)."""
    if "checkpoint" in ag:
        return ag["checkpoint"]
    if "limit_surface" in ag:
        prm = ag["params"]
        return (f"{ag['limit_surface']} (quasi-static limit surface, tip friction "
                f"{prm['tip_friction']:g}, pressure radius x {prm['pressure_scale']:g})")
    physics = {k for k in ag.get("params", {}) if k not in ("source", "substeps")}
    kind = "fitted MuJoCo" if physics else "nominal MuJoCo (the data's own MJCF)"
    return f"{ag['mujoco']} ({kind} replaying the data)"


def print_table(res: dict[str, Any], label: str = "FIGNet") -> None:
    """Print the headline metrics against the reference models."""
    h = res["horizon_step"]
    print(f"{res['trajectories']} trajectories ({res['horizon_trajectories']} reach frame {h}); "
          f"errors at frame {h} from frame 0 ({res['seconds']:.2f} s) and at each one's last frame")
    # Millimetres: pushes err by tenths of a millimetre, which 4 decimals of metres hide.
    print(f"{'model':16s} {'transl. (mm)':>12s} {'rot. (deg)':>11s} {'last tr. (mm)':>13s} "
          f"{'last rot.':>10s}")
    for name, pre in ((label, ""), ("no motion", "still_"), ("const. velocity", "constvel_")):
        print(f"{name:16s} {1e3 * res[pre + 'translation_rmse_final']:12.2f} "
              f"{res[pre + 'rotation_deg_final']:11.2f} "
              f"{1e3 * res[pre + 'translation_rmse_last']:13.2f} {res[pre + 'rotation_deg_last']:10.2f}")
    ci_t, ci_r = res["translation_rmse_ratio_still_ci95"], res["rotation_deg_ratio_still_ci95"]
    print(f"ratio to no motion: translation {res['translation_rmse_ratio_still']:.1%} "
          f"(95% interval {ci_t[0]:.0%}-{ci_t[1]:.0%}), rotation {res['rotation_deg_ratio_still']:.1%} "
          f"({ci_r[0]:.0%}-{ci_r[1]:.0%}); last frame {res['translation_rmse_last_ratio_still']:.1%}"
          f" / {res['rotation_deg_last_ratio_still']:.1%}")
    if "collision_edges_per_step" in res:
        print(f"collision edges per scene-step {res['collision_edges_per_step']:.1f}, "
              f"{res['ms_per_step_batched']:.1f} ms per batched step, "
              f"floor penetration ratio {res['penetration_ratio']:.2f}")
    if "against" in res:
        ag = res["against"]
        print(f"against {_against_label(ag)}: translation RMSE "
              f"{1e3 * ag['translation_rmse_final']:.2f} mm, rotation {ag['rotation_deg_final']:.2f} deg")
        for q, name in (("translation_rmse", "translation"), ("rotation_deg", "rotation"),
                        ("translation_rmse_last", "last-frame translation"),
                        ("rotation_deg_last", "last-frame rotation")):
            r, lo, hi = ag["ratios"][q]
            print(f"  ratio of medians (this / that), {name}: {r:.3f} (95% interval {lo:.3f}-{hi:.3f})")
    if "per_recording" in res:
        pr = res["per_recording"]
        print(f"per recording ({pr['recordings_final']} recordings reach frame {h}, each one's "
              f"trajectories averaged, then the median): {label} "
              f"{1e3 * pr['translation_rmse_final']:.2f} mm "
              f"/ {pr['rotation_deg_final']:.2f} deg, no motion "
              f"{1e3 * pr['still_translation_rmse_final']:.2f} mm / {pr['still_rotation_deg_final']:.2f} deg")
        if "against" in res:
            ag = res["against"]["per_recording"]
            print(f"  against: {1e3 * ag['translation_rmse_final']:.2f} mm / "
                  f"{ag['rotation_deg_final']:.2f} deg")
            for q, name in (("translation_rmse", "translation"), ("rotation_deg", "rotation")):
                r, lo, hi = pr["vs"][q]
                print(f"  ratio of medians over recordings, {name}: {r:.3f} (95% interval, recordings "
                      f"resampled, {lo:.3f}-{hi:.3f})")
    if "rotation_gain" in res:
        print(f"rotation gain (predicted / true turn of objects turning > 1 deg, median) "
              f"{res['rotation_gain']:.2f}; one-step spin gain (teacher-forced) "
              f"{res['one_step_spin_gain']:.2f}")
    if math.isfinite(res.get("yaw_slope", math.nan)):
        print(f"yaw about the vertical since the last given pose, predicted on true over every "
              f"object: slope {res['yaw_slope']:.2f}, correlation {res['yaw_correlation']:.2f}")
    if "one_step_free_flight" in res:
        if math.isfinite(res["one_step_free_flight"]):
            print(f"one-step free-flight acceleration error (RMS / |a| dt^2, {res['free_flight_steps']} "
                  f"steps, data's a = {res['free_flight_acceleration']:.2f} m/s^2) "
                  f"{res['one_step_free_flight']:.3f}")
        else:
            print(f"no free-flight metric: {res.get('one_step_free_flight_absent', 'undefined')}")


def plot_curves(res: dict[str, Any], path: Path) -> None:
    """Translation and rotation error against step (median over trajectories)."""
    plt = _pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    given = int(res.get("given_poses", 1))
    t = np.arange(given, given + len(res["translation_rmse_curve"]))
    ax[0].plot(t, res["translation_rmse_curve"])
    ax[0].set(xlabel="frame (from 0)", ylabel="translation RMSE (m), median")
    ax[1].plot(t, res["rotation_deg_curve"])
    ax[1].set(xlabel="frame (from 0)", ylabel="rotation error (deg), median")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=PLOT_DPI)
    plt.close(fig)


def plot_floor(rows: list[dict[str, Any]], path: Path, title: str = "") -> None:
    """Errors of :func:`perturbation_floor` (% of no motion) against the start error (log axis)."""
    plt = _pyplot()
    rows = [r for r in rows if r["position_noise"] > 0]
    noise = [1000 * r["position_noise"] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.2))
    for q, label in (("translation_rmse", "translation"), ("rotation_deg", "rotation")):
        ax.plot(noise, [100 * r[f"{q}_ratio_still"] for r in rows], "o-", label=label)
    ax.set(xscale="log", xlabel="start position error (mm)", ylabel="MuJoCo's error (% of no motion)",
           title=f"{title}, step {rows[0]['horizon_step']}" if rows else title)
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=PLOT_DPI)
    plt.close(fig)


def write_comparison_video(sim: LearnedSimulator, traj: Trajectory, path: Path) -> None:
    """Side-by-side video at real time: the data (left, labelled by :func:`truth_label`: ground
    truth of a simulator, or ``recorded``) and the learned rollout (right)."""
    H = sim.config.history + 1
    scene = build_scene(traj, sim.config.mesh_options)
    true = torch.as_tensor(traj.poses, dtype=torch.float32)
    pred, _, _ = batched_rollout(sim, scene, true)
    pred_full = torch.cat((true[:H], pred)).double().numpy()
    model, bodies = trajectory_model(traj)
    # One camera for both halves, framed on the ground truth, so the two are comparable.
    cam = fit_camera(model, bodies, traj.poses)
    fixed = Camera(lookat=tuple(cam.lookat), distance=float(cam.distance))
    left = render_frames(model, traj.poses, bodies, VIDEO_SIZE, VIDEO_SIZE, fixed)
    right = render_frames(model, pred_full, bodies, VIDEO_SIZE, VIDEO_SIZE, fixed)
    left = [_label(f, truth_label(traj)) for f in left]
    right = [_label(f, "FIGNet rollout") for f in right]
    write_video(side_by_side(left, right), path, fps=1.0 / traj.dt)


def _label(frame: np.ndarray, text: str) -> np.ndarray:
    """The frame ``uint8[H, W, 3]`` with ``text`` written in its top-left corner."""
    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img)
    width = 2 * LABEL_INSET + LABEL_GLYPH_WIDTH * len(text)
    draw.rectangle((0, 0, width, LABEL_HEIGHT), fill=(0, 0, 0))
    draw.text((LABEL_INSET, LABEL_INSET), text, fill=(255, 255, 255))
    return np.asarray(img)
