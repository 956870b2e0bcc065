"""``fignet-gym sim2real``: nominal MuJoCo, fitted MuJoCo and FIGNet at several training-set sizes
on one real (or stand-in) trajectory file, scored on a held-out split.

Stages, each written to ``OUT`` as it finishes (``--resume`` skips finished ones; a killed FIGNet
run resumes from its last checkpoint). ``run.json`` records the options, the FIGNet recipe
(``--config``, ``--budget``, ``--set``, ``--init``) included: a resume with other ones is refused,
so one table never compares sizes trained differently. A file mixing scene types is refused.

1. ``split/``: seeded train / validation / test files (:func:`~fignet_gym.data.split.write_split`).
2. ``mujoco_nominal.json``: MuJoCo with the MJCF's own parameters replaying the test split.
3. ``mujoco_fit.json``: contact parameters fitted on training, selected on validation
   (:func:`~fignet_gym.train.sysid.fit_contact_params`); ``mujoco_fitted_env.json`` is the same in
   the ``CubeToss-v0`` env's form. ``mujoco_fitted.json``: the fitted MuJoCo on test.
4. ``pretrain/`` (only with ``pretrain`` > 0, ``--pretrain N``): MuJoCo fitted on the first
   ``min(sizes)`` training trajectories (``fit.json``; every size's subset contains them, so no
   model sees a trajectory outside its own subset), ``N`` synthetic tosses re-simulated in it
   from randomised releases (``synthetic.h5``, :mod:`fignet_gym.train.synthetic`), and a FIGNet
   pretrained on them (``run/``, selected on the real validation split). Each size then fine-tunes
   it (:data:`FINETUNE_OVERRIDES`) instead of training from scratch.
5. ``fignet_<size>/``: a FIGNet run on the first ``size`` training trajectories (the training
   step is :func:`default_train`, a call to ``fignet_gym.train.real.train_on_split``; any callable
   ``(train_file, valid_file, size, out_dir) -> checkpoint`` can replace it; with ``polish``,
   runs on ``POLISH_MIN_SIZE`` or more trajectories are then fine-tuned through rollouts in
   ``fignet_<size>/polish/``), and ``fignet_<size>.json``: its test metrics, with paired
   bootstrap ratios to fitted MuJoCo.
6. ``results.json`` (with the CPU hours of every stage), ``table.md`` and ``errors_vs_size.png``.

Errors: median translation RMSE and rotation error over test trajectories at frame ``horizon``
counted from frame 0 (50: 0.34 s on the cube data) and at each trajectory's last frame, each also
as a fraction of the no-motion model's (the paper's Fig. 7c unit). Every model is given the same
first ``history + 1`` poses.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

from fignet_gym.atomic import write_text
from fignet_gym.data.format import TrajectoryFile, build_scene, load_trajectories
from fignet_gym.data.guards import check_single_scene_type
from fignet_gym.data.split import DEFAULT_FRACTIONS, file_split, group_members, write_split
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.scene import ObjectKind
from fignet_gym.train.analytic import ContactParams
from fignet_gym.train.config import load_run_config
from fignet_gym.train.data_checks import same_dt
from fignet_gym.train.evaluation import rollout_metrics
from fignet_gym.train.metrics import predictor_metrics
from fignet_gym.train.real_baselines import run_stages
from fignet_gym.train.sim2real_report import format_table, headline, plot_sizes, summary_lines
from fignet_gym.train.stats import paired_ratios, per_recording
from fignet_gym.train.synthetic import check_tosses

TrainFn = Callable[[Path, Path, "int | None", Path], Path]


#: A dynamic object whose lowest node stays this close (m) to ``z = 0`` in every frame rests on
#: the floor (the threshold of ``free_flight_gravity``'s free flight).
FLOOR_CLEARANCE = 0.01
#: ``--pretrain``: optimiser steps on the synthetic tosses (pushforward after 1/8 of them).
PRETRAIN_STEPS = 8000
#: ``--pretrain``: how each size fine-tunes the pretrained model: a low learning rate and
#: pushforward from the first step (on 8 real tosses, 1e-4 or plain one-step training first lost
#: the pretraining's rollouts within 250 steps; experiments/README.md, real data,
#: "Pretraining on a fitted MuJoCo").
#: ``--pretrain`` on pushes: optimiser steps on the synthetic pushes (from ``--init``).
PUSH_PRETRAIN_STEPS = 2000
#: ``--prior``: the fitted analytic models synthetic pushes are drawn from (half each for both).
PRIORS = ("mujoco", "limit-surface", "both")
FINETUNE_OVERRIDES: dict[str, Any] = {"training.lr": 3e-5, "training.lr_final": 1e-5,
                                      "training.unroll_after": 0}


def pretrain_checkpoint(out: str | os.PathLike) -> Path:
    """Where a ``--pretrain`` run in ``out`` keeps its pretrained model (what sizes fine-tune)."""
    return Path(out) / "pretrain" / "run" / "best.pt"


class Sim2RealError(ValueError):
    """A user error of ``sim2real`` (the message names the file or folder)."""


def default_train(config: str = "cube-real", budget: int | None = None,
                  overrides: dict[str, Any] | None = None, init: str | None = None,
                  polish: bool = True) -> TrainFn:
    """The FIGNet training step: ``train_on_split`` with ``config`` and ``budget`` optimiser
    steps (or its size-dependent default), from scratch or warm-started from ``init`` (a
    checkpoint or pretrained name), selected on validation either way; with ``polish``, subsets
    of ``POLISH_MIN_SIZE`` or more trajectories are then polished through rollouts."""

    def train(train_file: Path, valid_file: Path, size: int | None, out_dir: Path) -> Path:
        # deferred: train.real loads the trainer and TensorBoard; `fignet-gym --help` imports this module
        from fignet_gym.train import real

        trajs = load_trajectories(train_file)
        n = size if size is not None else len(trajs)
        sets = dict(overrides or {})
        if "simulator.gravity" not in sets and rests_on_floor(trajs[:n]):
            # Pushes: nothing flies, so there is no gravity to measure, and none to learn (the
            # floor balances it): the model keeps its own prior.
            sets["simulator.gravity"] = prior_gravity(config, init)
        return real.train_on_split(train_file, valid_file, size, out_dir, budget, config=config,
                                   overrides=sets or None, init=init,
                                   polish=polish and n >= real.POLISH_MIN_SIZE)

    return train


def _check_sizes(sizes: Sequence[int | None], n_train: int, data: str | os.PathLike) -> None:
    """Refuse a training-set size larger than the training split (``n_train`` trajectories)."""
    for s in sizes:
        if s is not None and s > n_train:
            raise Sim2RealError(f"{data}: training-set size {s} exceeds the training split's "
                                f"{n_train} trajectories")


def _check_init_dt(data: str | os.PathLike, init: str) -> None:
    """Refuse to fine-tune ``init`` on data of another step: the model predicts one step of its
    own ``dt``, and ``evaluate`` would refuse the pairing too."""
    dt = load_pretrained(init).config.dt
    with TrajectoryFile(data) as f:
        data_dt = f[0].dt
    if not same_dt(data_dt, dt):
        raise Sim2RealError(f"{data}: poses every {data_dt:g} s, but --init {init} steps {dt:g} s "
                            f"(re-import with `fignet-gym import-mit ... --dt {dt:g}`, or train "
                            "from scratch without --init)")


def _check_pretrain(data: str | os.PathLike, init: str | None, prior: str) -> None:
    """:class:`Sim2RealError` before anything is written if ``--pretrain`` cannot vary the
    data's trajectories: tosses start from scratch and know only the MuJoCo prior."""
    with TrajectoryFile(data) as f:
        push = _has_kinematic(f[0])
    if not push and init is not None:
        raise Sim2RealError("--pretrain and --init: synthetic tosses pretrain from scratch; "
                            "pass one of the two")
    if not push and prior != "mujoco":
        raise Sim2RealError(f"--prior {prior}: the limit surface models pushes; tosses pretrain "
                            "on the fitted MuJoCo only")


