"""The ``sim2real`` report: the table of every model's errors against training size, as % of no
motion, with paired ratios to fitted MuJoCo, the error-against-size plot and the summary lines."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

#: Columns of the table: (key prefix, heading).
_QUANTITIES = (("translation_rmse_final", "transl. @h (mm)"), ("rotation_deg_final", "rot. @h (deg)"),
               ("translation_rmse_last", "transl. last (mm)"), ("rotation_deg_last", "rot. last (deg)"))


def headline(res: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, _ in _QUANTITIES:
        out[key] = res[prefix + key]
        q, at = key.rsplit("_", 1)
        suffix = "" if at == "final" else "_last"
        ratio = res.get(f"{q}{suffix}_ratio_still") if not prefix else 1.0
        out[f"{key}_ratio_still"] = ratio
    out["horizon_step"] = res["horizon_step"]
    if "seconds" in res:
        out["seconds"] = res["seconds"]
    out["trajectories"] = res["trajectories"]
    return out


def format_table(results: dict[str, Any]) -> str:
    """Markdown table of the headline errors (and % of no motion) of every model."""
    h = results["mujoco_fitted"]["horizon_step"]
    n = results["mujoco_fitted"]["trajectories"]
    sec = results["mujoco_fitted"].get("seconds")
    at = f"frame {h} ({sec:.2f} s)" if sec is not None else f"frame {h}"
    head = ["model"] + [f"{name.replace('@h', f'@{h}')}" for _, name in _QUANTITIES]
    lines = [f"Test split: {n} trajectories; medians at {at} (from frame 0) and at each "
             "trajectory's last frame; (x%) = fraction of the no-motion model's error.", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def row(label: str, r: dict[str, Any]) -> str:
        cells = []
        for key, _ in _QUANTITIES:
            v = r[key] * (1000 if key.startswith("translation") else 1)
            ratio = r.get(f"{key}_ratio_still")
            cells.append(f"{v:.1f} ({100 * ratio:.0f}%)" if ratio is not None and math.isfinite(ratio)
                         else f"{v:.1f}")
        return f"| {label} | " + " | ".join(cells) + " |"

    lines.append(row("no motion", results["no_motion"]))
    lines.append(row("MuJoCo, nominal", results["mujoco_nominal"]))
    lines.append(row("MuJoCo, fitted", results["mujoco_fitted"]))
    if "limit_surface" in results:
        lines.append(row("limit surface, fitted", results["limit_surface"]))
    if "noise_floor" in results:
        nf = results["noise_floor"]
        lines.append(row(f"noise floor ({1000 * nf['noise']['position_m']:.3f} mm, "
                         f"{nf['noise']['rotation_deg']:.3f} deg)", nf))
    by_size = sorted(results["fignet"].values(), key=lambda r: r["training_trajectories"])
    for r in by_size:
        lines.append(row(f"FIGNet, {r['training_trajectories']} train", r))
    if "vs_fitted_mujoco" in results.get("limit_surface", {}):
        v = results["limit_surface"]["vs_fitted_mujoco"]
        lines += ["", "Limit surface / fitted MuJoCo (paired bootstrap 95%): " + ", ".join(
            f"{k} {v[k][0]:.2f} [{v[k][1]:.2f}, {v[k][2]:.2f}]" for k in v)]
    if results["fignet"]:
        lines += ["", "FIGNet / fitted MuJoCo, ratio of medians on the same test trajectories "
                  "(paired bootstrap 95% interval):", "",
                  "| training trajectories | transl. @h | rot. @h | transl. last | rot. last |",
                  "|---|---|---|---|---|"]
        for r in by_size:
            v = r["vs_fitted_mujoco"]
            cells = [f"{v[k][0]:.2f} [{v[k][1]:.2f}, {v[k][2]:.2f}]"
                     for k in ("translation_rmse", "rotation_deg", "translation_rmse_last",
                               "rotation_deg_last")]
            lines.append(f"| {r['training_trajectories']} | " + " | ".join(cells) + " |")
    if "per_recording" in results:
        per = results["per_recording"]
        first = next(iter(per.values()))
        lines += ["", f"Per recording (each recording's test trajectories averaged, then the median "
                  f"over the {first['recordings_final']} recordings; a push cut into many windows "
                  f"counts once), at {at}; ratio to fitted MuJoCo, bootstrap over recordings:",
                  "", "| model | transl. (mm) | rot. (deg) | ratio transl. | ratio rot. |",
                  "|---|---|---|---|---|",
                  f"| no motion | {1e3 * first['still_translation_rmse_final']:.2f} | "
                  f"{first['still_rotation_deg_final']:.2f} | | |"]
        for label, r in per.items():
            v = r["vs"]
            lines.append(f"| {label} | {1e3 * r['translation_rmse_final']:.2f} | "
                         f"{r['rotation_deg_final']:.2f} | " + " | ".join(
                             f"{v[k][0]:.2f} [{v[k][1]:.2f}, {v[k][2]:.2f}]"
                             for k in ("translation_rmse", "rotation_deg")) + " |")
    return "\n".join(lines)


def plot_sizes(results: dict[str, Any], path: Path) -> None:
    """Errors (% of no motion) against training-set size: FIGNet points, MuJoCo (and, for pushes,
    limit-surface) lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(15, 3.4))
    fg = sorted(results["fignet"].values(), key=lambda r: r["training_trajectories"])
    for ax, (key, name) in zip(axes, _QUANTITIES, strict=True):
        k = f"{key}_ratio_still"
        if fg:
            ax.plot([r["training_trajectories"] for r in fg], [100 * r[k] for r in fg], "o-",
                    label="FIGNet")
        for label, style in (("mujoco_fitted", "--"), ("mujoco_nominal", ":"), ("limit_surface", "-.")):
            if label in results:
                ax.axhline(100 * results[label][k], linestyle=style,
                           color={"mujoco_fitted": "k", "limit_surface": "tab:red"}.get(label, "gray"),
                           label=label.replace("mujoco_", "MuJoCo, ").replace("_", " "))
        ax.set(xscale="log", xlabel="training trajectories", title=name.replace(
            "@h", f"@{results['mujoco_fitted']['horizon_step']}"), ylabel="% of no motion")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def summary_lines(results: dict[str, Any]) -> list[str]:
    """Short text of the fit (for logs)."""
    p = results["fit"]["params"]
    text = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in p.items())
    return [f"fitted MuJoCo: {text}"]

