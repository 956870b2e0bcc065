"""Quaternions, rigid transforms and batched shape matching (Kabsch), in torch.

Quaternions are (w, x, y, z), MuJoCo's convention. Poses are ``float[..., 7]``: position then
quaternion. See ``docs/architecture.md`` for the dimension glossary.
"""

from __future__ import annotations

import torch
from torch import Tensor


class ShapeMatchError(RuntimeError):
    """A rigid fit was requested on a degenerate point set (fewer than 3 non-collinear points)."""


def quat_normalize(q: Tensor) -> Tensor:
    """Unit quaternion with non-negative w. ``float[..., 4] -> float[..., 4]``."""
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return torch.where(q[..., :1] < 0, -q, q)


def quat_mul(a: Tensor, b: Tensor) -> Tensor:
    """Hamilton product ``a * b``. ``float[..., 4] x float[..., 4] -> float[..., 4]``."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


def quat_conj(q: Tensor) -> Tensor:
    """Conjugate (inverse of a unit quaternion). ``float[..., 4] -> float[..., 4]``."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q: Tensor) -> Tensor:
    """Rotation matrix of a unit quaternion. ``float[..., 4] -> float[..., 3, 3]``."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        (
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ),
        dim=-1,
    ).reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(m: Tensor) -> Tensor:
    """Unit quaternion (w >= 0) of a rotation matrix. ``float[..., 3, 3] -> float[..., 4]``.

    Uses the four-candidate method (pick the best-conditioned diagonal term) so that it is
    accurate for every rotation, including 180 degrees.
    """
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    cand = torch.stack(
        (
            torch.stack((1 + m00 + m11 + m22, m[..., 2, 1] - m[..., 1, 2],
                         m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]), -1),
            torch.stack((m[..., 2, 1] - m[..., 1, 2], 1 + m00 - m11 - m22,
                         m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]), -1),
            torch.stack((m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0],
                         1 - m00 + m11 - m22, m[..., 1, 2] + m[..., 2, 1]), -1),
            torch.stack((m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0],
                         m[..., 1, 2] + m[..., 2, 1], 1 - m00 - m11 + m22), -1),
        ),
        dim=-2,
    )  # [..., 4 candidates, 4]
    diag = torch.stack((1 + m00 + m11 + m22, 1 + m00 - m11 - m22,
                        1 - m00 + m11 - m22, 1 - m00 - m11 + m22), -1)
    best = diag.argmax(-1, keepdim=True)
    q = torch.gather(cand, -2, best[..., None].expand(*best.shape, 4)).squeeze(-2)
    return quat_normalize(q)


def quat_rotate(q: Tensor, v: Tensor) -> Tensor:
    """Rotate vectors by unit quaternions. ``float[..., 4] x float[..., 3] -> float[..., 3]``."""
    qv, v = torch.broadcast_tensors(q[..., 1:], v)
    t = 2.0 * torch.cross(qv, v, dim=-1)
    return v + q[..., :1] * t + torch.cross(qv, t, dim=-1)


def transform_points(pose: Tensor, points: Tensor) -> Tensor:
    """World positions of body-frame points. ``float[..., 7] x float[..., 3] -> float[..., 3]``."""
    return pose[..., :3] + quat_rotate(pose[..., 3:], points)


def quat_angle(a: Tensor, b: Tensor) -> Tensor:
    """Geodesic angle (radians, in [0, pi]) between rotations. ``float[..., 4] x2 -> float[...]``.

    ``2 atan2(|vec(conj(a) b)|, |w(conj(a) b)|)``, not ``2 acos(|<a, b>|)``: in float32 the arccos
    form cannot resolve angles below ~1e-3 rad, which one step of a slowly pushed object is.
    """
    rel = quat_mul(quat_conj(a), b)
    return 2.0 * torch.atan2(rel[..., 1:].norm(dim=-1), rel[..., 0].abs())


def axis_angle_to_quat(axis_angle: Tensor) -> Tensor:
    """Quaternion of a rotation vector (axis times angle). ``float[..., 3] -> float[..., 4]``."""
    angle = axis_angle.norm(dim=-1, keepdim=True)
    half = 0.5 * angle
    # sin(x/2)/x -> 1/2 as x -> 0; the series avoids 0/0.
    scale = torch.where(angle > 1e-6, torch.sin(half) / angle.clamp_min(1e-12), 0.5 - angle**2 / 48)
    return torch.cat((torch.cos(half), axis_angle * scale), dim=-1)


def quat_to_axis_angle(q: Tensor) -> Tensor:
    """Rotation vector of a unit quaternion (shortest rotation). ``float[..., 4] -> float[..., 3]``."""
    q = quat_normalize(q)
    sin_half = q[..., 1:].norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(sin_half, q[..., :1])
    scale = torch.where(sin_half > 1e-7, angle / sin_half.clamp_min(1e-12), 2.0 / q[..., :1])
    return q[..., 1:] * scale


def segment_sum(values: Tensor, segment: Tensor, num_segments: int) -> Tensor:
    """Sum rows by segment: ``float[N, ...]``, ``int64[N]`` in ``[0, num_segments)`` -> ``float[S, ...]``."""
    out = values.new_zeros(num_segments, *values.shape[1:])
    return out.index_add_(0, segment, values)


def rigid_moments(field: Tensor, pos: Tensor, segment: Tensor, num_segments: int
                  ) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Per-object linear and angular moments of a node vector field ``float[N, 3]`` at node
    positions ``pos float[N, 3]``.

    Returns ``(count float[O], r float[N, 3], mean float[O, 3], torque float[O, 3])``: node
    counts (at least 1), each node's offset from its object's node centroid, the field's mean
    per object and ``sum_i r_i x field_i`` per object.
    """
    count = segment_sum(torch.ones_like(pos[:, 0]), segment, num_segments).clamp_min(1)
    r = pos - (segment_sum(pos, segment, num_segments) / count[:, None])[segment]
    mean = segment_sum(field, segment, num_segments) / count[:, None]
    torque = segment_sum(torch.cross(r, field, dim=-1), segment, num_segments)
    return count, r, mean, torque


