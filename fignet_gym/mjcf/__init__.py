"""MJCF builders for the push and toss scenes (MIT Pushing objects, MOVi-like tossed shapes).

One module per scene type (:mod:`~fignet_gym.mjcf.push`, :mod:`~fignet_gym.mjcf.pusht`,
:mod:`~fignet_gym.mjcf.toss`, :mod:`~fignet_gym.mjcf.cube`) over shared pieces
(:mod:`~fignet_gym.mjcf.assets`); the public names are re-exported here, where users import them.

Every builder returns an XML string for ``mujoco.MjModel.from_xml_string``. The world body holds
a finite floor plane (object 0 of :meth:`fignet_gym.simulator.scene.Scene.from_mjmodel`); then come the
bodies in document order, so a scene's object order is: floor, then the bodies as listed here.

Geometry choices (why):

* Every moving object is a **mesh geom**, also the simple shapes (cube, sphere, cylinder). FIGNet
  sees the triangle mesh, and MuJoCo then collides the same geometry (its convex hull): with
  primitives MuJoCo would collide an exact sphere while the learned model sees a 42-node
  polyhedron.
* MuJoCo collides a mesh by its convex hull. For convex shapes that is exact; for the non-convex
  procedural shapes (torus, torus knot, gear, star, hourglass) contacts with the floor are still
  exact (a plane only ever touches hull points), but one object cannot enter another's hole or the
  gap between gear teeth.
* Restitution follows the project convention (``docs/architecture.md``): a geom's
  ``solref = (timeconst, dampratio)`` with ``dampratio = restitution_to_dampratio(e)``.
  MuJoCo combines two geoms' ``solref`` by their mean and friction by the maximum (PyBullet, which
  made Kubric's data, multiplies both): the per-object properties are the same as Kubric's, the pair
  values differ.
"""

from fignet_gym.mjcf.assets import (
    CONES,
    CONTACT_TIMECONST,
    DEFAULT_CONE,
    ROLLING_FRICTION,
    TORSIONAL_FRICTION,
    prism_mesh,
    yaw_quat,
)
from fignet_gym.mjcf.cube import cube_scene_xml
from fignet_gym.mjcf.push import (
    ELLIPSE_SIDES,
    MIT_OBJECTS,
    MIT_THICKNESS,
    PushObject,
    ellipse_outline,
    push_object,
    push_scene_text,
    push_scene_xml,
)
from fignet_gym.mjcf.pusht import pusht_outline, pusht_rectangles, pusht_scene_xml
from fignet_gym.mjcf.toss import (
    COMPLEX_SHAPES,
    FLOOR_FRICTION,
    FLOOR_RESTITUTION,
    MATERIALS,
    SIMPLE_SHAPES,
    TOSS_SHAPES,
    TossObject,
    toss_scene_xml,
    unit_shape_mesh,
)
from fignet_gym.simulator.scene import MeshOptions, restitution_to_dampratio

__all__ = [
    "COMPLEX_SHAPES", "CONES", "CONTACT_TIMECONST", "DEFAULT_CONE", "ELLIPSE_SIDES", "FLOOR_FRICTION",
    "FLOOR_RESTITUTION",
    "MATERIALS", "MIT_OBJECTS", "MIT_THICKNESS", "ROLLING_FRICTION", "SIMPLE_SHAPES", "TORSIONAL_FRICTION",
    "TOSS_SHAPES", "MeshOptions",
    "PushObject", "TossObject", "cube_scene_xml", "ellipse_outline", "prism_mesh", "push_object",
    "push_scene_text", "push_scene_xml", "pusht_outline", "pusht_rectangles", "pusht_scene_xml",
    "restitution_to_dampratio", "toss_scene_xml", "unit_shape_mesh",
    "yaw_quat",
]
