"""The quasi-static limit-surface pushing model against hand-computed cases."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from fignet_gym.dynamics.base import STATE_SPEC
from fignet_gym.dynamics.limit_surface import (
    LimitSurfaceDynamics,
    closest_on_hull,
    planar_geometry,
    pressure_radius,
    pusher_twist,
)
from fignet_gym.mjcf import push_scene_xml

W, C, V, MU = 0.045, 0.03, 0.01, 0.3  # half width, pressure radius, push, tip friction


def _contact_velocity(tw: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.array([tw[0] - tw[2] * p[1], tw[1] + tw[2] * p[0]])


def test_pressure_radius_of_a_square_is_its_closed_form() -> None:
    """Mean distance from the centre of a square of half side a: a (sqrt 2 + asinh 1) / 3."""
    sq = np.array([[-W, -W], [W, -W], [W, W], [-W, W]])
    assert pressure_radius(sq, 256) == pytest.approx(W * (math.sqrt(2) + math.asinh(1)) / 3, rel=2e-3)


def test_push_through_the_centre_translates_without_turning() -> None:
    tw, stick = pusher_twist(np.array([-W, 0.0]), np.array([1.0, 0.0]), np.array([V, 0.0]), MU, C)
    np.testing.assert_allclose(tw, [V, 0.0, 0.0], atol=1e-12)
    assert stick


def test_frictionless_off_centre_push_rotates_about_the_hand_computed_centre() -> None:
    """A force along +x through (-w, h) on an ellipsoidal limit surface: twist proportional to
    (1, 0, -h / c^2), scaled so the contact point keeps up with the pusher along the normal;
    the object turns about (0, -c^2 / h), whose velocity is zero."""
    h = 0.02
    p = np.array([-W, h])
    tw, stick = pusher_twist(p, np.array([1.0, 0.0]), np.array([V, 0.0]), 0.0, C)
    kappa = V * C**2 / (C**2 + h**2)
    np.testing.assert_allclose(tw, [kappa, 0.0, -h * V / (C**2 + h**2)], rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(_contact_velocity(tw, np.array([0.0, -C**2 / h])), 0.0, atol=1e-15)
    assert tw[2] < 0  # pushed above the centre along +x: clockwise
    assert not stick


def test_sticking_inside_the_motion_cone_and_sliding_outside() -> None:
    """Centred push: the motion cone's edge is at tan(alpha) = mu (1 + w^2 / c^2). Just inside,
    the contact point moves with the pusher; just outside, it only keeps its normal velocity."""
    p, n = np.array([-W, 0.0]), np.array([1.0, 0.0])
    alpha = math.atan(MU * (1 + W**2 / C**2))
    for factor, sticks in ((0.98, True), (1.02, False)):
        a = alpha * factor
        v = V * np.array([math.cos(a), math.sin(a)])
        tw, stick = pusher_twist(p, n, v, MU, C)
        vc = _contact_velocity(tw, p)
        assert stick == sticks
        assert vc[0] == pytest.approx(v[0], rel=1e-9)
        if sticks:
            assert vc[1] == pytest.approx(v[1], rel=1e-9)
        else:
            assert vc[1] < v[1]
            assert vc[1] / vc[0] == pytest.approx(math.tan(alpha), rel=1e-9)  # on the cone edge


def test_pulling_away_does_not_move_the_object() -> None:
    tw, _ = pusher_twist(np.array([-W, 0.0]), np.array([1.0, 0.0]), np.array([-V, 0.002]), MU, C)
    np.testing.assert_array_equal(tw, 0.0)


def test_closest_on_hull_signs_inside_and_outside() -> None:
    sq = np.array([[-W, -W], [W, -W], [W, W], [-W, W]])
    d, near, out = closest_on_hull(sq, np.array([-W - 0.01, 0.0]))
    assert d == pytest.approx(0.01) and out == pytest.approx([-1.0, 0.0])
    d, near, out = closest_on_hull(sq, np.array([-W + 0.002, 0.001]))
    assert d == pytest.approx(-0.002) and out == pytest.approx([-1.0, 0.0])
    np.testing.assert_allclose(near, [-W, 0.001])


def _push(yaw: float, travel: float, offset: float = 0.0) -> np.ndarray:
    """Roll out a straight push of rect1 (half side 45 mm) in a frame turned by ``yaw``: the tip
    starts touching the -x face at ``offset`` along it and moves ``travel`` along +x; returns the
    object's final (x, y, yaw) in the push's own frame."""
    model = mujoco.MjModel.from_xml_string(push_scene_xml("rect1", object_pose=(0, 0, yaw)))
    data = mujoco.MjData(model)
    dyn = LimitSurfaceDynamics(MU)
    r = planar_geometry(model).tip_radius
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    start = rot @ np.array([-W - r, offset])
    data.mocap_pos[0, :2] = start
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    steps = 20
    control = np.zeros((steps, 7))
    control[:, 2] = data.mocap_pos[0, 2]
    control[:, 3] = 1.0
    for k in range(steps):
        control[k, :2] = start + rot @ np.array([travel * (k + 1) / steps, 0.0])
    out = dyn.rollout(model, state, control, frame_skip=5)[0, -1]
    x, y = rot.T @ out[1:3]
    final_yaw = 2 * math.atan2(out[7], out[4]) - yaw
    return np.array([x, y, math.remainder(final_yaw, 2 * math.pi)])


def test_rollout_of_a_centred_push_moves_the_object_with_the_tip() -> None:
    np.testing.assert_allclose(_push(0.0, 0.02), [0.02, 0.0, 0.0], atol=1e-9)


def test_rollout_is_the_same_push_in_a_turned_frame() -> None:
    """An off-centre push turned by a quarter turn in the world gives the same motion in its own
    frame (a wrong yaw convention in reading or writing the pose breaks this)."""
    a, b = _push(0.0, 0.02, offset=0.02), _push(math.pi / 2, 0.02, offset=0.02)
    assert a[2] < -0.05  # pushed above the centre along +x: it turns clockwise
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_validate_refuses_scenes_without_one_pusher() -> None:
    xml = """<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
      <body pos="0 0 .1"><freejoint/><geom type="box" size=".05 .05 .05"/></body>
    </worldbody></mujoco>"""
    with pytest.raises(ValueError, match="mocap"):
        LimitSurfaceDynamics().validate(mujoco.MjModel.from_xml_string(xml), 1)
