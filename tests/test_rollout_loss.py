"""Training through rollouts: the differentiable shape match, the differentiable step, the
rollout loss's weighting and the windows it is given."""
from pathlib import Path

import numpy as np
import pytest
import torch

from fignet_gym.data.format import build_scene, load_trajectories
from fignet_gym.simulator.geometry import axis_angle_to_quat, kabsch, polar_fit, quat_angle, transform_points
from fignet_gym.train.config import load_run_config
from fignet_gym.train.sampling import WindowSampler
from fignet_gym.train.trainer import Trainer

TINY = {"simulator.latent_size": 8, "simulator.message_passing_steps": 1,
        "training.batch_size": 2, "training.steps": 6, "training.valid_every": 100,
        "training.valid_trajectories": 1, "training.threads": 1}
CUBE = 0.05 * torch.tensor([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                           dtype=torch.float64)


def _random_pose(gen: torch.Generator) -> torch.Tensor:
    rotvec = torch.randn(3, generator=gen, dtype=torch.float64) * 2.0
    return torch.cat((torch.randn(3, generator=gen, dtype=torch.float64), axis_angle_to_quat(rotvec)))


def test_polar_fit_is_kabsch_with_gradients_for_symmetric_objects() -> None:
    gen = torch.Generator().manual_seed(0)
    # A cube (isotropic covariance: Kabsch's SVD has no gradient there), an elongated cloud
    # (condition number ~1e3) and a coplanar floor that only an inactive object may be.
    cloud = torch.randn(30, 3, generator=gen, dtype=torch.float64) * torch.tensor([0.3, 0.02, 0.003])
    floor = torch.tensor([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=torch.float64)
    ref = torch.cat((CUBE, cloud, floor))
    seg = torch.tensor([0] * 8 + [1] * 30 + [2] * 4)
    poses = torch.stack([_random_pose(gen) for _ in range(3)])
    noise = 1e-4 * torch.randn(ref.shape, generator=gen, dtype=torch.float64)
    target = transform_points(poses[seg], ref) + noise
    active = torch.tensor([True, True, False])
    fit = polar_fit(ref, target, seg, 3, active)
    exact, _ = kabsch(ref[:38], target[:38], seg[:38], 2)
    assert torch.allclose(fit[:2, :3], exact[:, :3], atol=1e-12)
    assert quat_angle(fit[:2, 3:], exact[:, 3:]).max() < 1e-9
    # The inactive floor comes out finite (identity rotation about its centroid).
    identity = torch.tensor([1.0, 0, 0, 0], dtype=torch.float64)
    assert torch.isfinite(fit).all() and torch.allclose(fit[2, 3:].abs(), identity)

    # An exactly rigid cube: every singular value equal, yet the fit differentiates correctly.
    exact_cube = transform_points(poses[0], CUBE).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda t: polar_fit(CUBE, t, seg[:8], 1), (exact_cube,))


def test_differentiable_step_is_the_step_with_gradients(push_file: Path, tmp_path: Path) -> None:
    trajs = load_trajectories(push_file)
    sim_cfg, cfg = load_run_config("push-cpu", TINY)
    sim = Trainer(sim_cfg, cfg, trajs[:2], trajs[2:], tmp_path / "run").sim
    with torch.no_grad():  # a random network that predicts visible motion
        for p in sim.net.parameters():
            p.normal_(0.0, 0.3)
    traj, scene = trajs[0], build_scene(trajs[0])
    poses = torch.as_tensor(traj.poses, dtype=torch.float32)
    H = sim.config.history + 1
    t = int(np.argmax(np.abs(np.diff(traj.poses[:, :, :3], axis=0)).max(axis=(1, 2)) > 1e-6)) + 5
    hist, kin = poses[t - H + 1:t + 1], poses[t + 1]
    expect = sim.step(scene, hist, kin)
    got = sim.differentiable_step(scene, hist, kin)
    assert torch.allclose(got[:, :3], expect[:, :3], atol=1e-6)
    assert quat_angle(got[:, 3:], expect[:, 3:]).max() < 1e-4
    assert (got[:, :3] - hist[-1, :, :3]).abs().max() > 1e-5  # the network did move something
    got[scene.dynamic_mask].square().sum().backward()
    # Through the whole network: the first encoder layer is reached too.
    for module in (sim.net.decoder, sim.net.enc_node):
        assert sum(float(p.grad.abs().sum()) for p in module.parameters()) > 0


def _rollout_trainer(push_file: Path, out: Path, steps: int, unroll_after: int = 0) -> Trainer:
    trajs = load_trajectories(push_file)
    sim_cfg, cfg = load_run_config("push-cpu", {**TINY, "training.rollout_steps": steps,
                                                "training.unroll_after": unroll_after,
                                                "training.noise_std": 0.0, "training.noise_fraction": 0.0})
    return Trainer(sim_cfg, cfg, trajs[:2], trajs[2:], out)


def test_rollout_loss_weighs_a_carried_velocity_error_alike_at_every_step(
        push_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    R = 4
    trainer = _rollout_trainer(push_file, tmp_path / "r", R)
    H = trainer.sim.config.history + 1
    scene, window = trainer.batch()
    assert window.shape[0] == H + R  # the one-step target, then R - 1 more rollout targets
    rest = window[:1].expand(H + R, -1, -1)  # everything at rest
    dyn = scene.dynamic_mask
    d = torch.tensor([3e-3, -4e-3, 0.0])  # a velocity error made at the first step and kept

    def drift(_scene: object, hist: torch.Tensor, kin: torch.Tensor) -> torch.Tensor:
        moved = hist[-1].clone()
        moved[:, :3] += d
        return torch.where(dyn[:, None], moved, kin)

    monkeypatch.setattr(trainer.sim, "differentiable_step", drift)
    # Step j (1-based) is off by j d in every node: (j d)^2 / j^2, the same at every step.
    sigma = float(trainer.sim.target_norm.std.mean())
    expect = float(d.square().mean()) / sigma**2
    assert float(trainer.rollout_loss(scene, rest, None)) == pytest.approx(expect, rel=1e-4)
    # A constant position offset (an error made once, then corrected) fades as 1 / j^2.
    offset = rest[0] + torch.cat((d, d.new_zeros(4)))
    monkeypatch.setattr(trainer.sim, "differentiable_step",
                        lambda s, hist, kin: torch.where(dyn[:, None], offset, kin))
    fade = sum(1 / j**2 for j in range(1, R + 1)) / R
    assert float(trainer.rollout_loss(scene, rest, None)) == pytest.approx(expect * fade, rel=1e-4)


def test_rollout_loss_joins_the_loss_after_unroll_after(push_file: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    trainer = _rollout_trainer(push_file, tmp_path / "w", 3, unroll_after=2)
    calls: list[int] = []
    original = trainer.rollout_loss
    monkeypatch.setattr(trainer, "rollout_loss",
                        lambda *a: calls.append(trainer.state.step) or original(*a))
    trainer.run(stop_after=4)
    assert calls == [2, 3]
    assert trainer.state.history == [] or all(np.isfinite(h["score"]) for h in trainer.state.history)
    assert all(torch.isfinite(p).all() for p in trainer.sim.parameters())


def test_rollout_windows_are_weighted_by_their_largest_target_acceleration(push_file: Path) -> None:
    traj = load_trajectories(push_file)[0]
    scene = build_scene(traj)
    R, history = 5, 2
    sampler = WindowSampler([traj], [scene], history=history, still_weight=0.1, seed=0,
                            unroll=R - 1, targets=R)
    span = sampler.span
    # Brute force: each pose's largest dynamic-node second difference.
    nodes = scene.node_positions(torch.as_tensor(traj.poses, dtype=torch.float32))
    nodes = nodes[:, scene.dynamic_mask[scene.node_object]].double()
    acc = (nodes[2:] - 2 * nodes[1:-1] + nodes[:-2]).norm(dim=-1).amax(-1).numpy()  # pose p: acc[p - 2]
    dyn = scene.dynamic_mask.numpy()
    moved = np.abs(np.diff(traj.poses[:, dyn, :3], axis=0)).max(axis=(1, 2)) > 1e-6
    starts = range(traj.poses.shape[0] - span + 1)
    moving = np.array([moved[t:t + span - 1].any() for t in starts])
    a = np.array([max(acc[p - 2] for p in range(t + span - R, t + span)) for t in starts])
    a_ref = np.median(a[moving])
    w = 1 + np.minimum(a / a_ref, 10.0)
    got = sampler.prob[moving] / sampler.prob[moving].sum()
    assert np.allclose(got, w[moving] / w[moving].sum(), rtol=1e-4)
    with pytest.raises(ValueError, match="targets must be in 1..5"):
        WindowSampler([traj], [scene], history=history, still_weight=0.1, seed=0, unroll=4, targets=6)