def rests_on_floor(trajs: Sequence[Any], clearance: float = FLOOR_CLEARANCE) -> bool:
    """True if in every frame of every trajectory the lowest node of each dynamic object is within
    ``clearance`` (m) of the floor plane ``z = 0``: planar pushes, whose objects never fly.

    Such data carries no free flight to measure gravity from (``free_flight_gravity``), and its
    motion does not depend on gravity apart from the friction it loads, which the friction
    coefficients absorb.
    """
    for traj in trajs:
        scene = build_scene(traj)
        dyn = scene.dynamic_mask
        if not bool(dyn.any()):
            continue
        poses = torch.as_tensor(traj.poses, dtype=torch.float32)
        z = scene.node_positions(poses)[:, :, 2]  # [T, N]
        for o in dyn.nonzero().flatten().tolist():
            low = z[:, scene.node_object == o].amin(dim=1)  # [T]
            if bool((low.abs() > clearance).any()):
                return False
    return True


def push_space(kinematic: bool = True) -> tuple[Any, ...]:
    """The searched parameters of objects on a floor: ``DEFAULT_SPACE`` without gravity, plus,
    with ``kinematic`` objects (a pusher), their own friction: object-floor and tip-object
    friction, torsional friction, ``solref`` (the cone and the substeps are chosen as for any
    fit)."""
    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); `fignet-gym --help` imports this module
    from fignet_gym.train.sysid import DEFAULT_SPACE, KINEMATIC_ONLY

    return tuple(d for d in DEFAULT_SPACE if d.name != "gravity") + (KINEMATIC_ONLY if kinematic
                                                                     else ())


