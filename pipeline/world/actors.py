"""Procedural actor meshes: one canonical mesh per :class:`ObjectClass`, scaled and placed per actor.

Conventions:

- Each class has several body families (:data:`pipeline.world.actor_shapes.FAMILIES`: sedan, hatchback, estate,
  SUV, coupé, pickup for cars, and so on); an actor's *model* is one of its class's families, picked by its
  ``variant`` (a per-actor random number the render draws from the run's seed) among the families that suit its
  length (:meth:`ActorMeshes.model_codes`), so the same actor keeps its body in every frame. A family may have
  several poses (people through the walk cycle, a bicycle's cranks: :mod:`pipeline.world.people`,
  :mod:`pipeline.world.two_wheelers`), one canonical mesh each; :attr:`Actors.pose` picks the frame's.
- A model's canonical mesh lives in the *unit box frame*: centre at the origin, x forward, y left,
  z up, and its vertices span exactly [-0.5, 0.5] on every axis (it touches all six faces). Placing it
  is the affine map ``p_world = R(yaw) @ diag(length, width, height) @ p_unit + centre``, so the placed
  mesh fills its 3D box exactly and 3D labels and 2D projections agree.
- Shapes are modelled in metres at a typical size of the class and normalised once (cached); scaling
  to another size stretches the parts (a long truck gets longer wheels) — acceptable for detection data.
- Users' own meshes (:mod:`pipeline.world.user_meshes`) are :class:`Model` s that replace or join a class's
  families (:class:`ActorMeshes`); they suit actors of any length.
- Body paint is the material ``paint``; its colour is per actor (:attr:`Actors.color_rgb`), not in the
  material table. Brake lights are lit where :attr:`Actors.brake` is set (the renderer's concern).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from pipeline.core.build_cache import cached
from pipeline.core.classes import ObjectClass, Person
from pipeline.core.geometry import Boxes3D
from pipeline.world.actor_shapes import FAMILIES, SUITS_LENGTH_M
from pipeline.world.mesh import BODY, RIDER, Mesh
from pipeline.world.smooth_normals import corner_normals


@dataclass(frozen=True)
class Actors:
    """The actors of one frame, struct of arrays (N actors).

    Attributes:
        track_id: (N,) int32 unique positive track ids (0 is reserved for "static / nothing").
        object_class: N :class:`ObjectClass` members.
        boxes: (N) world boxes (centre, (length, width, height), yaw), metres / radians.
        color_rgb: (N, 3) float32 paint colour, linear RGB in [0, 1].
        brake: (N,) bool, brake lights lit.
        variant: (N,) uint32 per-actor random number that picks the body family (:meth:`ActorMeshes.model_codes`);
            0 (the default) picks each class's first suitable family.
        lights_on: (N,) bool, the vehicle's lamps (head and tail lamps, side markers, the plate lamp, its low beams)
            are switched on where the condition turns vehicle lights on (dusk, night); all True by default. A parked
            vehicle's are off.
        pose: (N,) int64 the pose of the actor's family to show (a family of several poses: a person's phase of the
            walk cycle, :func:`pipeline.world.gait.gait_poses`), taken modulo the family's number of poses; 0 (the
            default) is each family's first.
    """

    track_id: np.ndarray
    object_class: tuple[ObjectClass, ...]
    boxes: Boxes3D
    color_rgb: np.ndarray
    brake: np.ndarray = field(default=None)  # type: ignore[assignment]
    variant: np.ndarray = field(default=None)  # type: ignore[assignment]
    lights_on: np.ndarray = field(default=None)  # type: ignore[assignment]
    pose: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        n = len(self.boxes)
        track_id = np.asarray(self.track_id, dtype=np.int32).reshape(-1)
        classes = tuple(ObjectClass(c) for c in self.object_class)
        color = np.asarray(self.color_rgb, dtype=np.float32).reshape(-1, 3)
        brake = np.zeros(n, bool) if self.brake is None else np.asarray(self.brake, dtype=bool).reshape(-1)
        variant = np.zeros(n, np.uint32) if self.variant is None else np.asarray(self.variant, np.uint32).reshape(-1)
        lights_on = np.ones(n, bool) if self.lights_on is None else np.asarray(self.lights_on, bool).reshape(-1)
        pose = np.zeros(n, np.int64) if self.pose is None else np.asarray(self.pose, np.int64).reshape(-1)
        if not (len(track_id) == len(classes) == len(color) == len(brake) == len(variant) == len(lights_on)
                == len(pose) == n):
            raise ValueError(
                f"actor arrays differ in length: track_id {len(track_id)}, object_class {len(classes)}, "
                f"boxes {n}, color_rgb {len(color)}, brake {len(brake)}, variant {len(variant)}, "
                f"lights_on {len(lights_on)}, pose {len(pose)}"
            )
        if n and pose.min() < 0:
            raise ValueError("pose must be >= 0")
        if n and (track_id.min() <= 0 or len(np.unique(track_id)) != n):
            raise ValueError("track ids must be positive and unique (0 means static / nothing)")
        if n and (color.min() < 0.0 or color.max() > 1.0):
            raise ValueError("color_rgb must be linear RGB in [0, 1]")
        object.__setattr__(self, "track_id", track_id)
        object.__setattr__(self, "object_class", classes)
        object.__setattr__(self, "color_rgb", color)
        object.__setattr__(self, "brake", brake)
        object.__setattr__(self, "variant", variant)
        object.__setattr__(self, "lights_on", lights_on)
        object.__setattr__(self, "pose", pose)

    def __len__(self) -> int:
        return len(self.track_id)

    @classmethod
    def empty(cls) -> Actors:
        return cls(np.zeros(0, np.int32), (), Boxes3D(np.zeros((0, 3)), np.ones((0, 3)), np.zeros(0)), np.zeros((0, 3)))

    @property
    def class_codes(self) -> np.ndarray:
        """(N,) int32 index of each actor's class in ``list(ObjectClass)``."""
        order = list(ObjectClass)
        return np.array([order.index(c) for c in self.object_class], dtype=np.int32)


