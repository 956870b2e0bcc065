"""A scene's learned step does not depend on the scenes batched with it (bit for bit).

The learned dynamics is discontinuous where a face pair crosses the collision radius, so a
difference of one float32 ulp grows to centimetres within a toss: batched and single results must
agree exactly, not to a tolerance. Truth here is the unbatched computation itself.
"""

from __future__ import annotations

import contextlib

import gymnasium as gym
import mujoco
import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import fignet_gym.envs  # noqa: F401  (registers the environments)
from fignet_gym.dynamics import STATE_SPEC, FIGNetDynamics, compile_with_history
from fignet_gym.dynamics import learned as learned_dynamics
from fignet_gym.mjcf import push_scene_xml
from fignet_gym.pretrained import load_pretrained
from fignet_gym.simulator import networks
from fignet_gym.simulator.model import LOW_PRECISION_MIN_NODES
from fignet_gym.simulator.scene import Scene


@pytest.fixture(scope="module")
def push_sim():  # noqa: ANN201
    return load_pretrained("push").eval()


def _push_history(scene: Scene, lift: float) -> torch.Tensor:
    """``float[3, O, 7]``: the prism at rest on the floor with the tip against it, lifted by
    ``lift`` m (and the tip with it: no contact at all when lifted)."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pose = torch.tensor(scene.poses_from_data(data), dtype=torch.float32)
    moving = ~(scene.object_kind == 0)
    pose[moving, 2] += lift
    return pose[None].repeat(3, 1, 1)


def test_scene_in_a_mixed_batch_equals_the_scene_alone(push_sim) -> None:  # noqa: ANN001
    """A scene with more face edges than nodes batched with one without any contact: each takes
    its own first-layer route (node projections vs gathered latents), and the object MLPs of one
    push scene (3 rows) are as narrow as the BLAS small-matrix kernels."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    touching, flying = _push_history(scene, 0.0), _push_history(scene, 0.5)
    contacts, _ = push_sim.collide(scene, scene.node_positions(touching[-1]))
    assert contacts.num_contacts > scene.num_nodes  # the node-projection route
    contacts, _ = push_sim.collide(scene, scene.node_positions(flying[-1]))
    assert contacts.num_contacts == 0
    alone = [push_sim.step(scene, h, h[-1]) for h in (touching, flying)]
    for order in ((0, 1), (1, 0), (0, 1, 1, 0)):
        hist = torch.cat([(touching, flying)[i] for i in order], dim=1)
        out = push_sim.step(scene.repeat(len(order)), hist, hist[-1]).view(len(order), -1, 7)
        for k, i in enumerate(order):
            assert torch.equal(out[k], alone[i]), (order, k)


def test_large_batches_and_chunks_equal_the_scene_alone(push_sim, monkeypatch) -> None:  # noqa: ANN001
    """160 push scenes (4800 nodes) cross oneDNN's fused-linear threshold; stepped in chunks of
    3 to 4 scenes (a tiny ``CHUNK_NODES``) they give the same bits as in one product."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    states = (_push_history(scene, 0.0), _push_history(scene, 0.5))
    count = 160
    assert count * scene.num_nodes >= networks.FUSED_MIN_ROWS
    hist = torch.cat([states[i % 2] for i in range(count)], dim=1)
    big = push_sim.step(scene.repeat(count), hist, hist[-1]).view(count, -1, 7)
    for i in range(2):
        alone = push_sim.step(scene, states[i], states[i][-1])
        assert all(torch.equal(big[k], alone) for k in range(i, count, 2))
    monkeypatch.setattr(learned_dynamics, "CHUNK_NODES", 100)
    chunked = learned_dynamics.batched_step(push_sim, scene, count, hist, hist[-1])
    assert torch.equal(chunked.view(count, -1, 7), big)


def test_narrow_products_round_as_inside_a_larger_one_on_this_cpu() -> None:
    """The assumption behind MIN_ROWS, checked on the machine the suite runs on: any number of
    rows, padded by ``networks.linear``, gets the bits those rows get inside a large product, for
    the layer widths the network uses (edge first layers reach 9 latents plus features)."""
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for k in (3, 16, 64, 192, 320, 576, 640):
            for out in (3, 64, 192):
                w, b = torch.randn(out, k, generator=gen), torch.randn(out, generator=gen)
                x = torch.randn(3 * networks.MIN_ROWS, k, generator=gen)
                inside = torch.nn.functional.linear(torch.cat((x, x, x)), w, b)
                for m in range(1, x.shape[0] + 1):
                    assert torch.equal(networks.linear(x[:m], w, b), inside[:m]), (k, out, m)


@pytest.mark.skipif(not networks._ONEDNN, reason="no oneDNN in this torch build")
def test_fused_linear_rounds_like_plain_linear() -> None:
    """The assumption behind FUSED_MAX_IN: on this build oneDNN's fused linear (+ReLU) gives
    exactly F.linear's bits for the layer widths it is used on, whatever the rows."""
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for k in (8, 16, 64, 128, networks.FUSED_MAX_IN):
            for out in (64, 128, 192):
                w, b = torch.randn(out, k, generator=gen), torch.randn(out, generator=gen)
                x = torch.randn(networks.FUSED_MIN_ROWS + 37, k, generator=gen)
                x[::3] = 0.0  # resting scenes have exact zeros in their features
                plain = torch.nn.functional.linear(x, w, b)
                assert torch.equal(networks.linear(x, w, b), plain), (k, out)
                assert torch.equal(networks.linear(x, w, b, relu=True), plain.relu()), (k, out)