def _has_kinematic(traj: Any) -> bool:
    return bool((traj.kinds == int(ObjectKind.KINEMATIC)).any())


def prior_gravity(config: str, init: str | None = None) -> tuple[float, float, float]:
    """The gravity prior ``(gx, gy, gz)`` a model keeps when the data cannot measure one: the
    ``init`` checkpoint's own (a fine-tune), else the ``config`` preset's."""
    if init is not None:
        return tuple(float(g) for g in load_pretrained(init).config.gravity)  # type: ignore[return-value]

    sim_cfg, _ = load_run_config(config)
    return tuple(float(g) for g in SimulatorConfig.from_dict(sim_cfg).gravity)  # type: ignore[return-value]


def _read(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()) if path.is_file() else None


def _write(path: Path, obj: dict[str, Any]) -> None:
    write_text(path, json.dumps(obj, indent=1, default=float))


def _size_label(size: int | None) -> str:
    return "all" if size is None else str(size)


def parse_sizes(values: Sequence[str]) -> list[int | None]:
    """``["8", "16", "all"]`` -> ``[8, 16, None]``; :class:`Sim2RealError` on anything else."""
    out: list[int | None] = []
    for v in values:
        if str(v).lower() == "all":
            out.append(None)
        else:
            try:
                n = int(v)
            except ValueError:
                raise Sim2RealError(f"--sizes: {v!r} is not a number or 'all'") from None
            if n < 1:
                raise Sim2RealError(f"--sizes: {n} must be at least 1")
            out.append(n)
    return out


def _mujoco_metrics(trajs: list, params: Any, given: int, horizon: int) -> dict[str, Any]:
    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); `fignet-gym --help` imports this module
    from fignet_gym.train.sysid import ReplaySet

    rs = ReplaySet(trajs, given, horizon)
    t0 = time.process_time()
    preds = rs.predict(params)
    out = predictor_metrics(trajs, preds, given, horizon)
    out["cpu_seconds"] = time.process_time() - t0
    out["params"] = params.to_json()
    return out


