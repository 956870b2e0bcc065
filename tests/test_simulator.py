"""The learned simulator: features, invariances, batching, integration, checkpoints, learning."""

import math
from dataclasses import replace

import mujoco
import numpy as np
import pytest
import torch

from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator.checkpoint import CHECKPOINT_FORMAT, CheckpointError, CheckpointWarning, save
from fignet_gym.simulator.checkpoint import load as load_checkpoint_file
from fignet_gym.simulator.collision import FaceContacts
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.geometry import rigid_projection
from fignet_gym.simulator.graph import FACE_GROUPS, face_edge_features
from fignet_gym.simulator.model import LearnedSimulator, TrainingNoise, integrate, inverse_integrate
from fignet_gym.simulator.scene import Scene

SMALL = SimulatorConfig(latent_size=16, message_passing_steps=2, collision_radius=0.03)


def scene_and_history(xml: str, lift: float = 0.0) -> tuple[Scene, torch.Tensor]:
    model = mujoco.MjModel.from_xml_string(xml)
    scene = Scene.from_mjmodel(model)
    p = scene.static_poses.clone()
    # A generic orientation: parallel touching faces have non-unique closest points, whose choice
    # may flip with rounding; the invariance tests need well-defined contacts.
    q = torch.tensor([0.95, 0.2, -0.15, 0.1])
    p[1, 3:] = q / q.norm()
    p[1, 2] += 0.03 + lift
    # Three frames with some motion so velocity features are non-zero.
    hist = p[None].repeat(3, 1, 1)
    hist[0, 1, 0] -= 0.004
    hist[1, 1, 0] -= 0.002
    hist[:, 2, 0] = torch.tensor([0.07, 0.065, 0.06])  # tip approaching the box
    return scene, hist


def randomize_normalizers(sim: LearnedSimulator, xml: str) -> None:
    """Give the normalisers the statistics of real features so tests exercise them."""
    scene, hist = scene_and_history(xml)
    for lift in (0.0, 0.01, 0.02):
        moved = hist.clone()
        moved[:, 1, 2] += lift
        sim.normalize(sim.build_inputs(scene, moved, moved[-1]).graph, accumulate=True)
    sim.target_norm.accumulate(torch.randn(64, 3) * 1e-3)


def test_hand_computed_face_features() -> None:
    # Sender triangle A in z = 0, receiver B above it touching at one vertex's projection.
    pos = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0],
                        [0.2, 0.3, 0.1], [1, 0.3, 1.0], [0.2, 1.1, 0.9]], dtype=torch.float64)
    faces = torch.tensor([[0, 1, 2], [3, 4, 5]])
    ps, pr = torch.tensor([[0.2, 0.3, 0.0]], dtype=torch.float64), pos[3:4]
    c = FaceContacts(torch.tensor([0]), torch.tensor([1]), ps, pr, torch.tensor([0.1]))
    s_nodes, r_nodes, f = face_edge_features(pos, faces, c, torch.zeros_like(pos))
    # Nodes sorted by distance to each face's closest point: A: 0 (0.36), 2 (0.73), 1 (0.85).
    assert s_nodes.tolist() == [[0, 2, 1]] and r_nodes.tolist() == [[3, 5, 4]]
    n_r = torch.tensor([-0.72, -0.64, 0.64], dtype=torch.float64) / math.sqrt(1.3376)
    expected = torch.cat([
        torch.tensor([0, 0, 0.1, 0.1]),
        torch.tensor([-0.2, -0.3, 0, math.hypot(0.2, 0.3)]),
        torch.tensor([-0.2, 0.7, 0, math.hypot(0.2, 0.7)]),
        torch.tensor([0.8, -0.3, 0, math.hypot(0.8, 0.3)]),
        torch.tensor([0, 0, 0, 0.0]),
        torch.tensor([0, 0.8, 0.8, math.hypot(0.8, 0.8)]),
        torch.tensor([0.8, 0, 0.9, math.hypot(0.8, 0.9)]),
        torch.tensor([0, 0, 1.0]), n_r.float(),
    ]).double()
    assert torch.allclose(f[0], expected, atol=1e-6)
    # The sender (a kinematic pusher face) will rise by 0.04 and the receiver is 0.1 above it:
    # the next-step separation is 0.06 (the receiver's nodes' displacements do not count).
    kin_disp = torch.zeros_like(pos)
    kin_disp[:3, 2] = 0.04
    kin_disp[3:, 0] = 0.5
    _, _, f_next = face_edge_features(pos, faces, c, kin_disp, face_groups=FACE_GROUPS)
    assert torch.allclose(f_next[0, :34], f[0]) and f_next.shape[1] == 38
    assert torch.allclose(f_next[0, 34:], torch.tensor([0, 0, 0.06, 0.06], dtype=torch.float64))


