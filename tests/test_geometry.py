"""Quaternion helpers and batched Kabsch against hand-computed rotations."""

import math

import pytest
import torch

from fignet_gym.geometry import (
    ShapeMatchError,
    axis_angle_to_quat,
    kabsch,
    matrix_to_quat,
    quat_angle,
    quat_mul,
    quat_rotate,
    quat_to_axis_angle,
    quat_to_matrix,
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
