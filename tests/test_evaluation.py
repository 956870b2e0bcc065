"""Evaluation metrics against reference models whose errors are known by construction."""

import math

import pytest
import torch

from fignet_gym.data.format import build_scene
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.evaluation import one_step_errors, rollout_metrics
from fignet_gym.scene import Scene
from tests.sim_factories import zero_simulator


@pytest.fixture(scope="module")
def pushes() -> list:
    return list(iter_trajectories("push", 2, seed=11))


def test_zero_network_scores_as_constant_velocity(pushes: list) -> None:
    # A network that outputs zero (no gravity prior) extrapolates every node linearly: its one-step
    # errors are the constant-velocity model's up to the rotation's linearisation.
    sim = zero_simulator("push")
    scene = Scene.batch([build_scene(t, sim.config.mesh_options) for t in pushes])
    true = torch.cat([torch.as_tensor(t.poses[:30], dtype=torch.float32) for t in pushes], 1)
    m = one_step_errors(sim, scene, true)
    assert m["one_step_constvel_translation"] > 0.01  # the pushes start and stop: real errors
    assert m["one_step_translation"] == pytest.approx(m["one_step_constvel_translation"], rel=1e-3)
    assert m["one_step_rotation"] == pytest.approx(m["one_step_constvel_rotation"], rel=2e-2)


def test_rollout_metrics_of_a_model_that_never_moves_is_the_no_motion_reference(pushes: list) -> None:
    sim = zero_simulator("push")
    # Pushes start at rest, so a zero network keeps the object where it is: the no-motion model.
    m = rollout_metrics(sim, pushes, horizon=25)
    assert m["still_translation_rmse_final"] > 1e-3
    assert m["translation_rmse_ratio_still"] == pytest.approx(1.0, abs=1e-4)
    # Shape matching in float32 leaves ~1e-3 deg of jitter.
    assert m["rotation_deg_final"] == pytest.approx(m["still_rotation_deg_final"], abs=0.01)
    assert math.isfinite(m["penetration_m"])
