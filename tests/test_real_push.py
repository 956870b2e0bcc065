"""RealPush-v1 (and v0): Push-v1's task on the MuJoCo fitted to the real pushes (and push-real)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.envs.real_push import STEP_SECONDS, RealPushEnv, load_fitted_params
from fignet_gym.registration import PUSH_V1_KWARGS

ENV_ID = "fignet_gym/RealPush-v1"


def test_check_env_and_seeded_episodes() -> None:
    env = gym.make(ENV_ID)
    gym_check_env(env.unwrapped, skip_render_check=True)
    runs = []
    for seed in (3, 3, 4):
        obs0, _ = env.reset(seed=seed)
        obs1, reward, *_ , info = env.step(np.array([0.5, -0.2]))
        assert reward == pytest.approx(sum(v for k, v in info.items() if k.startswith("reward_")))
        runs.append(np.concatenate([obs0, obs1]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])
    env.close()


def test_mujoco_backend_carries_the_fitted_parameters_as_the_replays_do() -> None:
    """The env's model has exactly what ``ContactParams.apply`` (the sim2real replays) sets on
    the same scene; a step is 0.02 s; the task is Push-v1's."""
    import copy

    from fignet_gym.train.analytic import ContactParams

    fit = load_fitted_params()
    env = RealPushEnv()
    ref = copy.copy(RealPushEnv(dynamics="mujoco", mujoco_params={}).model)
    ContactParams.from_json(fit).apply(ref, STEP_SECONDS)
    for field in ("geom_friction", "geom_solref"):
        np.testing.assert_array_equal(getattr(env.model, field), getattr(ref, field))
    for field in ("cone", "impratio", "timestep"):
        assert getattr(env.model.opt, field) == getattr(ref.opt, field)
    assert env.frame_skip == fit["substeps"] and env.dt == pytest.approx(STEP_SECONDS)
    assert env.task.dt == pytest.approx(STEP_SECONDS)
    assert env.task.success_yaw == pytest.approx(PUSH_V1_KWARGS["success_yaw"])


def test_refuses_unknown_shapes_and_parameters_the_fit_sets() -> None:
    with pytest.raises(ValueError, match="shape"):
        RealPushEnv(shape="tri3")
    with pytest.raises(ValueError, match="friction"):
        RealPushEnv(friction=0.3)
    with pytest.raises(ValueError, match="unknown keys"):
        RealPushEnv(mujoco_params={"gravity": -9.8})


def test_push_real_ships_with_its_fit_and_drives_the_env() -> None:
    from fignet_gym import load_pretrained
    from fignet_gym.pretrained import pretrained_dir, pretrained_path

    sim = load_pretrained("push-real")
    assert sim.config.scene_type == "push" and sim.config.dt == pytest.approx(STEP_SECONDS)
    assert pretrained_path("push-real").stat().st_size < 10e6
    card = (pretrained_dir() / "push-real.md").read_text()
    assert 'load_pretrained("push-real")' in card and "CPU hours" in card
    env = RealPushEnv(dynamics="fignet")  # push-real by default
    env.reset(seed=0)
    obs, *_ = env.step(np.array([1.0, 0.0]))
    assert np.isfinite(obs).all()


def test_evaluate_scores_the_shipped_push_fit_on_a_users_file(tmp_path) -> None:
    """``evaluate --against mujoco:push-real`` replays a user's real pushes in the shipped fit:
    the replay's model carries the fit's tip friction and substeps, and its scores are the
    shipped parameters' (a different tip friction scores otherwise)."""
    import json
    from dataclasses import replace
    from pathlib import Path

    from sim_factories import zero_simulator

    from fignet_gym.cli import main
    from fignet_gym.data.format import load_trajectories
    from fignet_gym.dynamics.contact_params import ContactParams
    from fignet_gym.pretrained import pretrained_dir
    from fignet_gym.simulator.checkpoint import save
    from fignet_gym.train.analytic import Replay, replay_all
    from fignet_gym.train.evaluation import evaluate
    from fignet_gym.train.metrics import predictor_metrics

    data, zero = tmp_path / "abs.h5", tmp_path / "zero.pt"
    sample = Path(__file__).parent / "data" / "mit_sample"
    assert main(["import-mit", str(sample), "--out", str(data), "--dt", str(STEP_SECONDS)]) == 0
    save(zero_simulator("push", dt=STEP_SECONDS), zero)
    res = evaluate(str(zero), str(data), str(tmp_path / "e"), horizon=25, videos=0,
                   against="mujoco:push-real")
    shipped = json.loads((pretrained_dir() / "push-real.mujoco.json").read_text())
    assert res["against"]["params"] == shipped
    trajs = load_trajectories(data)
    model = Replay(trajs[0]).model(ContactParams.from_json(shipped))
    tip = np.array([model.body_mocapid[b] >= 0 for b in model.geom_bodyid])
    assert tip.any() and (~tip).any()
    np.testing.assert_allclose(model.geom_friction[tip, 0], shipped["friction_kinematic"])
    np.testing.assert_allclose(model.geom_friction[~tip, 0], shipped["friction"])
    assert model.opt.timestep == pytest.approx(STEP_SECONDS / shipped["substeps"])
    ag = res["against"]
    for tip_friction, same in ((shipped["friction_kinematic"], True), (1.0, False)):
        params = replace(ContactParams.from_json(shipped), friction_kinematic=tip_friction)
        m = predictor_metrics(trajs, replay_all(trajs, params), 3, 25)
        assert (m["rotation_deg_final"] == pytest.approx(ag["rotation_deg_final"])) == same


