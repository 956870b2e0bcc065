"""Isotropic contact physics: a push or a toss turned about the vertical and shifted
horizontally gives the same motion in its own frame, by MuJoCo itself (issue 38).

Turns come from scipy (independent of the code under test). Each test also runs MuJoCo's default
pyramidal cone, which must fail the same check: the check can fail.
"""

import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import fignet_gym  # noqa: F401  (registers the envs)
from fignet_gym.data.generate import iter_trajectories
from fignet_gym.mjcf import TossObject, push_scene_xml, toss_scene_xml

HEADINGS = np.arange(8) * np.pi / 4 + 0.3


def _in_own_frame(pos: np.ndarray, quat: np.ndarray, heading: float, shift: np.ndarray
                  ) -> tuple[np.ndarray, Rotation]:
    """World positions ``float[K, 3]`` and wxyz quaternions ``float[K, 4]`` taken back by the
    turn ``heading`` and the horizontal ``shift``."""
    back = Rotation.from_euler("z", -heading)
    return back.apply(pos - shift), back * Rotation.from_quat(quat, scalar_first=True)


def _spread(finals: list[tuple[np.ndarray, Rotation]]) -> tuple[float, float]:
    """Largest position (m) and orientation (deg) difference from the first heading's result."""
    p0, r0 = finals[0]
    dp = max(float(np.abs(p - p0).max()) for p, _ in finals)
    da = max(float(np.degrees((r.inv() * r0).magnitude()).max()) for _, r in finals)
    return dp, da


def _push(shape: str, cone: str | None) -> tuple[float, float]:
    finals = []
    for k, th in enumerate(HEADINGS):
        shift = np.array([0.03 * np.cos(k), -0.02 * k, 0.0])
        turn = Rotation.from_euler("z", th)
        tip = shift + turn.apply([-0.07, 0.02, 0.0])
        kw = {} if cone is None else {"cone": cone}
        model = mujoco.MjModel.from_xml_string(push_scene_xml(
            shape, object_pose=(shift[0], shift[1], th), tip_xy=tip[:2], **kw))
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        velocity = turn.apply([0.1, 0.0, 0.0])  # along the object's own axis
        for _ in range(250):  # 0.5 s
            data.mocap_pos[0] += velocity * model.opt.timestep
            mujoco.mj_step(model, data)
        finals.append(_in_own_frame(data.qpos[None, :3], data.qpos[None, 3:7], th, shift))
    return _spread(finals)


@pytest.mark.parametrize("shape", ["rect1", "tri2", "ellip3"])
def test_push_is_the_same_at_every_heading(shape: str) -> None:
    dp, da = _push(shape, None)  # the scene's default: what generate and Push-v2 use
    assert dp < 1e-6 and da < 1e-4, (dp, da)


def test_pyramidal_push_depends_on_the_heading() -> None:
    dp, da = _push("rect1", "pyramidal")
    assert dp > 1e-3 and da > 1.0, (dp, da)


def _toss(cone: str | None) -> tuple[float, float]:
    # Objects dropped level with a horizontal velocity and a spin about the vertical: they land,
    # slide, turn and stop (no tumbling, whose chaos would amplify float rounding).
    objs = [TossObject("cube", 0.7, "metal"), TossObject("sphere", 0.7, "metal"),
            TossObject("cube", 1.4, "metal")]
    start = np.array([[0.0, 0.0, 1.0], [3.0, 0.5, 1.2], [-3.0, 1.0, 1.5]])
    lin = np.array([[2.0, 0.5, 0.0], [-1.0, 1.0, 0.0], [1.0, -1.0, 0.0]])
    spin = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -2.0], [0.0, 0.0, 1.0]])
    finals = []
    for k, th in enumerate(HEADINGS):
        shift = np.array([np.cos(2 * k), np.sin(k), 0.0])
        turn = Rotation.from_euler("z", th)
        poses = np.concatenate([turn.apply(start) + shift,
                                np.tile(turn.as_quat(scalar_first=True), (3, 1))], 1)
        vel = np.concatenate([turn.apply(lin), spin], 1)  # angular velocity is local in qvel
        kw = {} if cone is None else {"cone": cone}
        model = mujoco.MjModel.from_xml_string(
            toss_scene_xml(objs, poses=poses, velocities=vel, **kw))
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, 0)
        for _ in range(1000):  # 2 s
            mujoco.mj_step(model, data)
        finals.append(_in_own_frame(data.xpos[1:], data.xquat[1:], th, shift))
    return _spread(finals)


def test_toss_is_the_same_at_every_heading() -> None:
    dp, da = _toss(None)
    assert dp < 1e-6 and da < 1e-4, (dp, da)


def test_pyramidal_toss_depends_on_the_heading() -> None:
    dp, da = _toss("pyramidal")
    assert dp > 1e-3 and da > 1.0, (dp, da)


@pytest.mark.parametrize("kind", ["push", "toss-simple", "toss-complex"])
def test_generated_scenes_use_the_elliptic_cone(kind: str) -> None:
    traj = next(iter(iter_trajectories(kind, 1, seed=3)))
    model = mujoco.MjModel.from_xml_string(traj.mjcf)
    assert model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC


@pytest.mark.parametrize(("env_id", "cone", "pretrained"), [
    ("fignet_gym/Push-v2", mujoco.mjtCone.mjCONE_ELLIPTIC, "push"),
    ("fignet_gym/Push-v1", mujoco.mjtCone.mjCONE_PYRAMIDAL, "push-pyramidal"),
    ("fignet_gym/Toss-v1", mujoco.mjtCone.mjCONE_ELLIPTIC, "toss"),
    ("fignet_gym/Toss-v0", mujoco.mjtCone.mjCONE_PYRAMIDAL, "toss"),
])
def test_env_versions_keep_their_physics_and_models(env_id: str, cone: int, pretrained: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Gymnasium's out-of-date notice for v0 and v1
        env = gym.make(env_id).unwrapped
    assert env.model.opt.cone == cone
    assert env.default_checkpoint == pretrained
    env.close()


def test_unknown_cone_is_a_one_line_error() -> None:
    with pytest.raises(ValueError, match="unknown friction cone 'round'; valid: elliptic, pyramidal"):
        push_scene_xml("rect1", cone="round")