def rigid_projection(field: Tensor, pos: Tensor, segment: Tensor, num_segments: int) -> Tensor:
    """Least-squares projection of a per-node vector field onto each object's rigid fields.

    Every object's part of ``field`` is replaced by the closest field of the form
    ``A + alpha x (pos - centroid)`` (one linear and one angular term per object): for node
    accelerations, the linearised motion that shape matching keeps of them. A point force at
    one node thus becomes a translation plus the torque about the centroid it exerts.

    Args:
        field: ``float[N, 3]`` e.g. node accelerations.
        pos: ``float[N, 3]`` node positions (world frame).
        segment: ``int64[N]`` object of each node, in ``[0, num_segments)``.
        num_segments: ``O``.

    Returns:
        ``float[N, 3]``, orthogonal projection (idempotent; rigid fields are kept as they are).
    """
    _, r, lin, torque = rigid_moments(field, pos, segment, num_segments)
    # Geometric inertia sum |r|^2 I - r r^T per object, solved in float64: objects are cm-sized,
    # so its entries are ~1e-4 and float32 would lose the small angular terms.
    rr = r.double()
    outer = rr[:, :, None] * rr[:, None, :]
    eye = torch.eye(3, dtype=torch.float64, device=pos.device)
    inertia = segment_sum((rr * rr).sum(-1)[:, None, None] * eye - outer, segment, num_segments)
    # A tiny ridge keeps single-node and collinear objects (no rotation defined about the line) finite.
    ridge = 1e-9 * inertia.diagonal(dim1=-2, dim2=-1).sum(-1).clamp_min(1e-30)
    alpha = torch.linalg.solve(inertia + ridge[:, None, None] * eye, torque.double()[:, :, None])
    alpha = alpha[:, :, 0].to(field.dtype)
    return lin[segment] + torch.cross(alpha[segment], r, dim=-1)