def test_evaluate_against_the_shipped_limit_surface_scores_its_replays(tmp_path, capsys) -> None:
    """``--against limit-surface:push-real`` replays the user's pushes in the shipped
    limit-surface fit: the reference errors are those of ``LimitSurfaceDynamics`` with the
    shipped numbers through the same replay path (another tip friction scores otherwise), the
    label says what it is, and the per-push view averages each push's windows first."""
    import json
    from pathlib import Path

    from sim_factories import zero_simulator

    from fignet_gym.cli import main
    from fignet_gym.data.format import load_trajectories
    from fignet_gym.data.split import trajectory_groups
    from fignet_gym.dynamics.limit_surface import LimitSurfaceDynamics
    from fignet_gym.pretrained import pretrained_dir
    from fignet_gym.simulator.checkpoint import save
    from fignet_gym.train.analytic import replay_all
    from fignet_gym.train.evaluation import evaluate
    from fignet_gym.train.metrics import predictor_metrics
    from fignet_gym.train.real_baselines import LS_STEP

    data, zero = tmp_path / "abs.h5", tmp_path / "zero.pt"
    sample = Path(__file__).parent / "data" / "mit_sample"
    assert main(["import-mit", str(sample), "--out", str(data), "--dt", str(STEP_SECONDS)]) == 0
    save(zero_simulator("push", dt=STEP_SECONDS), zero)
    res = evaluate(str(zero), str(data), str(tmp_path / "e"), horizon=25, videos=0,
                   against="limit-surface:push-real")
    shipped = json.loads((pretrained_dir() / "push-real.limit_surface.json").read_text())
    ag = res["against"]
    assert ag["params"] == {k: shipped[k] for k in ("tip_friction", "pressure_scale")}
    trajs = load_trajectories(data)
    for mu, same in ((shipped["tip_friction"], True), (1.0, False)):
        dyn = LimitSurfaceDynamics(mu, shipped["pressure_scale"])
        m = predictor_metrics(trajs, replay_all(trajs, LS_STEP, dyn), 3, 25)
        assert (m["rotation_deg_final"] == pytest.approx(ag["rotation_deg_final"])) == same
    assert "quasi-static limit surface, tip friction 0.2" in capsys.readouterr().out
    groups = trajectory_groups(trajs)
    assert len(set(groups)) < len(groups)  # a long push gives several windows
    pr = res["per_recording"]
    assert pr["recordings_last"] == len(set(groups))
    per = {}
    for g, e in zip(groups, res["translation_rmse_last_per_trajectory"], strict=True):
        per.setdefault(g, []).append(e)
    assert pr["translation_rmse_last"] == pytest.approx(np.median([np.mean(v) for v in per.values()]))
    # Bad specs: one line each, before any rollout.
    for spec, msg in (("limit-surface:nope", "neither a shipped limit-surface fit"),):
        assert main(["evaluate", "--checkpoint", str(zero), "--data", str(data), "--out",
                     str(tmp_path / "bad"), "--against", spec]) == 2
        err = capsys.readouterr().err
        assert msg in err and "limit-surface:push-real" in err and len(err.strip().splitlines()) == 1


def test_each_version_steps_its_own_learned_model() -> None:
    """RealPush-v0 keeps the first push-real (``push-real-v0``), v1 steps the re-shipped one; the
    fitted MuJoCo is the same in both."""
    import torch

    from fignet_gym import load_pretrained

    env0 = gym.make("fignet_gym/RealPush-v0", dynamics="fignet").unwrapped
    env1 = gym.make("fignet_gym/RealPush-v1", dynamics="fignet").unwrapped
    for env, name in ((env0, "push-real-v0"), (env1, "push-real")):
        mine = env.dynamics.simulator.state_dict()
        ref = load_pretrained(name).state_dict()
        assert all(torch.equal(mine[k], ref[k]) for k in ref)
    np.testing.assert_array_equal(env0.model.geom_friction, env1.model.geom_friction)
