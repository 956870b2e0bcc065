"""The physics contract of training and stepping: the noise correction in the training target,
the rotation augmentation, and equivariance of a learned step under rotation about the vertical.

Rotations come from scipy (an independent implementation), never from the code under test.
"""

from dataclasses import replace

import mujoco
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from fignet_gym import load_pretrained
from fignet_gym.data.format import build_scene
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.simulator.model import LearnedSimulator, SimulatorConfig, TrainingNoise
from fignet_gym.simulator.scene import Scene
from fignet_gym.train.sampling import rotate_about_z

SMALL = SimulatorConfig(latent_size=16, message_passing_steps=2, collision_radius=0.03)


def turned(poses: torch.Tensor, rot: Rotation) -> torch.Tensor:
    """Poses ``float[..., O, 7]`` (position, wxyz quaternion) of the whole scene turned by ``rot``
    about the world origin."""
    p = poses.double().numpy().reshape(-1, 7)
    quat = (rot * Rotation.from_quat(p[:, 3:], scalar_first=True)).as_quat(scalar_first=True)
    out = np.concatenate((rot.apply(p[:, :3]), quat), -1).reshape(poses.shape)
    return torch.as_tensor(out, dtype=poses.dtype)


def matrix(rot: Rotation) -> torch.Tensor:
    return torch.as_tensor(rot.as_matrix(), dtype=torch.float32)


def tumbling_box(xml: str) -> tuple[Scene, torch.Tensor]:
    """The push-like scene with the box translating and turning about a tilted axis, the tip
    approaching: poses ``float[4, O, 7]`` (three history frames, then the true next one)."""
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(xml))
    start = Rotation.from_quat([0.95, 0.2, -0.15, 0.1], scalar_first=True)
    frames = []
    for k in range(4):
        p = scene.static_poses.clone()
        q = (Rotation.from_rotvec(np.array([0.3, -0.2, 0.9]) * 0.05 * k) * start).as_quat(scalar_first=True)
        p[1, 3:] = torch.as_tensor(q, dtype=torch.float32)
        p[1, :3] += torch.tensor([0.003 * k, -0.001 * k, 0.03 + 0.0015 * k * k])
        p[2, 0] = 0.07 - 0.005 * k
        frames.append(p)
    return scene, torch.stack(frames)


def node_acceleration(scene: Scene, poses: torch.Tensor) -> torch.Tensor:
    """Finite-difference acceleration ``float[N_dyn, 3]`` of dynamic nodes over three poses."""
    x = scene.node_positions(poses)
    return (x[2] - 2 * x[1] + x[0])[scene.dynamic_mask[scene.node_object]]


def test_noisy_training_target_undoes_the_velocity_noise(push_like_xml: str) -> None:
    # learning_to_simulate's rule: with noise n on the input positions, the target is the
    # acceleration that takes the noisy state to the true next position plus the last frame's
    # noise (which no model can see): the clean target minus the velocity noise n_t - n_{t-1}.
    scene, poses = tumbling_box(push_like_xml)
    sim, noise = LearnedSimulator(SMALL), TrainingNoise(std=2e-3)
    clean = sim.training_example(scene, poses)
    noisy = sim.training_example(scene, poses, torch.Generator().manual_seed(5), noise=noise)
    drawn = sim.pose_noise(scene, poses[:-1], torch.Generator().manual_seed(5), noise)  # the same draw
    x = scene.node_positions(drawn)
    n = x - scene.node_positions(poses[:-1])  # node noise float[H, N, 3]
    dyn = scene.dynamic_mask[scene.node_object]
    assert (n[-1] - n[-2])[dyn].norm(dim=-1).mean() > 2e-4  # the velocity noise is not negligible
    assert torch.allclose(noisy.target[dyn], (clean.target - (n[-1] - n[-2]))[dyn], atol=1e-6)
    # The same, as the integrator sees it: x_t + (x_t - x_{t-1}) + a lands on x_{t+1} + n_t.
    landed = 2 * x[-1] - x[-2] + noisy.target
    assert torch.allclose(landed[dyn], (scene.node_positions(poses[-1]) + n[-1])[dyn], atol=1e-6)
    assert torch.equal(noisy.weight, clean.weight) and torch.equal(noisy.weight, dyn.float())


