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
    # deferred: Matplotlib loads, and its Agg backend is chosen, only when a plot is drawn
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the backend is chosen

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


def compare_runs(runs: dict[str, dict[str, Any]], out: Path) -> str:
    """Several ``sim2real`` runs on the same split (``{label: results.json}``; FIGNet recipes
    side by side): a Markdown table of every arm and size, over windows and per recording, with
    ratios to fitted MuJoCo, and ``compare.png`` (error against size, the analytic models as
    lines); writes ``compare.md`` and returns the table. ``ValueError`` if the runs were scored
    on different test splits (their fitted MuJoCo errors differ)."""
    first = next(iter(runs.values()))
    ref = first["mujoco_fitted"]
    for label, r in runs.items():
        if (r["mujoco_fitted"]["trajectories"], r["split"]) != (ref["trajectories"], first["split"]):
            raise ValueError(f"{label}: scored on another split ({r['split']} against "
                             f"{first['split']}): compare runs of one --data and --seed")
    h, sec = ref["horizon_step"], ref.get("seconds")
    at = f"frame {h} ({sec:.2f} s)" if sec is not None else f"frame {h}"
    per = first.get("per_recording", {})
    lines = [f"Medians at {at} over the {ref['trajectories']} test trajectories (windows) and, "
             "per recording, over each push's windows averaged; ratio to fitted MuJoCo with its "
             "paired bootstrap 95% interval (recordings resampled).", "",
             "| model | train | windows: transl. (mm) | rot. (deg) | ratio transl. | ratio rot. "
             "| per push: transl. (mm) | rot. (deg) | ratio transl. | ratio rot. |",
             "|---|---|---|---|---|---|---|---|---|---|"]

    def cells(win: dict[str, Any], vs: dict[str, Any] | None, rec: dict[str, Any] | None) -> str:
        out = [f"{1e3 * win['translation_rmse_final']:.2f}", f"{win['rotation_deg_final']:.2f}"]
        out += ([f"{vs[k][0]:.2f} [{vs[k][1]:.2f}, {vs[k][2]:.2f}]" for k in ("translation_rmse",
                                                                            "rotation_deg")]
                if vs else ["1", "1"])
        if rec is not None:
            out += [f"{1e3 * rec['translation_rmse_final']:.2f}", f"{rec['rotation_deg_final']:.2f}"]
            out += [f"{rec['vs'][k][0]:.2f} [{rec['vs'][k][1]:.2f}, {rec['vs'][k][2]:.2f}]"
                    for k in ("translation_rmse", "rotation_deg")]
        else:
            out += ["", "", "", ""]
        return " | ".join(out)

    analytic = [("MuJoCo, nominal", "mujoco_nominal"), ("MuJoCo, fitted", "mujoco_fitted"),
                ("limit surface, fitted", "limit_surface")]
    for name, key in analytic:
        if key in first:
            vs = first[key].get("vs_fitted_mujoco") if key != "mujoco_fitted" else None
            lines.append(f"| {name} | | {cells(first[key], vs, per.get(name))} |")
    for label, r in runs.items():
        rec = r.get("per_recording", {})
        for f in sorted(r["fignet"].values(), key=lambda v: v["training_trajectories"]):
            n = f["training_trajectories"]
            lines.append(f"| {label} | {n} | "
                         f"{cells(f, f['vs_fitted_mujoco'], rec.get(f'FIGNet, {n} train'))} |")
    table = "\n".join(lines)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.md").write_text(table + "\n")
    _plot_compare(runs, out / "compare.png")
    return table


def _plot_compare(runs: dict[str, dict[str, Any]], path: Path) -> None:
    # deferred: Matplotlib loads, and its Agg backend is chosen, only when a plot is drawn
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the backend is chosen

    first = next(iter(runs.values()))
    views = [("windows", lambda r, key: r.get(key), "translation_rmse_final", "translation"),
             ("windows", lambda r, key: r.get(key), "rotation_deg_final", "rotation")]
    if "per_recording" in first:
        views += [("per push", lambda r, key: r.get("per_recording", {}).get(key),
                   "translation_rmse_final", "translation"),
                  ("per push", lambda r, key: r.get("per_recording", {}).get(key),
                   "rotation_deg_final", "rotation")]
    fig, axes = plt.subplots(1, len(views), figsize=(4 * len(views), 3.4))
    names = {"mujoco_nominal": "MuJoCo, nominal", "mujoco_fitted": "MuJoCo, fitted",
             "limit_surface": "limit surface, fitted"}
    styles = {"mujoco_nominal": ("gray", ":"), "mujoco_fitted": ("k", "--"),
              "limit_surface": ("tab:red", "-.")}
    for ax, (view, get, q, title) in zip(axes, views, strict=True):
        unit = 1e3 if q.startswith("translation") else 1.0
        for label, r in runs.items():
            pts = sorted((f["training_trajectories"],
                          get(r, f"FIGNet, {f['training_trajectories']} train") if view != "windows"
                          else f) for f in r["fignet"].values())
            pts = [(n, v) for n, v in pts if v is not None]
            ax.plot([n for n, _ in pts], [unit * v[q] for _, v in pts], "o-", label=label)
        for key, name in names.items():
            v = get(first, name) if view != "windows" else first.get(key)
            if v is not None:
                color, style = styles[key]
                ax.axhline(unit * v[q], color=color, linestyle=style, label=name)
        ax.set(xscale="log", xlabel="training trajectories (windows)",
               ylabel="mm" if unit > 1 else "deg", title=f"{title}, {view}")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def summary_lines(results: dict[str, Any]) -> list[str]:
    """Short text of the fit (for logs)."""
    p = results["fit"]["params"]
    text = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in p.items())
    return [f"fitted MuJoCo: {text}"]