def run_sim2real(
    data: str | os.PathLike, out: str | os.PathLike, sizes: Sequence[int | None] = (8, 16, 32, 64, 128, None),
    *, fractions: Sequence[float] = DEFAULT_FRACTIONS, seed: int = 0, horizon: int = 50,
    given: int = 3, resume: bool = False, fit_evaluations: int = 240, fit_trajectories: int = 64,
    train_fn: TrainFn | None = None, fignet: bool = True, base_params: Any = None,
    pretrain: int = 0, config: str = "cube-real", budget: int | None = None,
    overrides: dict[str, Any] | None = None, init: str | None = None, polish: bool = True,
    prior: str = "mujoco", pretrain_budget: int | None = None,
) -> dict[str, Any]:
    """Run every stage (see the module docstring) and return the results dict.

    ``pretrain``: synthetic tosses or pushes to pretrain on (0: none), pushes drawn from
    ``prior`` (:data:`PRIORS`) and pretrained from ``init`` for ``pretrain_budget`` optimiser
    steps (pushes; default :data:`PUSH_PRETRAIN_STEPS`). ``train_fn`` trains each size;
    by default :func:`default_train` with ``config``, ``budget``, ``overrides`` and ``init``, or
    with ``pretrain`` a fine-tuning of :func:`pretrain_checkpoint` (:data:`FINETUNE_OVERRIDES`).
    ``config`` and ``overrides`` are also the pretraining's recipe. ``polish``: polish the
    models of ``POLISH_MIN_SIZE`` or more trajectories through rollouts (``train_on_split``).
    """
    # deferred: train.real loads the trainer and TensorBoard; `fignet-gym --help` imports this module
    from fignet_gym.train.real import run_cpu_hours

    # deferred: sysid loads CMA-ES and Matplotlib (~0.9 s); `fignet-gym --help` imports this module
    from fignet_gym.train.sysid import env_parameters, fit_contact_params

    out = Path(out)
    if prior not in PRIORS:
        raise Sim2RealError(f"--prior {prior!r}: choose one of {', '.join(PRIORS)}")
    results_path = out / "results.json"
    if out.exists() and any(out.iterdir()) and not resume:
        raise Sim2RealError(f"{out}: already holds a sim2real run (pass --resume to continue it, "
                            "or choose another --out)")
    config_path = out / "run.json"
    run_cfg = {"data": str(data), "fractions": list(fractions), "seed": seed, "horizon": horizon,
               "given_poses": given, "fit_evaluations": fit_evaluations,
               "fit_trajectories": fit_trajectories, "pretrain": pretrain, "polish": polish}
    if pretrain:
        run_cfg["prior"] = prior
        run_cfg["pretrain_budget"] = pretrain_budget  # None: PUSH_PRETRAIN_STEPS / PRETRAIN_STEPS
    old = _read(config_path)
    # Runs from before a key existed ran with its old behaviour (no pretraining, no polish).
    absent = {"pretrain": 0, "polish": False, "prior": "mujoco", "pretrain_budget": None}
    then = {k: old.get(k, absent.get(k)) for k in run_cfg} if old is not None else run_cfg
    changed = [f"{k} {then[k]!r} (now {v!r})" for k, v in run_cfg.items() if then[k] != v]
    if changed:
        raise Sim2RealError(f"{config_path}: this run was started with {', '.join(changed)}: "
                            "resume it with the same options (--no-polish for polish False) or "
                            "use another --out")
    recipe = _recipe(train_fn, config, budget, overrides, init) if fignet else None
    run_cfg["recipe"] = _check_recipe(config_path, (old or {}).get("recipe"), recipe)
    split_dir = out / "split"
    if not (split_dir / "split.json").is_file():
        # Everything that can be refused is refused before anything is written, so a corrected
        # rerun needs no --resume.
        check_single_scene_type(data, "--data")
        planned = file_split(data, fractions, seed)  # too few recordings: refused here too
        _check_sizes(sizes if fignet else (), len(planned.train), data)
    if pretrain and fignet:
        _check_pretrain(data, init, prior)
    if fignet and init is not None:
        _check_init_dt(data, init)
    out.mkdir(parents=True, exist_ok=True)
    _write(config_path, run_cfg)

    if not (split_dir / "split.json").is_file():
        write_split(data, split_dir, fractions, seed, force=True)  # no split.json: unfinished
    split = json.loads((split_dir / "split.json").read_text())
    n_train = len(split["train"])
    _check_sizes(sizes if fignet else (), n_train, data)
    train = load_trajectories(split_dir / "train.h5")
    valid = load_trajectories(split_dir / "valid.h5")
    test = load_trajectories(split_dir / "test.h5")
    stages: dict[str, Any] = {"split": {k: len(split[k]) for k in ("train", "valid", "test")}}

    base = base_params or ContactParams()
    nominal = _read(out / "mujoco_nominal.json")
    if nominal is None:
        print("nominal MuJoCo on the test split ...")
        nominal = _mujoco_metrics(test, base, given, horizon)
        _write(out / "mujoco_nominal.json", nominal)
    # Pushes on a floor: gravity only loads the friction, which the friction coefficients
    # absorb, so it is not searched (the two would be one degenerate direction).
    planar = rests_on_floor(train)
    stages["rests_on_floor"] = planar
    space = push_space(kinematic=any(_has_kinematic(t) for t in train)) if planar else None
    fit = fit_contact_params(train, valid, out / "mujoco_fit.json", base=base,
                             evaluations=fit_evaluations, fit_trajectories=fit_trajectories,
                             given=given, horizon=horizon, seed=seed, space=space)
    fitted_params = ContactParams.from_json(fit["params"])
    _write(out / "mujoco_fitted_env.json",
           env_parameters(fitted_params, test[0].dt, f"sim2real fit on {Path(data).name} "
                          f"(seed {seed}, {n_train} training trajectories)"))
    fitted = _read(out / "mujoco_fitted.json")
    if fitted is None:
        print("fitted MuJoCo on the test split ...")
        fitted = _mujoco_metrics(test, fitted_params, given, horizon)
        _write(out / "mujoco_fitted.json", fitted)

    extra = run_stages(out, train, test, fitted_params, fitted, planar and space is not None
                       and any(_has_kinematic(t) for t in train), given, horizon,
                       fit_trajectories, seed)
    cpu_hours: dict[str, Any] = {"mujoco_fit": fit.get("cpu_seconds", math.nan) / 3600}
    for name, r in extra.items():
        cpu_hours[name] = r["cpu_seconds"] / 3600
    if pretrain and fignet:
        k0 = min([s for s in sizes if s is not None], default=n_train)
        info = _pretrain(train[:k0], valid, split_dir / "valid.h5", out / "pretrain", pretrain,
                         config=config, overrides=overrides, fit_evaluations=fit_evaluations,
                         fit_trajectories=fit_trajectories, given=given, horizon=horizon, seed=seed,
                         prior=prior, init=init, budget=pretrain_budget)
        stages["pretrain"] = info
        cpu_hours["pretrain"] = info["cpu_hours"]
    learned: dict[str, Any] = {}
    if fignet:
        if train_fn is None and pretrain:
            # Tosses fine-tune gently (FINETUNE_OVERRIDES); pushes with their own recipe, the
            # one a fine-tune from --init uses, so the two compare at the same budget.
            sets = (overrides if any(_has_kinematic(t) for t in train)
                    else {**FINETUNE_OVERRIDES, **(overrides or {})})
            train_fn = default_train(config, budget, sets, init=str(pretrain_checkpoint(out)),
                                     polish=polish)
        elif train_fn is None:
            train_fn = default_train(config, budget, overrides, init, polish)
        for size in sizes:
            label = _size_label(size)
            path = out / f"fignet_{label}.json"
            res = _read(path)
            if res is None:
                print(f"FIGNet on {label} training trajectories ...")
                ckpt = train_fn(split_dir / "train.h5", split_dir / "valid.h5", size,
                                out / f"fignet_{label}")
                sim = load_pretrained(str(ckpt))
                if sim.config.history + 1 != given:
                    raise Sim2RealError(f"{ckpt}: the model takes {sim.config.history + 1} poses, "
                                        f"the MuJoCo baselines {given}: scores would not compare")
                res = rollout_metrics(sim, test, horizon=horizon)
                res["checkpoint"] = str(ckpt)
                res["recipe"] = run_cfg["recipe"]
                res["training_trajectories"] = size if size is not None else n_train
                res["vs_fitted_mujoco"] = paired_ratios(res, fitted)
                _write(path, res)
            learned[label] = res
            cpu_hours.setdefault("fignet", {})[label] = run_cpu_hours(out / f"fignet_{label}")
    cpu_hours["total"] = (cpu_hours["mujoco_fit"] + cpu_hours.get("pretrain", 0.0)
                          + sum(cpu_hours.get(name, 0.0) for name in extra)
                          + sum(cpu_hours.get("fignet", {}).values()))
    results = {"run": run_cfg, **stages, "cpu_hours": cpu_hours,
               "fit": {k: fit[k] for k in ("params", "valid", "cpu_seconds")},
               "mujoco_nominal": headline(nominal), "mujoco_fitted": headline(fitted),
               "no_motion": headline(fitted, prefix="still_"),
               **{name: {**headline(r), **{k: r[k] for k in ("params", "vs_fitted_mujoco", "noise")
                                            if k in r}} for name, r in extra.items()},
               "fignet": {k: {**headline(v), "training_trajectories": v["training_trajectories"],
                              "vs_fitted_mujoco": v["vs_fitted_mujoco"]} for k, v in learned.items()}}
    scored = {"MuJoCo, nominal": nominal, "MuJoCo, fitted": fitted,
              **({"limit surface, fitted": extra["limit_surface"]} if "limit_surface" in extra else {}),
              **{f"FIGNet, {v['training_trajectories']} train": v
                 for v in sorted(learned.values(), key=lambda v: v["training_trajectories"])}}
    if len(group_members(fitted["horizon_trajectories"], fitted.get("groups_final"))) < \
            fitted["horizon_trajectories"]:
        # Several windows per recording (long real pushes): each recording counts once too.
        results["per_recording"] = {k: per_recording(r, fitted) for k, r in scored.items()}
    _write(results_path, results)
    table = format_table(results)
    (out / "table.md").write_text(table + "\n")
    plot_sizes(results, out / "errors_vs_size.png")
    print(table)
    print(f"wrote {results_path}, {out / 'table.md'}, {out / 'errors_vs_size.png'}")
    return results


