"""Quaternion helpers and batched Kabsch against hand-computed rotations."""

import math

import pytest
import torch

from fignet_gym.simulator.geometry import (
    ShapeMatchError,
    axis_angle_to_quat,
    kabsch,
    matrix_to_quat,
    quat_angle,
    quat_mul,
    quat_rotate,
    quat_to_axis_angle,
    quat_to_matrix,
    rigid_projection,
    transform_points,
)


def random_quats(n: int) -> torch.Tensor:
    q = torch.randn(n, 4, dtype=torch.float64)
    return q / q.norm(dim=-1, keepdim=True)


def test_quat_rotate_matches_matrix_and_hand_case() -> None:
    q = random_quats(50)
    v = torch.randn(50, 3, dtype=torch.float64)
    assert torch.allclose(quat_rotate(q, v), (quat_to_matrix(q) @ v[:, :, None])[:, :, 0], atol=1e-12)
    # 90 degrees about z maps x to y.
    qz = torch.tensor([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)], dtype=torch.float64)
    assert torch.allclose(quat_rotate(qz, torch.tensor([1.0, 0, 0], dtype=torch.float64)),
                          torch.tensor([0.0, 1, 0], dtype=torch.float64), atol=1e-12)


def test_matrix_quat_roundtrip_including_180_degrees() -> None:
    q = random_quats(200)
    flips = torch.tensor([[0.0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=torch.float64)
    q = torch.cat((q, flips))
    back = matrix_to_quat(quat_to_matrix(q))
    assert torch.all(quat_angle(q, back) < 1e-6)


def test_axis_angle_roundtrip_and_composition() -> None:
    aa = torch.randn(100, 3, dtype=torch.float64)
    aa = aa / aa.norm(dim=-1, keepdim=True) * torch.rand(100, 1, dtype=torch.float64) * 3.0
    assert torch.allclose(quat_to_axis_angle(axis_angle_to_quat(aa)), aa, atol=1e-9)
    a, b = random_quats(20), random_quats(20)
    v = torch.randn(20, 3, dtype=torch.float64)
    assert torch.allclose(quat_rotate(quat_mul(a, b), v), quat_rotate(a, quat_rotate(b, v)), atol=1e-12)


def test_kabsch_recovers_known_rotation_and_translation() -> None:
    n_obj, per = 5, 12
    ref = torch.randn(n_obj * per, 3, dtype=torch.float64)
    seg = torch.arange(n_obj).repeat_interleave(per)
    pose = torch.cat((torch.randn(n_obj, 3, dtype=torch.float64), random_quats(n_obj)), -1)
    target = transform_points(pose[seg], ref)
    fit, residual = kabsch(ref, target, seg, n_obj)
    assert torch.allclose(fit[:, :3], pose[:, :3], atol=1e-9)
    assert torch.all(quat_angle(fit[:, 3:], pose[:, 3:]) < 1e-6)
    assert torch.all(residual < 1e-9)


def test_kabsch_never_returns_a_reflection() -> None:
    ref = torch.randn(10, 3, dtype=torch.float64)
    seg = torch.zeros(10, dtype=torch.long)
    mirrored = ref * torch.tensor([1.0, 1.0, -1.0], dtype=torch.float64)
    fit, residual = kabsch(ref, mirrored, seg, 1)
    rot = quat_to_matrix(fit[:, 3:])
    assert torch.allclose(torch.linalg.det(rot), torch.ones(1, dtype=torch.float64))
    assert residual.item() > 1e-3  # a proper rotation cannot fit a mirror image exactly


def test_kabsch_degenerate_raises() -> None:
    line = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(ShapeMatchError):
        kabsch(line, line + 1, torch.zeros(3, dtype=torch.long), 1)


def test_rigid_projection_of_a_point_force_hand_case() -> None:
    # Square of 4 nodes in the xy plane, unit push along y at corner (1, 1): translation F/4,
    # and with inertia sum |r|^2 I - r r^T = diag(4, 4, 8) the spin r x F / 8 = (0, 0, 1/8).
    pos = torch.tensor([[1.0, 1, 0], [-1, 1, 0], [-1, -1, 0], [1, -1, 0]], dtype=torch.float64) + 5.0
    force = torch.zeros(4, 3, dtype=torch.float64)
    force[0, 1] = 1.0
    out = rigid_projection(force, pos, torch.zeros(4, dtype=torch.long), 1)
    r = pos - 5.0
    expect = torch.tensor([0.0, 0.25, 0.0], dtype=torch.float64) + torch.cross(
        torch.tensor([0.0, 0.0, 0.125], dtype=torch.float64).expand(4, 3), r, dim=-1)
    assert torch.allclose(out, expect, atol=1e-9)


def test_rigid_projection_keeps_rigid_fields_and_removes_only_what_is_orthogonal() -> None:
    gen = torch.Generator().manual_seed(0)
    seg = torch.tensor([0] * 8 + [1] * 12 + [2] * 3)
    pos = torch.randn(23, 3, generator=gen, dtype=torch.float64) * 0.05
    lin, ang = (torch.randn(3, 3, generator=gen, dtype=torch.float64) for _ in range(2))
    rigid = lin[seg] + torch.cross(ang[seg], pos, dim=-1)
    assert torch.allclose(rigid_projection(rigid, pos, seg, 3), rigid, atol=1e-7)
    field = torch.randn(23, 3, generator=gen, dtype=torch.float64)
    proj = rigid_projection(field, pos, seg, 3)
    rest = field - proj
    # Orthogonal to every rigid field: no net force and no net torque left per object.
    for o in range(3):
        m = seg == o
        assert torch.allclose(rest[m].sum(0), torch.zeros(3, dtype=torch.float64), atol=1e-8)
        assert torch.allclose(torch.cross(pos[m], rest[m], dim=-1).sum(0),
                              torch.zeros(3, dtype=torch.float64), atol=1e-8)
    assert torch.allclose(rigid_projection(proj, pos, seg, 3), proj, atol=1e-7)


# ----------------------------------------------------------------- conventions, MuJoCo the oracle
def test_quat_mul_and_rotation_are_mujocos() -> None:
    import mujoco
    import numpy as np

    a, b = random_quats(40), random_quats(40)
    v = torch.randn(40, 3, dtype=torch.float64)
    mine_mul, mine_rot = quat_mul(a, b).numpy(), quat_rotate(a, v).numpy()
    for i in range(40):
        ref = np.empty(4)
        mujoco.mju_mulQuat(ref, a[i].numpy(), b[i].numpy())
        np.testing.assert_allclose(mine_mul[i], ref, atol=1e-12)
        rot = np.empty(3)
        mujoco.mju_rotVecQuat(rot, v[i].numpy(), a[i].numpy())
        np.testing.assert_allclose(mine_rot[i], rot, atol=1e-12)


def test_q_and_minus_q_are_the_same_rotation_everywhere() -> None:
    """The hemisphere: a 0.1 rad turn given as -q is still 0.1 rad (not -6.18), and the
    normalised quaternion is the same; MuJoCo's mju_quat2Vel agrees."""
    import mujoco
    import numpy as np

    from fignet_gym.simulator.geometry import quat_normalize

    aa = torch.tensor([[0.1, 0.0, 0.0], [0.0, -0.05, 0.08], [1.0, 2.0, -0.5]], dtype=torch.float64)
    q = axis_angle_to_quat(aa)
    for sign in (1.0, -1.0):
        torch.testing.assert_close(quat_to_axis_angle(sign * q), aa, atol=1e-12, rtol=0)
        torch.testing.assert_close(quat_normalize(sign * q), quat_normalize(q), atol=1e-12, rtol=0)
        for i in range(len(q)):
            ref = np.empty(3)
            mujoco.mju_quat2Vel(ref, (sign * q[i]).numpy(), 1.0)
            # MuJoCo keeps the long way round for -q; the shortest rotation is the same one
            if sign > 0:
                np.testing.assert_allclose(quat_to_axis_angle(q[i]).numpy(), ref, atol=1e-12)


def test_fignet_qvel_is_mujocos_differentiate_pos_from_tilted_starts() -> None:
    """The free joint's qvel that the learned dynamics writes is MuJoCo's own finite difference
    of its qpos (angular velocity in the body frame), for bodies that start tilted."""
    import mujoco
    import numpy as np
    from sim_factories import zero_simulator

    from fignet_gym.dynamics import FIGNetDynamics, compile_with_history
    from fignet_gym.mjcf import TossObject, toss_scene_xml

    objs = [TossObject("cube", 0.1), TossObject("cylinder", 0.1)]
    poses = np.array([[0, 0, 0.5, 1, 0, 0, 0], [0.6, 0, 0.5, 1, 0, 0, 0]], float)
    model = compile_with_history(toss_scene_xml(objs, floor_half_size=2.0, poses=poses))
    dyn = FIGNetDynamics(zero_simulator())
    rng = np.random.default_rng(0)
    data = mujoco.MjData(model)
    for j in range(2):
        q = rng.normal(size=4)
        data.qpos[7 * j + 3 : 7 * j + 7] = q / np.linalg.norm(q)  # tilted
        data.qvel[6 * j : 6 * j + 6] = rng.normal(size=6) * [0.3, 0.3, 0.3, 2, 2, 2]
    mujoco.mj_forward(model, data)
    for _ in range(3):
        before = data.qpos.copy()
        dyn.step(model, data, 10)
        ref = np.empty(model.nv)
        mujoco.mj_differentiatePos(model, ref, dyn.dt, before, data.qpos)
        np.testing.assert_allclose(data.qvel, ref, rtol=0, atol=2e-4)
