"""What defines a learned simulator: :class:`SimulatorConfig`, saved in every checkpoint, and the
bounds every config (new or read from a file) is checked against before any module is built.

Training-only settings (noise, loss weights) are not here: they do not change what a trained
model computes, so they live in :class:`fignet_gym.train.config.TrainConfig`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any

from fignet_gym.checks import Range, SettingError, check_settings, check_value
from fignet_gym.simulator.graph import FaceGroup, enabled_face_groups
from fignet_gym.simulator.scene import MeshOptions

#: Allowed values of the numeric config fields (inclusive bounds; the paper's model: history 2,
#: latent 128, 10 blocks). Anything outside is refused in checkpoints and new configs alike, so a
#: config asking for ``10**7`` processor blocks is refused instead of exhausting memory.
CONFIG_BOUNDS: dict[str, Range] = {
    "dt": Range("float", 1e-6, 10.0),
    "history": Range("int", 1, 16),
    "latent_size": Range("int", 1, 4096),
    "hidden_size": Range("int", 1, 8192, none_ok=True),  # None: latent_size
    "message_passing_steps": Range("int", 1, 64),
    "collision_radius": Range("float", 1e-6, 100.0),
    "feature_clip": Range("float", 0.0, 1e4),
}
#: Collision edge kinds (``SimulatorConfig.collision``).
COLLISIONS = ("face", "node")
#: Bounds of gravity components (m/s^2).
GRAVITY_BOUND = 1e3
_GRAVITY = Range("float", -GRAVITY_BOUND, GRAVITY_BOUND)
#: Allowed values of the mesh options (each level multiplies node counts, so they are kept small).
MESH_BOUNDS: dict[str, Range] = {
    "sphere_subdivisions": Range("int", 0, 5),
    "cylinder_sections": Range("int", 3, 256),
    "capsule_rings": Range("int", 1, 64),
    "box_subdivisions": Range("int", 0, 5),
    "plane_half_size": Range("float", 1e-3, 1e5),
    "plane_cells": Range("int", 1, 256),
}


@dataclass(frozen=True)
class SimulatorConfig:
    """Everything that defines a learned simulator (saved in every checkpoint).

    Attributes:
        dt: learned step length (s); a property of the training data.
        history: number of finite-difference velocities in the node features (``H = history + 1`` poses).
        latent_size: width of every latent vector.
        hidden_size: width of MLP hidden layers (``None``: ``latent_size``).
        message_passing_steps: processor blocks (unshared weights).
        mesh_edges: use mesh-mesh edges (FIGNet* drops them for speed).
        object_nodes: use one virtual node per object.
        collision: ``"face"`` (FIGNet face-face hyper-edges) or ``"node"`` (MeshGraphNets node-node).
        collision_radius: ``d_c`` (m). Face-face edges whose receiver face belongs to a static or
            kinematic object are dropped: the paper keeps both directions, but those receivers'
            motion is given anyway, and dropping them halves the edges with the floor and the
            pusher for the same messages into every dynamic node.
        feature_clip: length (m) above which face spanning vectors and object-mesh offsets are
            shortened (0: off, the paper's features). Two-triangle floors have spans of metres
            beside the centimetres of objects: clipping keeps the small ones visible after
            normalisation.
        gravity: known acceleration (m/s^2) of free dynamic objects. The network predicts the
            residual ``a - g dt^2``, so free flight is exact from the start and the network's
            precision is spent on contacts (whose large accelerations set the target scale and so
            would otherwise limit how precisely it can output the small free-fall term).
        next_separation: append to face-face features the separation a kinematic sender face
            will leave after its known next displacement (the ``next_separation`` group of
            ``graph.FACE_GROUPS``); not in the paper, for contact onsets under a pusher.
        rigid_output: project the network's node accelerations onto each object's rigid motions
            (:func:`geometry.rigid_projection`) before the loss and in every step (not in the
            paper, which shape-matches only in rollouts). The network may then express a contact
            as a force at the nodes it touches, and the projection turns it into the torque about
            the centroid analytically, instead of each node having to compute ``alpha x r``.
        canonical_frame: see every scene in a frame that turns and shifts with it
            (:mod:`fignet_gym.simulator.symmetry`), which makes every prediction exactly
            equivariant under turns about the vertical and horizontal shifts. Needs vertical
            ``gravity``. Off in checkpoints saved before it existed.
        scene_type: what the model was trained on ("push", "toss", ...; "" = unspecified).
        mesh_options: how MuJoCo primitives are meshed for this model.
    """

    dt: float = 0.02
    history: int = 2
    latent_size: int = 128
    hidden_size: int | None = None
    message_passing_steps: int = 10
    mesh_edges: bool = True
    object_nodes: bool = True
    collision: str = "face"
    collision_radius: float = 0.02
    feature_clip: float = 0.0
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    next_separation: bool = False
    rigid_output: bool = False
    canonical_frame: bool = False
    scene_type: str = ""
    mesh_options: MeshOptions = field(default_factory=MeshOptions)

    def __post_init__(self) -> None:
        check_config(self)  # bounded sizes: a config can never ask for unbounded memory
        if self.canonical_frame and any(g != 0 for g in self.gravity[:2]):
            raise ValueError(f"canonical_frame needs vertical gravity, got {self.gravity}")

    @property
    def face_groups(self) -> tuple[FaceGroup, ...]:
        """The optional face-edge feature groups this config switches on, in layout order."""
        return enabled_face_groups(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain-type dictionary (safe for ``torch.load(weights_only=True)``)."""
        return asdict(self)

    @staticmethod
    def from_dict(d: dict[str, Any]) -> SimulatorConfig:
        """Inverse of :meth:`to_dict`; unknown keys are a ``ValueError``."""
        d = dict(d)
        unknown = set(d) - {f.name for f in fields(SimulatorConfig)}
        if unknown:
            raise ValueError(f"unknown config keys {sorted(unknown)}")
        if "gravity" in d:
            d["gravity"] = tuple(float(g) for g in d["gravity"])
        if isinstance(d.get("mesh_options"), dict):
            d["mesh_options"] = MeshOptions(**d["mesh_options"])
        return SimulatorConfig(**d)


#: The flags (every ``bool`` field), ``collision`` and ``scene_type``.
_KIND_BOUNDS: dict[str, Range] = {
    **{f.name: Range("bool") for f in fields(SimulatorConfig) if f.type in ("bool", bool)},
    "collision": Range("str", choices=COLLISIONS),
    "scene_type": Range("str"),
}


def check_config(config: SimulatorConfig) -> None:
    """:class:`~fignet_gym.checks.SettingError` (a ``ValueError``) naming the first field of
    ``config`` of the wrong type or out of bounds (:data:`CONFIG_BOUNDS`, gravity, the flags,
    ``collision``, ``scene_type``, :data:`MESH_BOUNDS` as ``mesh_options.<field>``)."""
    check_settings(config, CONFIG_BOUNDS)
    if len(config.gravity) != 3:
        raise SettingError("gravity", f"must have 3 entries, got {config.gravity!r}")
    for g in config.gravity:
        check_value("gravity", g, _GRAVITY)
    check_settings(config, _KIND_BOUNDS)
    check_settings(config.mesh_options, MESH_BOUNDS, "mesh_options.")
