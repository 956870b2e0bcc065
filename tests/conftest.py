"""Shared test fixtures: deterministic seeds, headless rendering, small thread counts."""

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

PUSH_LIKE_XML = """
<mujoco>
  <option timestep="0.002"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="box" pos="0 0 0.05">
      <freejoint/>
      <geom type="box" size="0.05 0.04 0.05" mass="1"/>
    </body>
    <body name="tip" mocap="true" pos="0.2 0 0.03">
      <geom type="cylinder" size="0.005 0.02"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(autouse=True)
def _deterministic() -> None:
    torch.manual_seed(0)
    np.random.seed(0)
    torch.set_num_threads(1)


@pytest.fixture
def push_like_xml() -> str:
    """A box on a floor with a mocap cylinder tip (MuJoCo primitives only)."""
    return PUSH_LIKE_XML


@pytest.fixture(scope="module")
def push_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three generated pushes (seed 7) in a trajectory file, for training tests."""
    from fignet_gym.data.format import write_trajectories
    from fignet_gym.data.generate import iter_trajectories

    path = tmp_path_factory.mktemp("data") / "push.h5"
    write_trajectories(path, list(iter_trajectories("push", 3, seed=7)))
    return path