def test_translation_equivariance(push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    scene, hist = scene_and_history(push_like_xml)
    shift = torch.tensor([0.3, -0.2, 0.1])
    out = sim.step(scene, hist, hist[-1])
    moved = hist.clone()
    moved[..., :3] += shift
    out_moved = sim.step(scene, moved, moved[-1])
    assert torch.allclose(out_moved[:, :3], out[:, :3] + shift, atol=2e-5)
    assert torch.allclose(out_moved[:, 3:], out[:, 3:], atol=2e-5)
    assert not torch.allclose(out[1], hist[-1, 1], atol=1e-6)  # the model does predict motion


def test_invariance_to_face_vertex_order(push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    scene, hist = scene_and_history(push_like_xml)
    # Cyclic rotations keep each face's winding (and so its outward normal).
    shift = torch.randint(0, 3, (scene.faces.shape[0],))
    idx = (torch.arange(3)[None, :] + shift[:, None]) % 3
    rotated = Scene(**{**{k: v for k, v in scene.__dict__.items() if k != "_cache"},
                       "faces": torch.gather(scene.faces, 1, idx)})
    out = sim.step(scene, hist, hist[-1])
    out_rot = sim.step(rotated, hist, hist[-1])
    assert torch.allclose(out, out_rot, atol=1e-6)


def test_batched_equals_separate(push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    s1, h1 = scene_and_history(push_like_xml)
    s2, h2 = scene_and_history(push_like_xml.replace('size="0.05 0.04 0.05"', 'size="0.03 0.06 0.05"'))
    h2[..., 1] += 0.01
    batch = Scene.batch([s1, s2])
    out = sim.step(batch, torch.cat((h1, h2), 1), torch.cat((h1[-1], h2[-1]), 0))
    sep = torch.cat((sim.step(s1, h1, h1[-1]), sim.step(s2, h2, h2[-1])))
    assert torch.allclose(out, sep, atol=1e-5)


def test_zero_decoder_keeps_a_resting_scene_still(push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    with torch.no_grad():
        last = sim.net.decoder.rest[-1]
        last.weight.zero_()
        last.bias.zero_()
    sim.target_norm.total.zero_()  # zero mean: decoder output 0 means zero acceleration
    scene, _ = scene_and_history(push_like_xml)
    p = scene.static_poses.clone()
    p[1, 2] += 0.5  # in the air, far from any contact
    hist = p[None].repeat(3, 1, 1)
    traj = sim.rollout(scene, hist, p[None].repeat(20, 1, 1))
    assert torch.allclose(traj, p[None].expand_as(traj), atol=1e-6)


def test_gravity_prior_gives_exact_discrete_free_fall(push_like_xml: str) -> None:
    sim = LearnedSimulator(replace(SMALL, gravity=(0.0, 0.0, -9.81))).eval()
    with torch.no_grad():
        sim.net.decoder.rest[-1].weight.zero_()
        sim.net.decoder.rest[-1].bias.zero_()
    scene, _ = scene_and_history(push_like_xml)
    p = scene.static_poses.clone()
    p[1, 2] += 2.0  # far above the floor: no contact
    traj = sim.rollout(scene, p[None].repeat(3, 1, 1), p[None].repeat(10, 1, 1))
    k = torch.arange(1, 11, dtype=torch.float32)
    # x_{t+1} = 2 x_t - x_{t-1} + g dt^2 from rest: displacement g dt^2 k (k + 1) / 2.
    expected = p[1, 2] - 9.81 * sim.config.dt**2 * k * (k + 1) / 2
    assert torch.allclose(traj[:, 1, 2], expected, atol=1e-5)
    assert torch.allclose(traj[:, 0], p[0].expand(10, 7))  # the floor does not fall


def test_checkpoint_roundtrip_and_bad_files(tmp_path, push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    path = tmp_path / "m.pt"
    save(sim, path, meta={"note": "test"})
    loaded, meta = load_checkpoint_file(path)
    assert meta == {"note": "test"} and loaded.config == sim.config
    scene, hist = scene_and_history(push_like_xml)
    assert torch.equal(sim.step(scene, hist, hist[-1]), loaded.step(scene, hist, hist[-1]))

    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(path.read_bytes()[:200])
    with pytest.raises(CheckpointError, match="corrupt.pt"):
        load_pretrained(corrupt)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match="not a fignet_gym checkpoint"):
        load_pretrained(foreign)
    # A pickle that would run code is refused by weights_only loading.
    evil = tmp_path / "evil.pt"
    torch.save({"format": "x", "obj": np.random.default_rng(0)}, evil)
    with pytest.raises(CheckpointError):
        load_pretrained(evil)
    mismatched = tmp_path / "mismatch.pt"
    blob = torch.load(path, weights_only=True)
    blob["config"]["latent_size"] = 32
    del blob["checksum"]  # an unsealed file: the shape check (not the checksum) must refuse it
    torch.save(blob, mismatched)
    with pytest.warns(CheckpointWarning, match="no content checksum"), \
            pytest.raises(CheckpointError, match="do not match"):
        load_pretrained(mismatched)


def mujoco_trajectory(xml: str, steps: int, substeps: int) -> tuple[Scene, torch.Tensor]:
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    scene = Scene.from_mjmodel(model)
    data.qvel[:3] = [0.4, 0.1, 0.0]
    data.qvel[3:6] = [0.0, 0.0, 3.0]
    mujoco.mj_forward(model, data)
    poses = []
    for _ in range(steps):
        poses.append(scene.poses_from_data(data))
        mujoco.mj_step(model, data, substeps)
    return scene, torch.tensor(np.stack(poses), dtype=torch.float32)


def test_overfits_one_short_mujoco_trajectory(push_like_xml: str) -> None:
    scene, traj = mujoco_trajectory(push_like_xml, steps=24, substeps=10)
    sim = LearnedSimulator(SimulatorConfig(latent_size=32, message_passing_steps=2,
                                           collision_radius=0.03))
    windows = traj.unfold(0, 4, 1).permute(0, 3, 1, 2)  # [K, H+1, O, 7]
    k = windows.shape[0]
    batch = scene.repeat(k)
    poses = windows.permute(1, 0, 2, 3).reshape(4, k * scene.num_objects, 7)
    example = sim.training_example(batch, poses)
    opt = torch.optim.Adam(sim.parameters(), lr=3e-3)
    losses = []
    for _ in range(250):
        opt.zero_grad()
        loss = sim.loss(example, accumulate=len(losses) < 5)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 1e-2 * losses[5]


def test_clip_length_hand_case() -> None:
    from fignet_gym.simulator.graph import clip_length

    d = torch.tensor([[3.0, 4.0, 0.0], [0.3, 0.4, 0.0], [0.0, 0.0, 0.0]])
    out = clip_length(d, 1.0)
    assert torch.allclose(out, torch.tensor([[0.6, 0.8, 0.0], [0.3, 0.4, 0.0], [0.0, 0.0, 0.0]]))
    assert torch.equal(clip_length(d, 0.0), d)


def test_last_block_has_no_dead_weights_and_extra_weights_are_refused(tmp_path, push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    randomize_normalizers(sim, push_like_xml)
    last = len(sim.net.blocks) - 1
    assert not hasattr(sim.net.blocks[last], "mesh_obj") and hasattr(sim.net.blocks[0], "mesh_obj")
    # Every weight now gets a gradient: none is dead.
    scene, hist = scene_and_history(push_like_xml)
    sim.net(sim.normalize(sim.build_inputs(scene, hist, hist[-1]).graph)).sum().backward()
    assert all(p.grad is not None for p in sim.net.parameters())
    # Unexpected weights mean a mismatched file.
    path = tmp_path / "extra.pt"
    save(sim, path)
    blob = torch.load(path, weights_only=True)
    del blob["checksum"]  # an unsealed file: the shape check (not the checksum) must refuse it
    blob["state_dict"]["net.extra.weight"] = torch.zeros(2)
    torch.save(blob, path)
    with pytest.warns(CheckpointWarning, match="no content checksum"), \
            pytest.raises(CheckpointError, match="do not match"):
        load_pretrained(path)


def test_warm_start_onto_new_face_features_keeps_the_function(push_like_xml: str) -> None:
    from fignet_gym.train.warmstart import warm_start

    source = LearnedSimulator(SMALL).eval()
    randomize_normalizers(source, push_like_xml)
    wide = LearnedSimulator(replace(SMALL, **{grp.name: True for grp in FACE_GROUPS})).eval()
    warm_start(wide, source)
    scene, hist = scene_and_history(push_like_xml)
    nxt = hist[-1].clone()
    nxt[2, 0] -= 0.01  # the tip moves on: the new features are non-zero
    g = wide.build_inputs(scene, hist, nxt).graph
    assert g.face_edges.features.shape[1] == 34 + sum(grp.size for grp in FACE_GROUPS)
    assert g.face_edges.features[:, 34:].abs().sum() > 0
    assert torch.allclose(wide.step(scene, hist, nxt), source.step(scene, hist, nxt), atol=1e-6)
    with pytest.raises(ValueError, match="cannot warm-start"):
        warm_start(LearnedSimulator(replace(SMALL, latent_size=8)), source)
    with pytest.raises(ValueError, match="cannot warm-start"):  # features cannot be dropped
        warm_start(source, wide)


def test_rigid_training_noise_has_the_configured_scales(push_like_xml: str) -> None:
    from fignet_gym.simulator.geometry import quat_conj, quat_mul, quat_to_axis_angle

    scene, hist = scene_and_history(push_like_xml)
    gen = torch.Generator().manual_seed(0)
    for rot_std, expect_rot in ((0.0, None), (0.01, 0.01)):
        sim, noise = LearnedSimulator(SMALL), TrainingNoise(std=1e-3, rotation_std=rot_std)
        draws = torch.stack([sim.pose_noise(scene, hist, gen, noise) for _ in range(1500)])  # [S, H, O, 7]
        dyn = scene.dynamic_mask
        assert torch.equal(draws[:, :, ~dyn], hist[None, :, ~dyn].expand_as(draws[:, :, ~dyn]))
        assert torch.allclose(draws[:, 0], hist[0].expand_as(draws[:, 0]), atol=1e-6)  # walk starts at 0
        last = draws[:, -1, dyn]
        com_shift = scene.com_positions(draws[:, -1])[:, dyn] - scene.com_positions(hist[-1])[dyn]
        assert com_shift.pow(2).mean().sqrt().item() == pytest.approx(1e-3, rel=0.06)
        rotvec = quat_to_axis_angle(quat_mul(last[..., 3:], quat_conj(hist[-1, dyn, 3:])))
        rot_rms = rotvec.pow(2).mean().sqrt().item()
        if expect_rot is None:  # default: nodes at the RMS radius move by the noise std
            expect_rot = 1e-3 / sim._object_radius(scene)[dyn].item()
        assert rot_rms == pytest.approx(expect_rot, rel=0.06)


def test_rigid_output_predicts_rigid_motion_in_steps_and_in_the_loss(push_like_xml: str) -> None:
    sim = LearnedSimulator(replace(SMALL, rigid_output=True)).eval()
    randomize_normalizers(sim, push_like_xml)
    plain = LearnedSimulator(SMALL).eval()
    plain.load_state_dict(sim.state_dict())
    scene, hist = scene_and_history(push_like_xml)
    graph = sim.build_inputs(scene, hist, hist[-1]).graph
    seg, n_obj = scene.node_object, scene.num_objects

    def is_rigid(acc: torch.Tensor) -> bool:  # (rigid_projection is checked by hand in test_geometry)
        acc = acc.double()
        return torch.allclose(rigid_projection(acc, graph.node_pos.double(), seg, n_obj), acc,
                              atol=1e-6 * float(acc.abs().max()))

    with torch.no_grad():
        assert is_rigid(sim.predict_acceleration(graph))
        assert not is_rigid(plain.predict_acceleration(graph))  # so the check above can fail
        # Training sees the same projected prediction as stepping.
        example = sim.training_example(scene, torch.cat((hist, hist[-1:])))
        assert is_rigid(sim.target_norm.inverse(sim.training_prediction(example.graph)))


def test_training_settings_are_not_model_config_and_format_1_files_are_refused(tmp_path,
                                                                             push_like_xml: str) -> None:
    sim = LearnedSimulator(SMALL).eval()
    path = tmp_path / "m.pt"
    save(sim, path)
    blob = torch.load(path, weights_only=True)
    assert blob["format"] == CHECKPOINT_FORMAT
    assert not {"noise_std", "rotation_noise_std", "vertical_weight"} & set(blob["config"])
    with pytest.raises(ValueError, match="unknown config keys"):
        SimulatorConfig.from_dict({**SMALL.to_dict(), "noise_std": 1e-3})
    # A file of the first format (training settings in its config) is refused, saying why.
    old = tmp_path / "old.pt"
    torch.save({**blob, "format": "fignet_gym.checkpoint/1"}, old)
    with pytest.raises(CheckpointError, match="old.pt: checkpoint format 'fignet_gym.checkpoint/1'"):
        load_pretrained(old)


def test_integrate_and_inverse_integrate_are_an_exact_pair() -> None:
    gen = torch.Generator().manual_seed(0)
    x_prev, x_t, x_next, acc = (torch.randn(50, 3, generator=gen, dtype=torch.float64) for _ in range(4))
    # Independent truth: constant velocity needs no acceleration; from rest, a lands at x + a.
    assert torch.allclose(integrate(x_t, x_prev, torch.zeros_like(x_t)), x_t + (x_t - x_prev), atol=1e-12)
    assert inverse_integrate(x_t + (x_t - x_prev), x_t, x_prev).abs().max() < 1e-12
    assert torch.allclose(integrate(x_t, x_t, acc), x_t + acc, atol=1e-12)
    # Round trips, both ways.
    assert torch.allclose(integrate(x_t, x_prev, inverse_integrate(x_next, x_t, x_prev)), x_next,
                          atol=1e-12)
    assert torch.allclose(inverse_integrate(integrate(x_t, x_prev, acc), x_t, x_prev), acc, atol=1e-12)


def test_face_groups_are_config_flags_and_set_the_feature_width(push_like_xml: str) -> None:
    from dataclasses import fields

    from fignet_gym.simulator.graph import FACE_BASE, feature_sizes

    flags = {f.name: f.type for f in fields(SimulatorConfig)}
    scene, hist = scene_and_history(push_like_xml)
    for grp in FACE_GROUPS:
        assert flags[grp.name] in (bool, "bool")
        cfg = replace(SMALL, **{grp.name: True})
        assert cfg.face_groups == (grp,) and SMALL.face_groups == ()
        width = LearnedSimulator(cfg).build_inputs(scene, hist, hist[-1]).graph.face_edges.features.shape[1]
        assert width == FACE_BASE + grp.size == feature_sizes(2, face_groups=(grp,))["face"]


def test_node_collision_baseline_uses_node_edges_only(push_like_xml: str) -> None:
    sim = LearnedSimulator(replace(SMALL, collision="node", collision_radius=0.04)).eval()
    randomize_normalizers(sim, push_like_xml)
    scene, hist = scene_and_history(push_like_xml)
    g = sim.build_inputs(scene, hist, hist[-1]).graph
    s, r = g.node_edges.senders, g.node_edges.receivers
    assert g.face_edges.features.shape == (0, 34) and s.numel() > 0
    assert (scene.node_object[s] != scene.node_object[r]).all()
    d = g.node_pos[s] - g.node_pos[r]
    assert (d.norm(dim=-1) < 0.04).all()
    assert torch.allclose(g.node_edges.features, torch.cat((d, d.norm(dim=-1, keepdim=True)), -1))
    out = sim.step(scene, hist, hist[-1])
    assert torch.isfinite(out).all() and not torch.allclose(out[1], hist[-1, 1], atol=1e-6)