def test_dynamics_step_many_and_rollout_equal_single_scenes(push_sim) -> None:  # noqa: ANN001
    """The env-facing Dynamics: ``step_many`` on three MjData and a batched ``rollout`` equal
    stepping and rolling out each alone, bit for bit, over 20 steps of contact (one of them
    losing its stored history half-way)."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.07, 0.0)))
    dyn_batch, dyn_single = FIGNetDynamics(push_sim), FIGNetDynamics(push_sim)
    batch = [mujoco.MjData(model) for _ in range(3)]
    singles = [mujoco.MjData(model) for _ in range(3)]
    for i, d in enumerate(batch + singles):
        d.mocap_pos[0, 1] = 0.01 * (i % 3)
        mujoco.mj_forward(model, d)
    nstate = mujoco.mj_stateSize(model, STATE_SPEC)
    init = np.stack([np.empty(nstate) for _ in batch])
    for i, d in enumerate(batch):
        mujoco.mj_getState(model, d, init[i], STATE_SPEC)
    control = np.zeros((3, 20, 7))
    for t in range(20):
        for i in range(3):
            for d in (batch[i], singles[i]):
                d.mocap_pos[0, 0] += 0.002 * (i + 1)
            control[i, t, :3], control[i, t, 3:] = batch[i].mocap_pos[0], (1, 0, 0, 0)
        if t == 10:  # a batch mixing stored histories with one reseeded from qpos/qvel
            dyn_batch.forget(batch[1])
            dyn_single.forget(singles[1])
        dyn_batch.step_many(model, batch, 10)
        for d in singles:
            dyn_single.step(model, d, 10)
    moved = [float(np.abs(d.qpos[:3] - init[i, 1:4]).max()) for i, d in enumerate(batch)]
    assert max(moved) > 0.005  # the tips pushed the prisms
    for b, s in zip(batch, singles, strict=True):
        np.testing.assert_array_equal(b.qpos, s.qpos)
        np.testing.assert_array_equal(b.qvel, s.qvel)
    together = dyn_batch.rollout(model, init, control, frame_skip=10)
    for i in range(3):
        alone = dyn_single.rollout(model, init[i:i + 1], control[i:i + 1], frame_skip=10)
        np.testing.assert_array_equal(together[i], alone[0])


@pytest.mark.parametrize(("env_id", "steps"), [("fignet_gym/Toss-v0", 2), ("fignet_gym/Push-v1", 20)])
def test_vector_env_with_shipped_model_reproduces_single_envs(env_id: str, steps: int) -> None:
    """Issue 16's case: sub-environment 1 of a Toss vector env was 8 cm off its same-seed single
    env after one toss, Push 0.009 after 20 steps; now they are identical."""
    n = 3
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", dynamics="fignet")
    singles = [gym.make(env_id, dynamics="fignet") for _ in range(n)]
    obs, _ = venv.reset(seed=7)
    ref = [e.reset(seed=7 + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(ref))
    rng = np.random.default_rng(0)
    for _ in range(steps):
        act = rng.uniform(-1, 1, (n, *venv.single_action_space.shape)).astype(np.float32)
        obs, *_ = venv.step(act)
        ref = [e.step(act[i])[0] for i, e in enumerate(singles)]
        np.testing.assert_array_equal(obs, np.stack(ref))
    venv.close()


class _HostGuard(TorchDispatchMode):
    """Fails on any op that copies a tensor across devices and counts scalar host syncs
    (``bool``/``int`` of a tensor), while :func:`_no_host_transfers` also blocks ``.cpu()``,
    ``.numpy()`` and ``.tolist()``: on a CUDA machine these are the transfers that stall a
    rollout; on this CPU-only one the guard sees the same calls."""

    syncs = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # noqa: ANN001, ANN204
        kwargs = kwargs or {}
        if func is torch.ops.aten._local_scalar_dense.default:
            _HostGuard.syncs += 1
        out = func(*args, **kwargs)
        if func in (torch.ops.aten._to_copy.default, torch.ops.aten.copy_.default):
            src = args[1] if func is torch.ops.aten.copy_.default else args[0]
            dst = out if isinstance(out, torch.Tensor) else args[0]
            assert src.device == dst.device, f"{func}: {src.device} -> {dst.device}"
        return out


@contextlib.contextmanager
def _no_host_transfers(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN202
    def refuse(name: str):  # noqa: ANN202
        def f(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
            raise AssertionError(f"Tensor.{name}() inside a rollout step")
        return f

    with monkeypatch.context() as m:
        for name in ("cpu", "numpy", "tolist", "item"):
            m.setattr(torch.Tensor, name, refuse(name))
        with _HostGuard():
            yield


def test_rollout_steps_move_no_tensor_to_the_host(push_sim, monkeypatch) -> None:  # noqa: ANN001
    """The GPU path (CUDA is not available here to run it): a learned rollout step, in the
    simulator and inside ``FIGNetDynamics.rollout``, moves no tensor to the host; only a few
    scalar syncs for control flow remain, and their number does not grow with the batch."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    hist = _push_history(scene, 0.0)
    syncs = {}
    for b in (1, 8):
        h = hist.repeat(1, b, 1)
        kin = h[-1][None].repeat(5, 1, 1)
        _HostGuard.syncs = 0
        with _no_host_transfers(monkeypatch):
            push_sim.rollout(scene.repeat(b), h, kin)
        syncs[b] = _HostGuard.syncs
    # 5 per step, + 1 per scene for the canonical frame's cached static info: experiments/README.md,
    # Issue 17, "GPU path"
    assert syncs[1] == syncs[8] <= 5 * 5 + 1, syncs

    dyn = FIGNetDynamics(push_sim)
    advance = dyn._advance

    def guarded(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        with _no_host_transfers(monkeypatch):
            return advance(*args, **kwargs)

    monkeypatch.setattr(dyn, "_advance", guarded)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    init = np.empty((2, mujoco.mj_stateSize(model, STATE_SPEC)))
    for i in range(2):
        mujoco.mj_getState(model, data, init[i], STATE_SPEC)
    control = np.tile(np.r_[data.mocap_pos[0] + [0.01, 0, 0], 1, 0, 0, 0], (2, 5, 1))
    assert np.isfinite(dyn.rollout(model, init, control, frame_skip=10)).all()


@pytest.mark.parametrize("batch", [1, 2])
def test_analytic_flops_match_torch_flop_counter(push_sim, batch: int) -> None:  # noqa: ANN001
    """``network_flops`` (the bench's analytic count, block by block) equals what torch's own
    FLOP counter sees the network execute, on a mixed batch that takes both first-layer routes."""
    from torch.utils.flop_counter import FlopCounterMode

    from fignet_gym.tools.bench_limits import network_flops

    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    states = (_push_history(scene, 0.0), _push_history(scene, 0.5))
    hist = torch.cat(states[:batch], dim=1)
    flops, _ = network_flops(push_sim, scene.repeat(batch), hist)
    graph = push_sim.build_inputs(scene.repeat(batch), hist, hist[-1]).graph
    counter = FlopCounterMode(display=False)
    with counter, torch.no_grad():
        push_sim.net(push_sim.normalize(graph))
    assert sum(flops.values()) == counter.get_total_flops()


def test_bfloat16_mode_runs_a_mixed_batch(push_sim) -> None:  # noqa: ANN001
    """The opt-in bf16 mode through both first-layer routes in one batch: finite, and within the
    per-step error bf16 costs (a few percent of the float32 displacement). Graphs below
    ``LOW_PRECISION_MIN_NODES`` run in float32, bit for bit."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    copies = -(-LOW_PRECISION_MIN_NODES // (2 * scene.num_nodes))  # just enough for bf16
    for count in (copies, 1):
        hist = torch.cat((_push_history(scene, 0.0).repeat(1, count, 1),
                          _push_history(scene, 0.5).repeat(1, count, 1)), dim=1)
        batch = scene.repeat(2 * count)
        ref = push_sim.step(batch, hist, hist[-1])
        push_sim.inference_dtype = torch.bfloat16
        try:
            out = push_sim.step(batch, hist, hist[-1])
        finally:
            push_sim.inference_dtype = torch.float32
        assert torch.isfinite(out).all()
        moved = (ref[:, :3] - hist[-1][:, :3]).norm(dim=-1).max()
        gap = (out[:, :3] - ref[:, :3]).norm(dim=-1).max()
        if count > 1:
            assert 0 < gap <= 0.1 * moved + 1e-6
        else:
            assert gap == 0


def test_in_place_residuals_change_nothing_and_keep_gradients(push_sim) -> None:  # noqa: ANN001
    """Inference writes each block's residual sums into the dead latents: the network's output
    must equal the autograd path's (new tensors) bit for bit, its input graph must be untouched,
    and training (grad enabled) must still backpropagate through every block."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    hist = torch.cat((_push_history(scene, 0.0), _push_history(scene, 0.5)), dim=1)
    graph = push_sim.normalize(push_sim.build_inputs(scene.repeat(2), hist, hist[-1]).graph)
    before = graph.node_features.clone()
    with torch.no_grad():
        fast = push_sim.net(graph)
    assert torch.equal(graph.node_features, before)
    with torch.enable_grad():
        slow = push_sim.net(graph)
        slow.square().sum().backward()
    assert torch.equal(fast, slow.detach())
    first = push_sim.net.blocks[0].mesh_node.first.weight
    assert first.grad is not None and bool(first.grad.abs().sum() > 0)
    push_sim.zero_grad(set_to_none=True)


def test_bfloat16_copy_follows_parameter_updates(push_sim) -> None:  # noqa: ANN001
    """The bf16 mode runs a bfloat16 copy of the network; an in-place update (an optimiser
    step) must reach the next step, which must then match float32 with the updated weights."""
    model = compile_with_history(push_scene_xml("rect1", tip_xy=(-0.055, 0.0)))
    scene = Scene.from_mjmodel(model, push_sim.config.mesh_options)
    copies = -(-LOW_PRECISION_MIN_NODES // scene.num_nodes)
    hist = _push_history(scene, 0.5).repeat(1, copies, 1)
    graph = push_sim.build_inputs(scene.repeat(copies), hist, hist[-1]).graph
    weight = push_sim.net.decoder.rest[-1].weight

    def accel(dtype: torch.dtype) -> torch.Tensor:
        push_sim.inference_dtype = dtype
        try:
            return push_sim.predict_acceleration(graph)
        finally:
            push_sim.inference_dtype = torch.float32

    def close(a: torch.Tensor, b: torch.Tensor) -> bool:
        return bool((a - b).norm() <= 0.05 * b.norm())

    before = accel(torch.bfloat16)
    assert close(before, accel(torch.float32))
    with torch.no_grad():
        weight.mul_(-1.0)
    try:
        after = accel(torch.bfloat16)
        assert close(after, accel(torch.float32))
        assert not close(after, before)
    finally:
        with torch.no_grad():
            weight.mul_(-1.0)
    assert close(accel(torch.bfloat16), before)
    assert push_sim.net.decoder.rest[-1].weight.dtype == torch.float32  # the model itself is untouched