def _fit_moments(reference: Tensor, target: Tensor, segment: Tensor, num_segments: int,
                 weights: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Weights ``float[N]``, their sums ``float[O]``, centroids of reference and target
    ``float[O, 3]`` and the cross-covariance ``sum w p q^T`` ``float[O, 3, 3]`` of a rigid fit."""
    w = torch.ones(reference.shape[0], device=reference.device, dtype=reference.dtype) \
        if weights is None else weights
    wsum = segment_sum(w, segment, num_segments)
    if bool((wsum <= 0).any()):
        raise ShapeMatchError("kabsch: an object has no points to fit")
    c_ref = segment_sum(reference * w[:, None], segment, num_segments) / wsum[:, None]
    c_tgt = segment_sum(target * w[:, None], segment, num_segments) / wsum[:, None]
    p = reference - c_ref[segment]
    q = target - c_tgt[segment]
    cov = segment_sum(w[:, None, None] * p[:, :, None] * q[:, None, :], segment, num_segments)
    return w, wsum, c_ref, c_tgt, cov


def polar_fit(reference: Tensor, target: Tensor, segment: Tensor, num_segments: int,
              active: Tensor | None = None, iterations: int = 12) -> Tensor:
    """The rigid fit of :func:`kabsch` (poses ``float[O, 7]``) in a form that autograd can
    differentiate for every object, used to train through rollouts.

    Kabsch's SVD has no gradient when singular values coincide, which they do for symmetric
    objects (a cube's covariance is isotropic). The rotation is the orthogonal polar factor of
    the covariance, computed by scaled Newton iterations ``X <- (g X + X^-T / g) / 2``, which are
    smooth wherever the covariance is invertible. Reflections are not corrected (a rollout's
    predicted points are never mirror images of the reference).

    Args:
        reference, target: ``float[N, 3]`` body-frame points and their predicted world positions.
        segment: ``int64[N]`` object of each point; num_segments: ``O``.
        active: ``bool[O]`` objects to fit (default all); the others (a floor whose points are
            coplanar, so that its covariance is singular) get the identity rotation.
        iterations: Newton steps; 12 reach float64 precision for condition numbers up to ~1e6.
    """
    _, _, c_ref, c_tgt, cov = _fit_moments(reference, target, segment, num_segments)
    x = cov.transpose(-1, -2).double()
    if active is not None:
        x = torch.where(active[:, None, None], x, torch.eye(3, dtype=x.dtype, device=x.device))
    for _ in range(iterations):
        inv_t = torch.linalg.inv(x).transpose(-1, -2)
        # Higham's scaling makes the iteration converge in a few steps from any invertible start.
        g = (inv_t.norm(dim=(-2, -1)) / x.norm(dim=(-2, -1))).sqrt()[:, None, None]
        x = 0.5 * (g * x + inv_t / g)
    rot = x.to(reference.dtype)
    trans = c_tgt - (rot @ c_ref[:, :, None])[:, :, 0]
    return torch.cat((trans, matrix_to_quat(rot)), dim=-1)


def kabsch(
    reference: Tensor, target: Tensor, segment: Tensor, num_segments: int,
    weights: Tensor | None = None, min_singular: float = 1e-9,
) -> tuple[Tensor, Tensor]:
    """Best rigid fit of each segment's reference points onto its target points.

    Args:
        reference: ``float[N, 3]`` points in each object's body frame.
        target: ``float[N, 3]`` the same points, observed (or predicted) in the world.
        segment: ``int64[N]`` object index of each point, in ``[0, num_segments)``.
        num_segments: ``O``.
        weights: optional ``float[N]`` non-negative point weights.
        min_singular: the second singular value of a segment's covariance below which the fit is
            ambiguous (collinear points); such a segment raises ``ShapeMatchError``.

    Returns:
        ``(pose float[O, 7], residual float[O])``: the pose maps reference onto target
        (``target ~= transform_points(pose, reference)``), and the RMS fit residual. The rotation is
        a proper rotation (determinant +1): reflections are corrected, not returned.
    """
    dt = reference.dtype
    w, wsum, c_ref, c_tgt, cov = _fit_moments(reference, target, segment, num_segments, weights)
    # SVD in float64: covariance of small objects (cm scale) is ~1e-4 and float32 loses the yaw.
    u, s, vh = torch.linalg.svd(cov.double())
    scale = s[:, :1].clamp_min(1e-30)
    if bool((s[:, 1] / scale[:, 0] < min_singular).any()):
        bad = torch.nonzero(s[:, 1] / scale[:, 0] < min_singular).flatten().tolist()
        raise ShapeMatchError(f"kabsch: degenerate (collinear) point sets for objects {bad}")
    d = torch.sign(torch.linalg.det(vh.transpose(-1, -2) @ u.transpose(-1, -2)))
    d = torch.where(d == 0, torch.ones_like(d), d)
    corr = torch.diag_embed(torch.stack((torch.ones_like(d), torch.ones_like(d), d), -1))
    rot = (vh.transpose(-1, -2) @ corr @ u.transpose(-1, -2)).to(dt)
    trans = c_tgt - (rot @ c_ref[:, :, None])[:, :, 0]
    fitted = (rot[segment] @ reference[:, :, None])[:, :, 0] + trans[segment]
    sq = segment_sum(w * ((fitted - target) ** 2).sum(-1), segment, num_segments)
    residual = (sq / wsum).sqrt()
    return torch.cat((trans, matrix_to_quat(rot)), dim=-1), residual
