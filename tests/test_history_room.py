"""``with_history``: a model a user loaded with ``MjModel.from_xml_path`` gets room for the learned
pose history without recompiling its MJCF (issue 41, item 2)."""

from __future__ import annotations

import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest

from fignet_gym.dynamics import FIGNetDynamics, compile_with_history, with_history
from fignet_gym.dynamics.history import history_size
from fignet_gym.mjcf import push_scene_xml
from fignet_gym.pretrained import load_pretrained


@pytest.fixture(scope="module")
def loaded(tmp_path_factory: pytest.TempPathFactory) -> tuple[mujoco.MjModel, str]:
    xml = push_scene_xml("rect1", tip_xy=(-0.07, 0.0))
    path = Path(tmp_path_factory.mktemp("scene")) / "scene.xml"
    path.write_text(xml)
    model = mujoco.MjModel.from_xml_path(str(path))
    assert model.nuserdata < history_size(model)  # as a user's own file comes
    return model, xml


def _push(model: mujoco.MjModel, step, n: int) -> np.ndarray:
    """``float[n, nq]`` qpos after each of ``n`` steps of a tip moving into the object."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    out = []
    for _ in range(n):
        data.mocap_pos[0, 0] += 0.002
        step(model, data)
        out.append(data.qpos.copy())
    return np.array(out)


def test_the_copy_has_room_and_the_same_physics(loaded) -> None:  # noqa: ANN001
    model, _ = loaded
    roomy = with_history(model)
    assert roomy is not model and roomy.nuserdata == history_size(model)
    assert with_history(roomy) is roomy
    assert mujoco.MjData(roomy).userdata.shape == (history_size(model),)
    mj = lambda m, d: mujoco.mj_step(m, d, 10)  # noqa: E731
    np.testing.assert_array_equal(_push(roomy, mj, 30), _push(model, mj, 30))


def test_learned_steps_on_the_copy_keep_the_history_as_a_compiled_model_does(loaded) -> None:  # noqa: ANN001
    model, xml = loaded
    dyn = FIGNetDynamics(load_pretrained("push").eval())
    step = lambda m, d: dyn.step(m, d, 10)  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "no room for the pose history" warning
        roomy = _push(with_history(model), step, 12)
    compiled = _push(compile_with_history(xml), step, 12)
    np.testing.assert_array_equal(roomy, compiled)
    # Without the room every step restarts the history from qpos/qvel: another trajectory.
    with pytest.warns(UserWarning, match=r"with_history\(model\)"):
        bare = _push(model, step, 12)
    assert np.abs(bare - compiled).max() > 1e-6