RARE_FAMILY_TAG = 0x5EA7  # the draw that picks a family with a share (ActorMeshes.family_codes)


def actor_variants(track_id: np.ndarray, seed: int) -> np.ndarray:
    """(N,) uint32 per-actor random numbers from (run seed, track id): SplitMix64's finaliser of their mix, so an
    actor draws the same number in every frame and shard, and other seeds draw others."""
    with np.errstate(over="ignore"):
        z = (np.asarray(track_id, np.uint64) * np.uint64(0x9E3779B97F4A7C15)
             + np.uint64(int(seed) % 2**64) * np.uint64(0xD1B54A32D192ED03))
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z ^= z >> np.uint64(31)
    return (z >> np.uint64(32)).astype(np.uint32)


def srgb8_to_linear(rgb8: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 sRGB colours (SUMO's) to (N, 3) float32 linear RGB in [0, 1]."""
    c = np.asarray(rgb8, dtype=np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def normalise_to_unit_box(mesh: Mesh) -> Mesh:
    """Scale and shift a mesh so that its vertices span exactly [-0.5, 0.5] on x, y and z."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    if np.any(hi - lo <= 0):
        raise ValueError("a mesh with zero extent on some axis cannot fill a box")
    unit = (mesh.vertices - 0.5 * (lo + hi)) / (hi - lo)
    # Remove the last ulp of rounding so that min/max are exactly -0.5 / +0.5.
    unit[np.isclose(unit, -0.5, atol=1e-12)] = -0.5
    unit[np.isclose(unit, 0.5, atol=1e-12)] = 0.5
    return Mesh(unit, mesh.triangles, mesh.material, mesh.semantic, mesh.part)


@functools.cache
def _family(family, pose: int = 0) -> tuple[Mesh, np.ndarray, np.ndarray]:
    mesh = family(pose) if family_poses(family) > 1 else family()
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return normalise_to_unit_box(mesh), hi - lo, lo


def family_poses(family) -> int:
    """How many poses a body family has (a :class:`pipeline.world.people.PersonFamily`'s ``poses``; 1 for the
    others, which take no argument)."""
    return int(getattr(family, "poses", 1))


def family_mesh(family, pose: int = 0) -> Mesh:
    """The built-in procedural mesh of one body family (in one of its poses) in the unit box frame (vertices span
    exactly [-0.5, 0.5]^3)."""
    return _family(family, pose)[0]


def family_extent(family, pose: int = 0) -> np.ndarray:
    """(3,) float64 the family's size in metres as modelled (what its unit-box mesh was scaled by)."""
    return _family(family, pose)[1]


def family_low(family, pose: int = 0) -> np.ndarray:
    """(3,) float64 the lowest corner of the family's mesh as modelled, metres, in its modelling frame (a person's:
    the pelvis above x = y = 0, the ground at z = 0)."""
    return _family(family, pose)[2]


def canonical_mesh(object_class: ObjectClass) -> Mesh:
    """The first body family's mesh of a class, in the unit box frame."""
    return family_mesh(FAMILIES[ObjectClass(object_class)][0])


@dataclass(frozen=True)
class Model:
    """A named canonical mesh for :class:`ActorMeshes` (a user's asset, say): ``mesh`` in the unit box frame,
    spanning exactly [-0.5, 0.5] on every axis (:func:`normalise_to_unit_box`). It suits actors of any length."""

    name: str
    mesh: Mesh
    extent_m: tuple[float, float, float] | None = None  # its size as modelled, for smooth normals' crease angle


class ActorMeshes:
    """The canonical meshes (models) of every class: the built-in body families unless overridden.

    Args:
        overrides: class -> one mesh, or named models, in the unit box frame that replace all of the class's
            families.
        extra: class -> named models that join the class's families (after them), picked like them.
        families: class -> built-in families that replace FAMILIES' for the class (e.g. the people with their
            umbrella poses, :func:`umbrella_meshes`).
        Every mesh must span exactly [-0.5, 0.5] on every axis (use :func:`normalise_to_unit_box`), so that placed
        meshes fill their 3D boxes.

    Attributes:
        models: every model's mesh, classes in ObjectClass order, each class's families in FAMILIES order, then its
            extra models.
        model_class: (M,) the class of each model; model_names: (M,) its family's or model's name ("sedan", ...;
            the class's name for an override given as a bare mesh); model_extent: (M,) its size in metres as
            modelled, (3,) each (a given model's :attr:`Model.extent_m`); model_low: (M,) its lowest corner as
            modelled, (3,) each (zeros for a given model); model_pose: (M,) its pose within its family.
        families: every family slot (the built-in families, in FAMILIES order, then the given models), each with
            its models at consecutive indices, one per pose (:func:`family_poses`).
        scene_cache: per-model scenes and triangle tables, owned by the renderer (pipeline.world.scene).
    """

    def __init__(self, overrides: Mapping[ObjectClass, Mesh | Sequence[Model]] | None = None,
                 extra: Mapping[ObjectClass, Sequence[Model]] | None = None,
                 families: Mapping[ObjectClass, Sequence] | None = None) -> None:
        replaced = {ObjectClass(c): [Model(ObjectClass(c).value, m)] if isinstance(m, Mesh) else list(m)
                    for c, m in (overrides or {}).items()}
        added = {ObjectClass(c): list(m) for c, m in (extra or {}).items()}
        for object_class, models in [*replaced.items(), *added.items()]:
            if not models:
                raise ValueError(f"no models given for {object_class!s}")
            for model in models:
                lo, hi = model.mesh.vertices.min(axis=0), model.mesh.vertices.max(axis=0)
                if not (np.all(lo == -0.5) and np.all(hi == 0.5)):
                    raise ValueError(f"mesh {model.name!r} for {object_class!s} must span exactly [-0.5, 0.5]^3, "
                                     f"got {lo} .. {hi}")
        self.models: list[Mesh] = []
        self.model_class: list[ObjectClass] = []
        self.model_names: list[str] = []
        self.model_extent: list[np.ndarray] = []
        self.model_low: list[np.ndarray] = []  # as modelled (family_low); zeros for a given model
        self.model_pose: list[int] = []
        self.families: list[object] = []  # per family slot: the built-in family, or the given Model
        self._known_extent: list[bool] = []  # per model: its extent is as modelled (not the unit box's stand-in)
        # Per class code: its first family slot, and each of its families' (low, high) suitable length in metres.
        self._first = np.zeros(len(ObjectClass), np.int64)
        self._suits: list[np.ndarray] = []
        self._shares: list[np.ndarray] = []  # per class, each family's share where it is picked by one (else 0)
        first_model, poses = [], []  # per family slot
        for code, object_class in enumerate(ObjectClass):
            self._first[code] = len(self.families)
            builtin = () if object_class in replaced else (families or {}).get(object_class, FAMILIES[object_class])
            suits = [SUITS_LENGTH_M.get(f, (0.0, np.inf)) for f in builtin]
            shares = [float(getattr(f, "share", 0.0)) for f in builtin]
            for family in builtin:
                first_model.append(len(self.models))
                poses.append(family_poses(family))
                self.families.append(family)
                for pose in range(family_poses(family)):
                    self._add_model(object_class, family_mesh(family, pose), family.__name__,
                                    family_extent(family, pose), family_low(family, pose), pose, True)
            for model in replaced.get(object_class, []) + added.get(object_class, []):
                first_model.append(len(self.models))
                poses.append(1)
                self.families.append(model)
                suits.append((0.0, np.inf))
                shares.append(0.0)
                extent = np.ones(3) if model.extent_m is None else np.asarray(model.extent_m, float)
                self._add_model(object_class, model.mesh, model.name, extent, None, 0, model.extent_m is not None)
            self._suits.append(np.asarray(suits, np.float64).reshape(-1, 2))
            self._shares.append(np.asarray(shares, np.float64))
        self._family_first_model = np.asarray(first_model, np.int64)
        self._family_poses = np.asarray(poses, np.int64)
        self.scene_cache: dict[object, object] = {}  # model index -> Embree scene; "tables" -> triangle tables
        self._hulls: dict[int, np.ndarray] = {}
        self._corners: dict[int, np.ndarray] = {}
        self._parts: dict[tuple[int, int], tuple[np.ndarray, np.ndarray] | None] = {}

    def _add_model(self, object_class: ObjectClass, mesh: Mesh, name: str, extent: np.ndarray,
                   low: np.ndarray | None, pose: int, known: bool) -> None:
        """Append one model (a family's pose, or a given model: ``low`` None)."""
        self.models.append(mesh)
        self.model_class.append(object_class)
        self.model_names.append(name)
        self.model_extent.append(extent)
        self.model_low.append(np.zeros(3) if low is None else low)
        self.model_pose.append(pose)
        self._known_extent.append(known)

    def corner_normals(self, model: int) -> np.ndarray:
        """(T, 3, 3) float32 smooth shading normals per triangle corner of a model, unit-box frame
        (:func:`pipeline.world.smooth_normals.corner_normals`)."""
        if model not in self._corners:
            mesh = self.models[model]
            self._corners[model] = corner_normals(mesh.vertices, mesh.triangles, self.model_extent[model])
        return self._corners[model]

    def rider(self, model: int) -> tuple[np.ndarray, np.ndarray] | None:
        """A model's rider (its triangles of part RIDER, :attr:`pipeline.world.mesh.Mesh.part`) as a mesh of its
        own: (R, 3) float64 vertices (unit-box frame) and (S, 3) int64 triangles into them; None without one."""
        return self.part(model, RIDER)

    def cycle(self, model: int) -> tuple[np.ndarray, np.ndarray] | None:
        """A ridden model's cycle without its rider (its triangles of part BODY) as :meth:`rider` gives the rider;
        None for a model without a rider."""
        return self.part(model, BODY) if self.rider(model) is not None else None

    def part(self, model: int, part: int) -> tuple[np.ndarray, np.ndarray] | None:
        """A model's triangles of ``part`` (BODY or RIDER) as a mesh of their own: (R, 3) float64 vertices
        (unit-box frame) and (S, 3) int64 triangles into them; None where it has none."""
        if (model, part) not in self._parts:
            mesh = self.models[model]
            tris = mesh.triangles[mesh.part == part]
            used, inverse = np.unique(tris, return_inverse=True)
            self._parts[(model, part)] = ((mesh.vertices[used], inverse.reshape(-1, 3).astype(np.int64))
                                          if len(tris) else None)
        return self._parts[(model, part)]

    def hull_mask(self, model: int) -> np.ndarray:
        """(V,) bool: the vertices of a model that are not strictly inside its convex hull (Qhull's vertices and the
        points it finds coplanar with a facet). The extremes of any projection of the mesh from a point outside it,
        perspective included, lie among them."""
        if model not in self._hulls:
            from scipy.spatial import ConvexHull

            vertices = self.models[model].vertices
            hull = ConvexHull(vertices, qhull_options="Qc")
            mask = np.zeros(len(vertices), bool)
            mask[hull.vertices] = True
            mask[hull.coplanar[:, 0]] = True
            self._hulls[model] = mask
        return self._hulls[model]

    def complete(self) -> ActorMeshes:
        """Compute every model's hull mask and corner normals now (what frames otherwise compute on a model's first
        use in each process), e.g. before the meshes are cached for other processes; returns self."""
        for model in range(len(self.models)):
            self.hull_mask(model)
            self.corner_normals(model)
        return self

    def __getitem__(self, object_class: ObjectClass) -> Mesh:
        """The class's first model."""
        return self.models[int(self._first[list(ObjectClass).index(ObjectClass(object_class))])]

    def family_codes(self, actors: Actors) -> np.ndarray:
        """(N,) int64 each actor's family (index into :attr:`families`). A family with a ``share`` (the wheelchair
        users and the people pushing a pram among the pedestrians) is an actor's where an independent draw from its
        variant (:func:`actor_variants` of it, RARE_FAMILY_TAG) falls within that share; the others pick, among their
        class's other families whose length range holds the actor's length (all of them where none does), the one at
        ``variant`` modulo their number, so that a family with a share leaves every other actor's family as it was
        without it."""
        codes = actors.class_codes
        out = np.zeros(len(actors), np.int64)
        length = actors.boxes.size[:, 0] if len(actors) else np.zeros(0)
        for code in np.unique(codes):
            idx = np.flatnonzero(codes == code)
            suits, share = self._suits[code], self._shares[code]
            rare = share > 0.0
            ok = (length[idx, None] >= suits[None, :, 0]) & (length[idx, None] < suits[None, :, 1]) & ~rare[None, :]
            ok[~ok.any(axis=1)] = ~rare if (~rare).any() else True
            count = ok.sum(axis=1)
            pick = actors.variant[idx].astype(np.int64) % count  # the pick-th suitable family
            rank = np.cumsum(ok, axis=1) - 1
            family = np.argmax(ok & (rank == pick[:, None]), axis=1)
            if rare.any():
                draw = actor_variants(actors.variant[idx], RARE_FAMILY_TAG) / 2.0**32
                which = np.searchsorted(np.cumsum(share[rare]), draw, side="right")
                chosen = which < rare.sum()
                family[chosen] = np.flatnonzero(rare)[which[chosen]]
            out[idx] = self._first[code] + family
        return out

    def model_codes(self, actors: Actors) -> np.ndarray:
        """(N,) int64 each actor's model (index into :attr:`models`): its family's (:meth:`family_codes`) mesh in
        the actor's ``pose`` (modulo the family's number of poses)."""
        family = self.family_codes(actors)
        return self._family_first_model[family] + actors.pose % self._family_poses[family]

    def family_names(self, family: np.ndarray) -> np.ndarray:
        """(N,) object the names of families ``family`` (N,) (indices into :attr:`families`): a built-in family's
        ("sedan", "child_jeans", ...) or a given model's."""
        names = np.array(self.model_names, object)
        return names[self._family_first_model[np.asarray(family, np.int64)]]

    def family_persons(self, family: np.ndarray) -> np.ndarray:
        """(N,) object who the people of families ``family`` (N,) are (:class:`pipeline.core.classes.Person`'s
        values): a built-in person family's ``person``; "adult" for a pedestrian model given without a family; ""
        for every other class."""
        out = []
        for f in np.asarray(family, np.int64).tolist():
            cls = self.model_class[int(self._family_first_model[f])]
            person = getattr(self.families[f], "person", Person.ADULT)
            out.append(Person(person).value if cls is ObjectClass.PEDESTRIAN else "")
        return np.array(out, object)

    def family_poses(self, family: int) -> int:
        """How many poses family ``family`` (an index into :attr:`families`) has."""
        return int(self._family_poses[family])

    def family_models(self, family: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """(N,) int64 the models of families ``family`` (N,) in poses ``pose`` (N,) (modulo each one's count)."""
        family = np.asarray(family, np.int64)
        return self._family_first_model[family] + np.asarray(pose, np.int64) % self._family_poses[family]

    def body_lengths(self, actors: Actors) -> np.ndarray:
        """(N,) float64 the actors' box lengths as their bodies are proportioned. SUMO's length of a pedestrian
        (0.215 m) is its walking model's footprint, not the body: a walking person's stride spans about 0.8 m, a
        standing one is about 0.3 m deep, and a model stretched to 0.215 m would be squashed in a side view. For the
        classes in :data:`BODY_SIZED_CLASSES`, an actor whose model has known proportions (the built-in families; a
        given model with ``extent_m``) gets the model's length as modelled times the box's height over the model's;
        every other actor keeps its length."""
        length = np.asarray(actors.boxes.size[:, 0], np.float64).copy() if len(actors) else np.zeros(0)
        sized = np.flatnonzero(np.isin(actors.class_codes, [list(ObjectClass).index(c) for c in BODY_SIZED_CLASSES]))
        if len(sized) == 0:
            return length
        codes = self.model_codes(actors)[sized]
        extent = np.array([self.model_extent[m] for m in codes], np.float64).reshape(-1, 3)
        known = np.array([self._known_extent[m] for m in codes], bool)
        height = np.asarray(actors.boxes.size[sized, 2], np.float64)
        length[sized[known]] = extent[known, 0] * height[known] / extent[known, 2]
        return length


# Classes whose SUMO box is not the body's (see ActorMeshes.body_lengths).
BODY_SIZED_CLASSES = (ObjectClass.PEDESTRIAN,)
# Built once per installation and code version, with every model's hull and corner normals, then loaded (~50 ms
# instead of ~3.3 s of CPU per process: pipeline.core.build_cache).
DEFAULT_MESHES: ActorMeshes = cached("actor-meshes", lambda: ActorMeshes().complete())


def umbrella_meshes() -> ActorMeshes:
    """The built-in models with the people's umbrella poses too (:data:`pipeline.world.people.UMBRELLA_FAMILIES`),
    for a rain that asks for umbrellas: built (and kept in the build cache under a name of its own, so that neither
    set's file evicts the other's) only when asked for, so that a run without them holds none of those 308 meshes
    (11 more poses of each of the 28 families)."""
    global _UMBRELLA_MESHES
    if _UMBRELLA_MESHES is None:
        _UMBRELLA_MESHES = cached("umbrella-actor-meshes",
                                  lambda: ActorMeshes(families=umbrella_families()).complete())
    return _UMBRELLA_MESHES


def umbrella_families() -> dict[ObjectClass, tuple]:
    """The ``families`` argument of :class:`ActorMeshes` that gives the people their umbrella poses."""
    from pipeline.world.people import UMBRELLA_FAMILIES

    return {ObjectClass.PEDESTRIAN: UMBRELLA_FAMILIES}


_UMBRELLA_MESHES: ActorMeshes | None = None


def unit_to_world(boxes: Boxes3D) -> np.ndarray:
    """(N, 3, 4) float64 affine maps from each actor's unit box frame to the world: [R diag(size) | centre]."""
    c, s = np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad)
    out = np.zeros((len(boxes), 3, 4))
    out[:, 0, 0], out[:, 0, 1] = c * boxes.size[:, 0], -s * boxes.size[:, 1]
    out[:, 1, 0], out[:, 1, 1] = s * boxes.size[:, 0], c * boxes.size[:, 1]
    out[:, 2, 2] = boxes.size[:, 2]
    out[:, :, 3] = boxes.center
    return out


@dataclass(frozen=True)
class ActorGeometry:
    """All actors of a frame merged into one triangle soup, with per-triangle attributes.

    Attributes:
        vertices: (V, 3) float64 world positions, metres (Embree gets a float32 copy).
        triangles: (T, 3) uint32 vertex indices.
        vertex_actor: (V,) int32 dense actor index (position in :class:`Actors`) of each vertex.
        triangle_actor: (T,) int32 dense actor index of each triangle.
        triangle_material: (T,) int32 material index.
        triangle_semantic: (T,) uint8 :class:`SemanticClass` value.
        vertex_on_hull: (V,) bool, the vertex is on its model's convex hull (:meth:`ActorMeshes.hull_mask`): the
            others never bound a projection of the actor seen from outside it.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_actor: np.ndarray
    triangle_actor: np.ndarray
    triangle_material: np.ndarray
    triangle_semantic: np.ndarray
    vertex_on_hull: np.ndarray


def code_groups(codes: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    """(code, the positions (int64, ascending) that hold it) for each code >= 0 among ``codes``, codes ascending: the
    groups ``np.flatnonzero(codes == code)`` gives, from one stable sort instead of one pass over every entry per
    code (a frame's actors meet a few hundred models)."""
    codes = np.asarray(codes, np.int64)
    order = np.argsort(codes, kind="stable")
    ordered = codes[order]
    start = int(np.searchsorted(ordered, 0))
    ends = np.flatnonzero(np.diff(ordered[start:])) + 1
    for sel in np.split(order[start:], ends) if len(order) > start else ():
        yield int(codes[sel[0]]), sel


def _placed(vertices: np.ndarray, actors: Actors, idx: np.ndarray) -> np.ndarray:
    """(len(idx), V, 3) float64 the unit-frame ``vertices`` (V, 3) placed in each actor ``idx``'s box: vertex v of
    actor n at A_n @ v + t_n (:func:`unit_to_world`), as one stacked matmul (much faster than the same einsum)."""
    affine = unit_to_world(Boxes3D(actors.boxes.center[idx], actors.boxes.size[idx], actors.boxes.yaw_rad[idx]))
    return np.matmul(vertices, affine[:, :, :3].transpose(0, 2, 1)) + affine[:, None, :, 3]


def place_actors(actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, where: np.ndarray | None = None,
                 models: np.ndarray | None = None) -> ActorGeometry:
    """Scale and place every actor's canonical mesh (vectorised per model) and merge them; with ``where`` (A,) bool,
    only those actors' (their indices stay positions in ``actors``). ``models`` (A,): each actor's model, when the
    caller has :meth:`ActorMeshes.model_codes` already."""
    codes = meshes.model_codes(actors) if models is None else np.asarray(models, np.int64)
    if where is not None:
        where = np.asarray(where, bool)
        if where.shape != (len(actors),):
            raise ValueError(f"where must be ({len(actors)},) bool, one per actor; got shape {where.shape}")
        codes = np.where(where, codes, -1)
    parts: list[tuple[np.ndarray, ...]] = []
    vertex_offset = 0
    for code, idx in code_groups(codes):
        mesh = meshes.models[code]
        verts = _placed(mesh.vertices, actors, idx)
        nv, nt = len(mesh.vertices), len(mesh.triangles)
        offsets = vertex_offset + nv * np.arange(len(idx), dtype=np.int64)
        tris = mesh.triangles[None, :, :] + offsets[:, None, None]
        parts.append(
            (
                verts.reshape(-1, 3),
                tris.reshape(-1, 3),
                np.repeat(idx, nv),
                np.repeat(idx, nt),
                np.tile(mesh.material, len(idx)),
                np.tile(mesh.triangle_semantic, len(idx)),
                np.tile(meshes.hull_mask(code), len(idx)),
            )
        )
        vertex_offset += nv * len(idx)
    if not parts:
        z = np.zeros
        return ActorGeometry(z((0, 3)), z((0, 3), np.uint32), z(0, np.int32), z(0, np.int32),
                             z(0, np.int32), z(0, np.uint8), z(0, bool))
    cols = list(zip(*parts, strict=True))
    return ActorGeometry(
        np.concatenate(cols[0]),
        np.concatenate(cols[1]).astype(np.uint32),
        np.concatenate(cols[2]).astype(np.int32),
        np.concatenate(cols[3]).astype(np.int32),
        np.concatenate(cols[4]).astype(np.int32),
        np.concatenate(cols[5]),
        np.concatenate(cols[6]),
    )


def place_riders(actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, where: np.ndarray | None = None,
                 models: np.ndarray | None = None, cycles: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The riders of the actors (``where`` (A,) bool: of those only) placed as :func:`place_actors` places their
    models (:meth:`ActorMeshes.rider`; ``cycles``: their cycles without the rider, :meth:`ActorMeshes.cycle`): (V, 3)
    float64 world vertices, (T, 3) int64 triangles into them and (V,) int32 each vertex's actor; actors without a
    rider have none."""
    codes = meshes.model_codes(actors) if models is None else np.asarray(models, np.int64)
    if where is not None:
        codes = np.where(np.asarray(where, bool), codes, -1)
    vertices, triangles, owner = [np.zeros((0, 3))], [np.zeros((0, 3), np.int64)], [np.zeros(0, np.int32)]
    count = 0
    for code, idx in code_groups(codes):
        part = meshes.cycle(code) if cycles else meshes.rider(code)
        if part is None:
            continue
        verts, tris = part
        vertices.append(_placed(verts, actors, idx).reshape(-1, 3))
        triangles.append((tris[None] + (count + len(verts) * np.arange(len(idx)))[:, None, None]).reshape(-1, 3))
        owner.append(np.repeat(idx, len(verts)).astype(np.int32))
        count += len(verts) * len(idx)
    return np.concatenate(vertices), np.concatenate(triangles), np.concatenate(owner)


def rider_boxes(actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, models: np.ndarray | None = None
                ) -> tuple[np.ndarray, Boxes3D]:
    """Which actors have a rider ((A,) bool) and each rider's 3D box (A boxes; meaningful where it has one): the
    bounds of its model's rider in the actor's box frame, placed as the actor (the same yaw)."""
    codes = meshes.model_codes(actors) if models is None else np.asarray(models, np.int64)
    has = np.zeros(len(actors), bool)
    lo, hi = np.zeros((len(actors), 3)), np.zeros((len(actors), 3))
    for code in np.unique(codes).tolist():
        rider = meshes.rider(code)
        if rider is not None:
            sel = codes == code
            has[sel] = True
            lo[sel], hi[sel] = rider[0].min(axis=0), rider[0].max(axis=0)
    size = np.where(has[:, None], actors.boxes.size * (hi - lo), actors.boxes.size)  # no rider: the actor's box
    local = actors.boxes.size * 0.5 * (lo + hi)
    c, s = np.cos(actors.boxes.yaw_rad), np.sin(actors.boxes.yaw_rad)
    centre = actors.boxes.center + np.column_stack([c * local[:, 0] - s * local[:, 1],
                                                    s * local[:, 0] + c * local[:, 1], local[:, 2]])
    return has, Boxes3D(centre, size, actors.boxes.yaw_rad)


def place_hulls(actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, where: np.ndarray | None = None,
                models: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The placed vertices of :func:`place_actors` that lie on their model's convex hull (its ``vertex_on_hull``),
    without placing the others: (H, 3) float64 world positions and (H,) int32 their actors, in the order of
    :func:`place_actors`' vertices. Every actor's extremes in any direction, and the bounds of its projection seen
    from outside it, are among them; a frame needs them for every placed actor but the whole mesh for few."""
    codes = meshes.model_codes(actors) if models is None else np.asarray(models, np.int64)
    if where is not None:
        codes = np.where(np.asarray(where, bool), codes, -1)
    vertices, owner = [np.zeros((0, 3))], [np.zeros(0, np.int32)]
    for code, idx in code_groups(codes):
        hull = np.ascontiguousarray(meshes.models[code].vertices[meshes.hull_mask(code)])
        vertices.append(_placed(hull, actors, idx).reshape(-1, 3))  # row by row place_actors' numbers
        owner.append(np.repeat(idx, len(hull)).astype(np.int32))
    return np.concatenate(vertices), np.concatenate(owner)