#: The FIGNet recipe's keys and the options that set them (named when a resume differs).
_RECIPE_OPTIONS = {"config": "--config", "budget": "--budget", "set": "--set", "init": "--init",
                   "train_fn": "train_fn"}


def _recipe(train_fn: TrainFn | None, config: str, budget: int | None,
            overrides: dict[str, Any] | None, init: str | None) -> dict[str, Any]:
    """How every size's FIGNet is trained, as stored in ``run.json`` (JSON-normalised)."""
    if train_fn is not None:  # a caller's own training step: all that can be recorded is its name
        return {"train_fn": f"{train_fn.__module__}.{train_fn.__qualname__}"}
    recipe = {"config": config, "budget": budget, "set": overrides or {}, "init": init}
    return json.loads(json.dumps(recipe, default=float))


def _check_recipe(config_path: Path, stored: dict[str, Any] | None,
                  asked: dict[str, Any] | None) -> dict[str, Any] | None:
    """The recipe to record; :class:`Sim2RealError` if it differs from the one the run's sizes
    were trained with (one table would compare models trained differently). A run that has
    none yet (``--no-fignet`` so far, or from before recipes were recorded) takes the new one."""
    if asked is None or stored is None:
        return stored if asked is None else asked
    keys = sorted(set(stored) | set(asked), key=list(_RECIPE_OPTIONS).index)
    diffs = [f"{_RECIPE_OPTIONS[k]} {stored.get(k)!r} (now {asked.get(k)!r})" for k in keys
             if stored.get(k) != asked.get(k)]
    if diffs:
        raise Sim2RealError(f"{config_path}: this run's FIGNet sizes are trained with "
                            f"{', '.join(diffs)}: resume it with the same recipe, or use another "
                            "--out for another recipe")
    return stored