def test_rotation_augmentation_turns_orientations_with_positions(push_like_xml: str) -> None:
    scene, poses = tumbling_box(push_like_xml)
    for angle in (0.7, 2.5, -1.9):
        rot = Rotation.from_euler("z", angle)
        out = rotate_about_z(poses, angle)
        # Every node of every object lands where the turned scene puts it (positions alone would
        # pass with orientations left alone or turned the wrong way only for a point-like scene).
        assert torch.allclose(scene.node_positions(out), scene.node_positions(poses) @ matrix(rot).T,
                              atol=1e-6)
        assert torch.allclose(scene.com_positions(out), scene.com_positions(poses) @ matrix(rot).T,
                              atol=1e-6)
        assert torch.allclose(out[..., 3:].norm(dim=-1), torch.ones(out.shape[:-1]), atol=1e-6)


def test_free_step_is_exactly_equivariant_about_the_vertical_only(push_like_xml: str) -> None:
    # A network that outputs zero acceleration leaves the integrator, the gravity prior and shape
    # matching: exactly equivariant about the vertical axis (the axis of gravity), not about another.
    sim = LearnedSimulator(replace(SMALL, gravity=(0.0, 0.0, -9.81))).eval()
    with torch.no_grad():
        sim.net.decoder.rest[-1].weight.zero_()
        sim.net.decoder.rest[-1].bias.zero_()
    scene, poses = tumbling_box(push_like_xml)
    poses[:, 1, 2] += 0.5  # in the air: no contact (contacts also change nothing here)
    dyn = scene.dynamic_mask

    def step_turned(rot: Rotation) -> torch.Tensor:
        return sim.step(scene, turned(poses[:3], rot), turned(poses[3], rot))

    out = sim.step(scene, poses[:3], poses[3])
    for rot in (Rotation.from_euler("z", 1.2), Rotation.from_euler("z", -2.6)):
        assert torch.allclose(step_turned(rot)[dyn], turned(out, rot)[dyn], atol=2e-6)
    tilt = Rotation.from_euler("x", 1.2)
    assert not torch.allclose(step_turned(tilt)[dyn], turned(out, tilt)[dyn], atol=1e-4)


@pytest.fixture(scope="module")
def push_model_on_mujoco_push() -> tuple[LearnedSimulator, Scene, torch.Tensor]:
    """The shipped push model, its scene and a MuJoCo push ``float[T, O, 7]``."""
    sim = load_pretrained("push")
    traj = next(iter(iter_trajectories("push", 1, seed=11)))
    scene = build_scene(traj, sim.config.mesh_options)
    return sim, scene, torch.as_tensor(traj.poses, dtype=torch.float32)


def moved(poses: torch.Tensor, rot: Rotation, shift: tuple[float, float]) -> torch.Tensor:
    """:func:`turned` poses shifted horizontally by ``shift`` (m)."""
    out = turned(poses, rot)
    out[..., :2] += torch.tensor(shift, dtype=poses.dtype)
    return out


def equivariance_error(sim: LearnedSimulator, scene: Scene, hist: torch.Tensor,
                       nxt: torch.Tensor) -> tuple[float, float]:
    """Largest position (m) and orientation (rad) difference, over dynamic objects and 8 turns
    with shifts, between the step of a moved scene and the moved step."""
    dyn = scene.dynamic_mask
    out = sim.step(scene, hist, nxt)
    pos = ang = 0.0
    for k in range(8):
        rot, shift = Rotation.from_euler("z", 0.4 + 0.8 * k), (0.3 * np.cos(k), -0.2 * k)
        got = sim.step(scene, moved(hist, rot, shift), moved(nxt, rot, shift))[dyn].double()
        want = moved(out, rot, shift)[dyn].double()
        pos = max(pos, float((got[:, :3] - want[:, :3]).abs().max()))
        rel = (Rotation.from_quat(got[:, 3:].numpy(), scalar_first=True).inv()
               * Rotation.from_quat(want[:, 3:].numpy(), scalar_first=True))
        ang = max(ang, float(rel.magnitude().max()))
    return pos, ang


