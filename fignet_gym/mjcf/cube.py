"""MJCF of one cube over a floor plane (the ContactNets tosses and the ``CubeToss-v0`` env)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fignet_gym.mjcf.assets import CONTACT_TIMECONST, GRID_TEXTURE, fmt_numbers, friction_attr, visual_header
from fignet_gym.simulator.scene import restitution_to_dampratio


def cube_scene_xml(
    half_width: float, mass: float, inertia: float, friction: float | Sequence[float],
    restitution: float | None, *, timestep: float = 0.002, gravity: float = -9.81,
    floor_half_size: float = 2.0, contact_timeconst: float = CONTACT_TIMECONST, name: str = "cube",
    dampratio: float | None = None, cone: str = "pyramidal", impratio: float = 1.0,
) -> str:
    """MJCF of one cube (free joint, box geom) above a floor plane at ``z = 0`` (the world body).

    Objects of the scene: ``world`` (static floor), ``name`` (dynamic). A box primitive rather
    than a mesh: MuJoCo's box-plane collision is exact and the learned model's mesh follows
    :class:`~fignet_gym.simulator.scene.MeshOptions` (8 corners by default).

    Args:
        half_width: m. mass: kg. inertia: kg m^2 about each principal axis through the centre.
        friction: sliding friction of both geoms, or their (sliding, torsional, rolling)
            triple. restitution: as ``solref`` damping ratio
            (:func:`~fignet_gym.simulator.scene.restitution_to_dampratio`) with time constant
            ``contact_timeconst`` (s) on both geoms; ``dampratio`` gives the ratio directly
            instead (a fitted one may exceed 1, which no restitution maps to).
        cone, impratio: MuJoCo's friction cone and its impedance ratio.
    """
    if not (half_width > 0 and mass > 0 and inertia > 0):
        raise ValueError(f"cube needs positive half_width, mass and inertia, got {half_width}, "
                         f"{mass}, {inertia}")
    if dampratio is None:
        if restitution is None:
            raise ValueError("cube_scene_xml needs restitution or dampratio")
        dampratio = restitution_to_dampratio(restitution)
    solref = f"{contact_timeconst:.9g} {dampratio:.9g}"
    fr = fmt_numbers(friction) if np.ndim(friction) else friction_attr(f"{friction:.9g}")
    fl = floor_half_size
    return f"""<mujoco model="{name}_toss">
  <compiler angle="radian"/>
  <option timestep="{timestep:.9g}" gravity="0 0 {gravity:.9g}" cone="{cone}"
          impratio="{impratio:.9g}"/>
  {visual_header()}
  <asset>
    {GRID_TEXTURE}
    <material name="grid" texture="grid" texrepeat="{max(1, round(4 * fl))} {max(1, round(4 * fl))}"/>
  </asset>
  <worldbody>
    <light pos="0 0 {4 * fl:.9g}" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="{fl:.9g} {fl:.9g} 0.05" material="grid"
          friction="{fr}" solref="{solref}"/>
    <body name="{name}" pos="0 0 {2 * half_width:.9g}">
      <freejoint name="{name}"/>
      <inertial pos="0 0 0" mass="{mass:.9g}" diaginertia="{fmt_numbers([inertia] * 3)}"/>
      <geom name="{name}" type="box" size="{fmt_numbers([half_width] * 3)}"
            friction="{fr}" solref="{solref}" rgba=".8 .25 .2 1"/>
    </body>
  </worldbody>
</mujoco>
"""