def _pretrain(train: list, valid: list, valid_file: Path, out: Path, num: int, *, config: str,
              overrides: dict[str, Any] | None, fit_evaluations: int, fit_trajectories: int,
              given: int, horizon: int, seed: int, prior: str = "mujoco", init: str | None = None,
              budget: int | None = None) -> dict[str, Any]:
    """The ``pretrain/`` stage (module docstring) on the real trajectories ``train``; resumable.

    Tosses vary their releases in the fitted MuJoCo; pushes (trajectories with a kinematic
    pusher) draw new pushes of the same objects (:mod:`fignet_gym.train.synthetic_push`) from
    ``prior``: ``"mujoco"``, ``"limit-surface"`` or ``"both"`` (half each), each fitted on
    ``train``, and pretrain from ``init`` (``None``: from scratch)."""
    # deferred: train.real loads the trainer and TensorBoard; `fignet-gym --help` imports this module
    from fignet_gym.train.real import free_flight_gravity, train_on_split

    # deferred: the synthetic prior fits MuJoCo (sysid: CMA-ES, Matplotlib); only when pretraining
    from fignet_gym.train.sim2real_prior import synthetic_prior

    push = any(_has_kinematic(t) for t in train)
    if not push:
        try:
            check_tosses(train)
        except ValueError as exc:
            raise Sim2RealError(f"--pretrain: {exc}") from None
    synth, fit, ls, gen_seconds = synthetic_prior(
        train, valid, out, num, prior=prior, push=push, fit_evaluations=fit_evaluations,
        fit_trajectories=fit_trajectories, given=given, horizon=horizon, seed=seed,
        space=push_space(kinematic=True) if push else None)
    kind = "pushes" if push else "tosses"
    print(f"pretraining: FIGNet on {num} synthetic {kind} ({prior}) ...")
    if push:
        sets = {"simulator.gravity": prior_gravity(config, init), **(overrides or {})}
        steps = budget or PUSH_PRETRAIN_STEPS
    else:
        sets = {"simulator.gravity": (0.0, 0.0, free_flight_gravity(train)), **(overrides or {})}
        steps = budget or PRETRAIN_STEPS
    best = train_on_split(synth, valid_file, None, out / "run", steps, config=config,
                          overrides=sets, seed=seed, init=init)
    done = json.loads((out / "run" / "done.json").read_text())
    return {"source_trajectories": len(train), f"synthetic_{kind}": num, "prior": prior,
            "checkpoint": str(best), "fit": fit.get("params"), "fit_valid": fit.get("valid"),
            "limit_surface": ls or None, "steps": steps,
            "cpu_hours": (fit.get("cpu_seconds", 0.0) + gen_seconds) / 3600 + done["cpu_hours"]}


__all__ = ["FINETUNE_OVERRIDES", "FLOOR_CLEARANCE", "PRETRAIN_STEPS", "Sim2RealError", "default_train",
           "format_table", "parse_sizes", "plot_sizes", "pretrain_checkpoint", "prior_gravity", "push_space",
           "rests_on_floor", "run_sim2real", "summary_lines"]