def test_shipped_push_step_is_exactly_equivariant_about_the_vertical(push_model_on_mujoco_push) -> None:
    # The canonical frame makes the shipped model equivariant by construction: a turned and
    # shifted scene steps to the turned and shifted step, to float32 rounding, on every step of a
    # MuJoCo push; the same weights without the frame (equivariance learned from augmentation
    # only) are off by far more, and turning orientations the wrong way breaks it.
    sim, scene, poses = push_model_on_mujoco_push
    assert sim.config.canonical_frame
    com = scene.com_positions(poses)[:, scene.dynamic_mask]
    moving = ((com[1:] - com[:-1]).norm(dim=-1).amax(-1) > 1e-4).nonzero().squeeze(1)
    steps = [int(t) for t in moving[::4] if 2 <= int(t) < len(poses) - 1][:4]
    assert len(steps) >= 3  # the pusher moves the object
    learned_only = LearnedSimulator(replace(sim.config, canonical_frame=False)).eval()
    learned_only.load_state_dict(sim.state_dict())
    worst = learned = 0.0
    for t in steps:
        hist, nxt = poses[t - 2:t + 1], poses[t + 1]
        worst = max(worst, *equivariance_error(sim, scene, hist, nxt))
        learned = max(learned, equivariance_error(learned_only, scene, hist, nxt)[0])
    assert worst < 1e-5, worst
    assert learned > 10 * max(worst, 1e-6), (learned, worst)
    rot = Rotation.from_euler("z", 1.1)
    t = steps[0]
    wrong_way = turned(poses[t - 2:t + 2], rot)
    wrong_way[..., 3:] = turned(poses[t - 2:t + 2], rot.inv())[..., 3:]
    good = turned(sim.step(scene, poses[t - 2:t + 1], poses[t + 1]), rot)
    bad = sim.step(scene, wrong_way[:3], wrong_way[3])
    assert float((bad - good)[scene.dynamic_mask, :3].abs().max()) > 10 * max(worst, 1e-6)


def toss_history(xml_objects: int = 3, seed: int = 0) -> tuple[Scene, torch.Tensor]:
    """A toss scene (floor, ``xml_objects`` tilted objects: one resting on a corner, the others
    in flight, turning) and poses ``float[4, O, 7]``: three history frames and the next."""
    from fignet_gym.mjcf import TossObject, toss_scene_xml

    objs = [TossObject(s, 0.7, "metal") for s in ("cube", "cylinder", "sphere")][:xml_objects]
    scene = Scene.from_mjmodel(mujoco.MjModel.from_xml_string(toss_scene_xml(objs)),
                               SimulatorConfig().mesh_options)
    rng = np.random.default_rng(seed)
    start = Rotation.random(len(objs), random_state=seed)
    base = rng.uniform(-2, 2, (len(objs), 3)) + np.array([0, 0, 1.5])
    base[0, 2] = 0.62  # the cube's lowest corner near the floor: contacts
    spin = rng.normal(size=(len(objs), 3)) * 0.1
    frames = []
    for k in range(4):
        p = scene.static_poses.clone()
        rot = Rotation.from_rotvec(spin * k) * start
        p[1:, 3:] = torch.as_tensor(rot.as_quat(scalar_first=True), dtype=torch.float32)
        p[1:, :3] = torch.as_tensor(base + 0.02 * k * np.array([1.0, -0.5, -0.2]), dtype=torch.float32)
        frames.append(p)
    return scene, torch.stack(frames)


@pytest.mark.parametrize("batched", [False, True])
def test_canonical_frame_makes_any_model_equivariant(batched: bool) -> None:
    # Untrained weights: the symmetry comes from the frame, not from learning. Several objects,
    # tilted, in flight and touching the floor, one scene or two different ones in a batch.
    cfg = replace(SMALL, collision_radius=0.1, gravity=(0.0, 0.0, -10.0), rigid_output=True,
                  feature_clip=3.0)
    sim = LearnedSimulator(replace(cfg, canonical_frame=True)).eval()
    scene, poses = toss_history()
    if batched:
        other = toss_history(seed=1)[1]
        scene, poses = scene.repeat(2), torch.cat((poses, other), dim=1)
    pos, ang = equivariance_error(sim, scene, poses[:3], poses[3])
    assert pos < 1e-5 and ang < 1e-5, (pos, ang)
    plain = LearnedSimulator(cfg).eval()
    plain.load_state_dict(sim.state_dict())
    assert equivariance_error(plain, scene, poses[:3], poses[3])[0] > 1e-4  # the test can fail
