"""The learned simulator: graph network + normalisation + integration + shape matching.

Everything physical lives here (as in DeepMind's learning_to_simulate): input features, the
second-order Euler integrator and its exact inverse used to build training targets, the training
noise and how it cancels in the target, and shape matching that turns predicted node positions back
into rigid poses.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, fields

import torch
from torch import Tensor, nn

from fignet_gym.simulator.collision import (
    FaceContacts,
    find_face_contacts,
    no_face_contacts,
    no_node_edges,
    node_collision_edges,
)
from fignet_gym.simulator.config import SimulatorConfig
from fignet_gym.simulator.geometry import (
    axis_angle_to_quat,
    kabsch,
    polar_fit,
    quat_mul,
    quat_normalize,
    quat_rotate,
    rigid_moments,
    rigid_projection,
    segment_sum,
)
from fignet_gym.simulator.graph import Graph, build_graph, feature_sizes
from fignet_gym.simulator.networks import EncodeProcessDecode
from fignet_gym.simulator.normalization import Normalizer
from fignet_gym.simulator.scene import Scene
from fignet_gym.simulator.symmetry import CanonicalFrame, canonical_frame, from_frame, to_frame

#: Smallest RMS object radius (m) the default rotational noise is scaled by: a one-node object
#: would otherwise get an infinite rotation.
MIN_OBJECT_RADIUS = 1e-4
#: Floor of an object's summed squared node distances (m^2) in :func:`rigid_terms` (a
#: degenerate one-node object has no rotational part).
_TINY_SQUARED_RADIUS = 1e-12


def integrate(x_t: Tensor, x_prev: Tensor, acc: Tensor) -> Tensor:
    """Second-order Euler (Verlet) step of positions ``float[..., 3]``: the next position from the
    current ``x_t``, the previous ``x_prev`` and the finite-difference acceleration ``acc`` (m per
    step^2). Exact inverse: :func:`inverse_integrate`."""
    return 2 * x_t - x_prev + acc


def inverse_integrate(x_next: Tensor, x_t: Tensor, x_prev: Tensor) -> Tensor:
    """The acceleration ``float[..., 3]`` (m per step^2) that :func:`integrate` turns into
    ``x_next``: the training target of a step from ``x_prev``, ``x_t``."""
    return x_next - 2 * x_t + x_prev


@dataclass(frozen=True)
class TrainingNoise:
    """The random-walk noise added to a training example's input poses (a training setting, not
    part of the model).

    Attributes:
        std: std (m) of the translational noise at the last input frame (0: no noise).
        rotation_std: std (rad) of the rotational noise at the last input frame (0: the rotation
            that moves nodes at the object's RMS radius by ``std``).
    """

    std: float = 0.0
    rotation_std: float = 0.0


@dataclass(frozen=True)
class StepInputs:
    """Positions a step is computed from: ``node_hist float[H, N, 3]`` (oldest first) and
    ``node_next float[N, 3]`` (the next positions given for non-dynamic nodes)."""

    graph: Graph
    node_hist: Tensor
    node_next: Tensor
    contacts: FaceContacts


@dataclass(frozen=True)
class TrainingExample:
    """One-step supervision (:meth:`LearnedSimulator.training_example`).

    Attributes:
        graph: raw input features of the noisy history.
        target: ``float[N, 3]`` acceleration (m per step^2) minus the gravity prior that maps the
            noisy inputs onto the true next positions plus the last frame's noise.
        weight: ``float[N]`` per-node loss weight (1 for dynamic nodes, 0 for the others).
        true_node_pos: ``float[N, 3]`` the true (noise-free) current node positions, about which
            the loss's rotational terms are taken.
    """

    graph: Graph
    target: Tensor
    weight: Tensor
    true_node_pos: Tensor


#: Fewest mesh nodes for which a lower ``inference_dtype`` is used: on smaller graphs (one to ~16
#: push scenes, one to ~3 toss scenes) bf16 is slower than float32 on this repository's CPUs
#: (experiments/README.md, "Speed"), so they run in float32.
LOW_PRECISION_MIN_NODES = 1024


class LearnedSimulator(nn.Module):
    """FIGNet as a simulator: ``step(scene, history, next_kinematic) -> next poses``."""

    def __init__(self, config: SimulatorConfig | None = None) -> None:
        super().__init__()
        self.config = config or SimulatorConfig()
        c = self.config
        sizes = feature_sizes(c.history, face_groups=c.face_groups)
        face, node = c.collision == "face", c.collision == "node"
        self.net = EncodeProcessDecode(
            sizes, latent=c.latent_size, hidden=c.hidden_size or c.latent_size,
            steps=c.message_passing_steps, mesh_edges=c.mesh_edges, object_nodes=c.object_nodes,
            face_edges=face, node_edges=node)
        self.norms = nn.ModuleDict({k: Normalizer(v) for k, v in sizes.items()})
        self.norms["mesh_obj"] = Normalizer(sizes["obj_mesh"])
        self.target_norm = Normalizer(3)
        # Precision of the network at inference (not a config field: it changes no parameter and
        # is not saved). torch.bfloat16 runs a bfloat16 copy of the whole network (matmuls,
        # LayerNorms, sums) on graphs of at least LOW_PRECISION_MIN_NODES nodes, 1.3-1.5x faster
        # per batched scene on CPUs with AVX-512 BF16 or AMX, at a relative error of ~1e-2 in the
        # accelerations (experiments/README.md, "Speed").
        self.inference_dtype: torch.dtype = torch.float32
        self._low_precision: tuple[tuple, nn.Module] | None = None

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    # ------------------------------------------------------------------ inputs
    def build_inputs(self, scene: Scene, history: Tensor, next_kinematic: Tensor) -> StepInputs:
        """Graph of raw features from poses ``history float[H, O, 7]`` and ``next_kinematic float[O, 7]``."""
        H = self.config.history + 1
        if history.shape[0] != H or history.shape[1:] != (scene.num_objects, 7):
            raise ValueError(
                f"history must be float[{H}, {scene.num_objects}, 7], got {tuple(history.shape)}")
        # Current history and next poses in one transform each: [H + 1, ...], last = next.
        poses = torch.cat((history, next_kinematic[None]))
        nodes, coms = scene.node_positions(poses), scene.com_positions(poses)
        node_hist, node_next, com_hist, com_next = nodes[:-1], nodes[-1], coms[:-1], coms[-1]
        contacts, node_edges = self.collide(scene, node_hist[-1])
        graph = build_graph(scene, node_hist, com_hist, node_next, com_next, contacts, node_edges,
                            clip=self.config.feature_clip, face_groups=self.config.face_groups,
                            sort_unclipped=self.config.canonical_frame)
        return StepInputs(graph, node_hist, node_next, contacts)

    def collide(self, scene: Scene, node_pos: Tensor) -> tuple[FaceContacts, tuple[Tensor, Tensor]]:
        """Collision edges at node positions ``float[N, 3]``: ``(face contacts, node edges)``, of
        which the kind not configured (``collision``) is empty. Face contacts keep receivers on
        dynamic objects only."""
        radius = self.config.collision_radius
        if self.config.collision != "face":
            edges = node_collision_edges(node_pos, scene.node_object, scene.collision_pairs, radius)
            return no_face_contacts(node_pos), edges
        contacts = find_face_contacts(node_pos, scene.faces, scene.face_object, scene.collision_pairs, radius)
        keep = scene.dynamic_mask[scene.face_object[contacts.receiver_face]].nonzero().squeeze(1)
        contacts = FaceContacts(*(getattr(contacts, f.name).index_select(0, keep) for f in fields(contacts)))
        return contacts, no_node_edges(node_pos)

    def normalize(self, g: Graph, accumulate: bool = False) -> Graph:
        """Normalise every feature tensor (accumulating statistics when training)."""
        return g.map_features(lambda kind, x: self.norms[kind](x, accumulate))

    # ------------------------------------------------------------------ inference
    def predict_acceleration(self, graph: Graph) -> Tensor:
        """Per-node finite-difference acceleration (m per step^2), ``float[N, 3]``, including the
        gravity prior (which non-dynamic nodes also get: their prediction is never used)."""
        graph = self.normalize(graph)
        if self.inference_dtype == torch.float32 or graph.node_features.shape[0] < LOW_PRECISION_MIN_NODES:
            out = self.net(graph)
        else:
            low = graph.map_features(lambda _, x: x.to(self.inference_dtype))
            out = self._low_precision_net()(low).float()
        acc = self._rigid(self.target_norm.inverse(out), graph)
        return acc + self.gravity_step()

    def _low_precision_net(self) -> nn.Module:
        """The network in ``inference_dtype``, copied again whenever a parameter has changed
        (an optimiser step, a loaded state, a move to another device)."""
        key = (self.inference_dtype, *((p.data_ptr(), _version(p)) for p in self.net.parameters()))
        if self._low_precision is None or self._low_precision[0] != key:
            with torch.no_grad():
                net = copy.deepcopy(self.net).to(self.inference_dtype).requires_grad_(False)
            self._low_precision = (key, net)
        return self._low_precision[1]

    def _rigid(self, acc: Tensor, graph: Graph) -> Tensor:
        """Accelerations ``float[N, 3]`` (m per step^2) projected per object if ``rigid_output``."""
        if not self.config.rigid_output:
            return acc
        return rigid_projection(acc, graph.node_pos, graph.node_object, graph.num_objects)

    def gravity_step(self) -> Tensor:
        """The gravity prior ``g dt^2`` (m per step^2), ``float[3]``."""
        return torch.tensor(self.config.gravity, device=self.device) * self.config.dt**2

    @torch.no_grad()
    def step(self, scene: Scene, history: Tensor, next_kinematic: Tensor) -> Tensor:
        """One learned step.

        Args:
            scene: static topology (a single scene or a batch, :meth:`Scene.repeat`).
            history: ``float[H, O, 7]`` past poses, oldest first, last = current.
            next_kinematic: ``float[O, 7]`` next poses of non-dynamic objects (rows of dynamic
                objects are ignored).

        Returns:
            ``float[O, 7]`` next poses: dynamic objects by shape matching the predicted node
            positions, the others copied from ``next_kinematic``.
        """
        return self.step_with_info(scene, history, next_kinematic)[0]

    @torch.no_grad()
    def step_with_info(self, scene: Scene, history: Tensor, next_kinematic: Tensor
                       ) -> tuple[Tensor, StepInputs, Tensor]:
        """:meth:`step` that also returns its inputs and the shape-matching residual ``float[O]`` (m)."""
        frame = self._frame(scene, history[-1])
        inputs = self.build_inputs(scene, *self._into(scene, frame, history, next_kinematic))
        # Inference mode skips autograd bookkeeping on the network's ~1000 ops; acc is only read
        # by out-of-place ops below, so no inference tensor escapes.
        with torch.inference_mode():
            acc = self.predict_acceleration(inputs.graph)
        pred = self._next_nodes(scene, inputs, acc)
        poses, residual = kabsch(scene.ref_vertices, pred, scene.node_object, scene.num_objects)
        out = torch.where(scene.dynamic_mask[:, None], self._out_of(scene, frame, poses),
                          next_kinematic)
        return out, inputs, residual

    def _frame(self, scene: Scene, current: Tensor) -> CanonicalFrame | None:
        """The canonical frame of each scene at the current poses ``float[O, 7]``, or ``None``
        without ``canonical_frame``. Not differentiated: predictions do not depend on it."""
        if not self.config.canonical_frame:
            return None
        return canonical_frame(scene, current.detach())

    @staticmethod
    def _into(scene: Scene, frame: CanonicalFrame | None, *poses: Tensor) -> tuple[Tensor, ...]:
        """Each pose tensor ``float[..., O, 7]`` in ``frame`` (unchanged when it is ``None``)."""
        return poses if frame is None else tuple(to_frame(scene, p, frame) for p in poses)

    @staticmethod
    def _out_of(scene: Scene, frame: CanonicalFrame | None, poses: Tensor) -> Tensor:
        """Canonical poses ``float[..., O, 7]`` back in the world."""
        return poses if frame is None else from_frame(scene, poses, frame)

    def differentiable_step(self, scene: Scene, history: Tensor, next_kinematic: Tensor) -> Tensor:
        """:meth:`step` with gradients, for training through rollouts: the same prediction (in
        float32, normalisers fixed), shape matched by :func:`polar_fit`, which agrees with Kabsch
        to rounding but is differentiable for symmetric objects too. ``float[H, O, 7]``,
        ``float[O, 7]`` -> ``float[O, 7]``."""
        frame = self._frame(scene, history[-1])
        inputs = self.build_inputs(scene, *self._into(scene, frame, history, next_kinematic))
        pred = self._next_nodes(scene, inputs, self.predict_acceleration(inputs.graph))
        poses = polar_fit(scene.ref_vertices, pred, scene.node_object, scene.num_objects,
                          scene.dynamic_mask)
        return torch.where(scene.dynamic_mask[:, None], self._out_of(scene, frame, poses),
                           next_kinematic)

    @staticmethod
    def _next_nodes(scene: Scene, inputs: StepInputs, acc: Tensor) -> Tensor:
        """Node positions ``float[N, 3]`` one step on: :func:`integrate` with the accelerations
        ``acc`` on dynamic nodes; non-dynamic nodes take their given positions so that their
        (ignored) fit is well posed."""
        x_next = integrate(inputs.node_hist[-1], inputs.node_hist[-2], acc)
        dyn = scene.dynamic_mask[scene.node_object][:, None]
        return torch.where(dyn, x_next, inputs.node_next)

    @torch.no_grad()
    def rollout(self, scene: Scene, history: Tensor, kinematic: Tensor) -> Tensor:
        """Autoregressive rollout: ``history float[H, O, 7]``, ``kinematic float[T, O, 7]`` (next
        poses of non-dynamic objects for each of ``T`` steps) -> ``float[T, O, 7]``."""
        hist = history.clone()
        out = []
        for t in range(kinematic.shape[0]):
            nxt = self.step(scene, hist, kinematic[t])
            out.append(nxt)
            hist = torch.cat((hist[1:], nxt[None]), dim=0)
        return torch.stack(out)

    # ------------------------------------------------------------------ training
    def training_example(self, scene: Scene, poses: Tensor, generator: torch.Generator | None = None,
                         inputs: Tensor | None = None, noise: TrainingNoise | None = None
                         ) -> TrainingExample:
        """Noisy inputs and the acceleration target for one-step supervision.

        Args:
            scene: topology.
            poses: ``float[H + 1, O, 7]`` true poses; the last row is the target step.
            generator: random source for the training noise.
            inputs: ``float[H, O, 7]`` perturbed history to use instead of adding noise to
                ``poses[:-1]`` (the model's own rollout, for pushforward training).
            noise: the training noise added to ``poses[:-1]`` (default: none).

        Returns:
            A :class:`TrainingExample` whose target is the acceleration that maps the noisy
            inputs onto the true next positions plus the last frame's noise, minus the gravity
            prior.
        """
        hist, nxt = poses[:-1], poses[-1]
        noisy = inputs if inputs is not None else self.pose_noise(scene, hist, generator, noise)
        # The frame of the noisy inputs, as a step takes it from the poses it is given.
        noisy, hist, nxt = self._into(scene, self._frame(scene, noisy[-1]), noisy, hist, nxt)
        inputs = self.build_inputs(scene, noisy, nxt)
        x_true_t = scene.node_positions(hist[-1])
        noise_last = inputs.node_hist[-1] - x_true_t
        # The model cannot know the last frame's noise, so the target keeps it; what it must learn
        # is to undo the velocity noise (as in learning_to_simulate).
        target_next = scene.node_positions(nxt) + noise_last
        accel = inverse_integrate(target_next, inputs.node_hist[-1], inputs.node_hist[-2])
        target = accel - self.gravity_step()
        weight = scene.dynamic_mask[scene.node_object].to(target.dtype)
        return TrainingExample(inputs.graph, target, weight, x_true_t)

    def pose_noise(self, scene: Scene, hist: Tensor, gen: torch.Generator | None,
                   noise: TrainingNoise | None = None) -> Tensor:
        """Rigid random-walk noise on dynamic objects' poses: ``float[H, O, 7] -> float[H, O, 7]``.

        Noise is rigid (a translation and a rotation about the centre of mass per object and frame)
        because rollouts are shape matched: the errors a model meets at test time are rigid too.
        The rotation's std is ``noise.rotation_std``, or by default ``noise.std / radius`` so that
        node displacements are ``~noise.std``. No ``noise`` (or ``noise.std = 0``) adds none.
        """
        if noise is None or noise.std <= 0:
            return hist
        H, n_obj = hist.shape[0], hist.shape[1]
        walk = math.sqrt(max(H - 1, 1))  # increments add up to the std at the last frame
        sigma = noise.std / walk
        dev, dt = hist.device, hist.dtype
        dtrans = torch.randn(H - 1, n_obj, 3, generator=gen, device=dev, dtype=dt) * sigma
        if noise.rotation_std > 0:
            rot_sigma = hist.new_full((n_obj,), noise.rotation_std / walk)
        else:
            rot_sigma = sigma / self._object_radius(scene)
        drot = torch.randn(H - 1, n_obj, 3, generator=gen, device=dev, dtype=dt) * rot_sigma[:, None]
        zero = torch.zeros(1, n_obj, 3, device=dev, dtype=dt)
        trans = torch.cat((zero, dtrans.cumsum(0)), 0)
        rotvec = torch.cat((zero, drot.cumsum(0)), 0)
        dq = axis_angle_to_quat(rotvec)
        com = scene.com_positions(hist)
        q_new = quat_normalize(quat_mul(dq, hist[..., 3:]))
        # Rotate about the centre of mass: com stays, body origin moves with the rotation.
        p_new = com + quat_rotate(dq, hist[..., :3] - com) + trans
        # Static and kinematic objects keep their exact poses (the identity rotation above rounds).
        return torch.where(scene.dynamic_mask[None, :, None], torch.cat((p_new, q_new), dim=-1), hist)

    def _object_radius(self, scene: Scene) -> Tensor:
        """RMS distance ``float[O]`` of each object's nodes from its centre of mass."""
        d2 = ((scene.ref_vertices - scene.object_com[scene.node_object]) ** 2).sum(-1)
        s = segment_sum(d2, scene.node_object, scene.num_objects)
        n = segment_sum(torch.ones_like(d2), scene.node_object, scene.num_objects)
        return (s / n.clamp_min(1)).sqrt().clamp_min(MIN_OBJECT_RADIUS)

    def training_prediction(self, graph: Graph, accumulate: bool = False) -> Tensor:
        """The network's normalised acceleration prediction ``float[N, 3]`` with gradients, as the
        loss sees it (rigidly projected if ``rigid_output``, like every step); ``accumulate``
        updates the feature normalisers' statistics."""
        pred = self.net(self.normalize(graph, accumulate))
        if self.config.rigid_output:
            pred = self.target_norm(self._rigid(self.target_norm.inverse(pred), graph))
        return pred

    def loss(self, example: TrainingExample, rigid_weight: float = 0.0, accumulate: bool = True,
             vertical_weight: float = 1.0) -> Tensor:
        """The training loss of one (batched) example: scalar.

        The weighted MSE of normalised accelerations over dynamic nodes (z weighted by
        ``vertical_weight``; 1 is the paper's plain MSE), plus ``rigid_weight`` times the
        per-object linear and rotational acceleration terms (:func:`rigid_terms`), which isolate
        the rotation that a plain per-node MSE lets translation and noise drown (the yaw of a
        pushed object). ``accumulate`` updates
        the normalisers' statistics (target first, so that an early loss is already normalised).
        """
        graph, target, weight = example.graph, example.target, example.weight
        norm = self.target_norm
        if accumulate:
            norm.accumulate(target[weight > 0])
        pred_n = self.training_prediction(graph, accumulate)
        err = (pred_n - norm(target)) ** 2
        comp = err.new_tensor([1.0, 1.0, vertical_weight])
        loss = (err * comp).sum(-1).mul(weight).sum() / (weight.sum() * comp.sum()).clamp_min(1.0)
        if rigid_weight <= 0:
            return loss
        # One isotropic scale (not per axis) keeps cross products meaningful.
        scale = norm.std.mean().to(pred_n.dtype)
        seg, n_obj = graph.node_object, graph.num_objects
        lin_p, ang_p = rigid_terms(example.true_node_pos, norm.inverse(pred_n) / scale, seg, n_obj)
        lin_t, ang_t = rigid_terms(example.true_node_pos, target / scale, seg, n_obj)
        live = segment_sum(weight, seg, n_obj) > 0  # the objects the node term supervises
        n = live.sum().clamp_min(1)  # a batch may have no dynamic object
        rigid = ((lin_p - lin_t)[live].pow(2).sum() + (ang_p - ang_t)[live].pow(2).sum()) / (3 * n)
        return loss + rigid_weight * rigid


def _version(t: Tensor) -> int:
    """``t``'s in-place update counter (inference tensors have none and never change)."""
    return -1 if t.is_inference() else t._version


def rigid_terms(pos: Tensor, acc: Tensor, node_object: Tensor, num_objects: int) -> tuple[Tensor, Tensor]:
    """Per-object linear and rotational parts of node accelerations ``acc float[N, 3]`` at node
    positions ``pos float[N, 3]`` (nodes of object ``node_object int64[N]``).

    The rotational part is ``r_rms * sum_i r_i x a_i / sum_i |r_i|^2`` (``r`` from the object's
    node centroid): an angular acceleration expressed as the tangential acceleration at the
    object's RMS radius, so it has the units (and scale) of node accelerations. Both terms are
    linear in ``acc``, so cheap and differentiable. Returns ``(float[O, 3], float[O, 3])``.
    """
    count, r, lin, torque = rigid_moments(acc, pos, node_object, num_objects)
    r2 = segment_sum((r * r).sum(-1), node_object, num_objects).clamp_min(_TINY_SQUARED_RADIUS)
    return lin, torque / r2[:, None] * (r2 / count).sqrt()[:, None]
