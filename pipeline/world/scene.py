"""Ray casting against the world of one frame: the static road scene plus the frame's actors (Embree).

Design (measured with bench/bench_render_core.py; the figures are in docs/performance.md):

- The static world is one Embree scene built once per run (:class:`StaticScene`); rebuilding a merged
  static+actor BVH every frame costs far more than casting twice.
- The actors get no Embree scene of their own (:class:`FrameScene`): an actor is its model's canonical mesh
  under an affine map, so a ray meets it where the ray mapped into the actor's unit box frame meets the canonical
  mesh, whose scene is built once per model and process (:mod:`pipeline.world.actor_casts`: candidate (ray,
  actor) pairs by an exact test against each unit box, of the actors listed for the cells of a per-frame grid that
  the ray crosses up to its static hit, then one cast per model present). Building a BVH over the
  placed actors instead cost time per triangle, every frame: more than the actor rays it served. A ray's result
  is the nearer of the static and the actor hit. Callers may pass a conservative mask of the rays that can reach
  an actor at all (from projected boxes) to skip the actor test for the rest.
- The static world is also cut into chunks (:attr:`StaticScene.chunk_boxes`: axis-aligned boxes around nearby
  triangles, tall geometry in 20 m cells, ground-level geometry in 80 m ones) so that a camera can tell from
  their projection the rays that cannot hit it (most of the sky) and skip them: a conservative test, so every
  hit is still found (``static_rays``).
- Only the actors that some ray of the frame can reach are placed and tested (``active``, from
  :func:`pipeline.sensors.reach.actors_in_reach`: a minority of an urban frame's actors), and of their meshes only
  the hull vertices (``hull_vertices``: bounds and footprints); whole meshes on demand (``geometry``).
- Sun shadow rays are tested against the actors only where they can meet one
  (:meth:`FrameScene.sun_actor_candidates`: a conservative test of the points' and the actors' projections
  along the sun; a few per cent of the lit pixels); against the static world only those from
  hits within SUN_MAP_RANGE_M (:mod:`pipeline.sensors.shadows`) whose grid cell of the static world's projection
  along the sun lies as high as they do (:class:`pipeline.world.sunmap.SunMap`), and all from farther hits.
- "Object k alone" (ground truth) is exact without building a scene per object: the placement of a
  canonical mesh is affine, so a ray transformed into the actor's unit box frame hits the cached
  canonical mesh of its model exactly where the original ray hits the placed mesh, with the same ray
  parameter t. One cast per model present covers all objects.

All positions and directions are in the world frame, metres; ``t_m`` is metres along unit directions.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import open3d as o3d

from pipeline.core.jit import as_input, as_view_input, fma32, kernel
from pipeline.world import smooth_normals
from pipeline.world.actor_casts import (
    BOX_MARGIN,
    ORIGIN_BIN_RAD,
    actor_grid,
    grid_actor_pairs,
    nearest_actor_hits,
    origin_actor_pairs,
    origin_bins,
    origin_lists,
    shared_origin,
    unit_frame_rays,
)
from pipeline.world.actors import (
    DEFAULT_MESHES,
    ActorGeometry,
    ActorMeshes,
    Actors,
    code_groups,
    place_actors,
    place_hulls,
    unit_to_world,
)
from pipeline.world.hit_attributes import resolve_hits, spread_cast
from pipeline.world.materials import TINTED_MATERIALS, material_arrays, material_index
from pipeline.world.mesh import RIDER, Mesh, triangle_bounds
from pipeline.world.sunmap import SunMap, SunTiles, sun_slope


@dataclass(frozen=True)
class Hits:
    """First hits of N rays, struct of arrays. Fields other than ``hit`` are valid only where ``hit``.

    Attributes:
        t_m: (N,) float32 distance along the (unit) ray, metres; inf where nothing was hit.
        hit: (N,) bool, the ray hit something.
        instance_id: (N,) int32 actor track id; 0 for static geometry or nothing.
        actor_index: (N,) int32 position of the hit actor in the frame's :class:`Actors`; valid where
            ``instance_id > 0`` (0 elsewhere).
        semantic: (N,) uint8 :class:`SemanticClass` value (0 = nothing).
        material: (N,) int32 material index (0 where nothing was hit).
        normal: (N, 3) float32 unit geometric normal of the hit triangle, world frame, facing the ray's origin.
        color: (N, 3) float32 linear albedo, actors' paint replaced by their colour.
    """

    t_m: np.ndarray
    hit: np.ndarray
    instance_id: np.ndarray
    actor_index: np.ndarray
    semantic: np.ndarray
    material: np.ndarray
    normal: np.ndarray
    color: np.ndarray

    def __len__(self) -> int:
        return len(self.t_m)


def _rays(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(N, 6) float32 [origin | unit direction] after checking shapes."""
    origins = np.asarray(origins, dtype=np.float32)
    directions = np.asarray(directions, dtype=np.float32)
    if origins.ndim != 2 or origins.shape[1] != 3 or directions.shape != origins.shape:
        raise ValueError(f"origins and directions must both be (N, 3); got {origins.shape} and {directions.shape}")
    rays = np.empty((len(origins), 6), np.float32)
    rays[:, :3] = origins
    norm = np.sqrt(np.einsum("ij,ij->i", directions, directions))
    if len(norm) and not np.all(norm > 0):
        raise ValueError("ray directions must be non-zero")
    np.divide(directions, norm[:, None], out=rays[:, 3:])
    return rays


_embree_started = False  # see embree_started


def embree_started() -> bool:
    """Whether this process has made an Embree scene (and so may run Embree's worker threads, which a fork of the
    process would lose: a child must then not cast)."""
    return _embree_started


def _embree(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    global _embree_started
    _embree_started = True
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.ascontiguousarray(triangles, dtype=np.uint32)),
    )
    return scene


def _occluded(scene: o3d.t.geometry.RaycastingScene, rays: np.ndarray, t_max_m: float, threads: int,
              rows: np.ndarray | None = None) -> np.ndarray:
    """Embree's occlusion test of the (N, 6) float32 ``rays``, or of those at ``rows`` only ((len(rows),) bool)."""
    picked = rays if rows is None else np.take(rays, rows, axis=0)
    return scene.test_occlusions(o3d.core.Tensor.from_numpy(picked), tfar=t_max_m, nthreads=threads).numpy()


_NO_HITS = (np.zeros(0, np.float32), np.zeros(0, np.uint32), np.zeros((0, 3), np.float32))  # a cast of no ray


def _cast(
    scene: o3d.t.geometry.RaycastingScene, rays: np.ndarray, threads: int = 0, uv: bool = False
) -> tuple[np.ndarray, ...]:
    """t (N,) float32 (inf = miss), primitive id (N,) uint32, normal (N, 3) float32 (0 on a miss); with ``uv``
    also the hits' barycentric (u, v) (N, 2) float32 (the point is (1 - u - v) p0 + u p1 + v p2)."""
    out = scene.cast_rays(o3d.core.Tensor.from_numpy(np.ascontiguousarray(rays)), nthreads=threads)
    hits = (out["t_hit"].numpy(), out["primitive_ids"].numpy(), out["primitive_normals"].numpy())
    return (*hits, out["primitive_uvs"].numpy()) if uv else hits


def rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) row-wise dot products of two (N, 3) arrays (column-wise: several times faster than einsum)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def take_columns(a: np.ndarray, rows: np.ndarray) -> list[np.ndarray]:
    """The C columns of ``a[rows]`` ((N, C) float32, M rows) as contiguous (M,) arrays: one gather of whole rows
    and one OpenCV split, several times faster than C strided gathers."""
    if not len(rows):
        return [np.zeros(0, a.dtype) for _ in range(a.shape[1])]
    return [c.reshape(-1) for c in cv2.split(np.take(a, rows, axis=0).reshape(-1, 1, a.shape[1]))]


def make_rays(origin: np.ndarray, directions: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(N, 6) float32 world rays [origin | rotation @ d] from one origin (3,) and (N, 3) float32 unit
    directions in a sensor frame rotated by ``rotation`` (3, 3) into the world.

    One compiled pass (:func:`_rays_from`) with the arithmetic of OpenCV's SIMD ``transform``, which with a merge of
    the two halves took longer. Its bytes are its own arithmetic on any processor; OpenCV's agree within rounding,
    not always in bytes: how many trailing points OpenCV leaves to a scalar loop depends on the SIMD width.
    """
    directions = as_input(np.reshape(directions, (-1, 3)), np.float32)
    return _rays_from(as_input(np.reshape(origin, 3), np.float32), directions,
                      as_input(np.reshape(rotation, (3, 3)), np.float32))


@kernel("float32[:, ::1](float32[::1], float32[:, ::1], float32[:, ::1])")
def _rays_from(origin, directions, rotation):
    """(N, 6) float32 [origin | R d] for (N, 3) float32 ``directions`` and float32 R = ``rotation``, each component
    as OpenCV's SIMD ``transform`` computes it: fma(r0, x, fma(r1, y, r2 * z)) (r the row of R)."""
    out = np.empty((directions.shape[0], 6), np.float32)
    for i in range(directions.shape[0]):
        x, y, z = directions[i, 0], directions[i, 1], directions[i, 2]
        for k in range(3):
            out[i, k] = origin[k]
            out[i, 3 + k] = fma32(rotation[k, 0], x, fma32(rotation[k, 1], y, rotation[k, 2] * z))
    return out


def rectangles_mask(rows: int, cols: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(rows, cols) bool union of K index rectangles [lo[k, 0], hi[k, 0]) x [lo[k, 1], hi[k, 1]) (each (K, 2)
    int, clipped to the grid; empty ones add nothing): e.g. the rays that may reach an actor, from its window.

    Vectorised over rectangles: +-1 at their corners, then OpenCV's 2D prefix sum (much faster than numpy's
    cumsums) counts the rectangles over each cell.
    """
    lo = np.clip(np.asarray(lo, np.int64).reshape(-1, 2), 0, [rows, cols])
    hi = np.clip(np.asarray(hi, np.int64).reshape(-1, 2), 0, [rows, cols])
    hi = np.maximum(hi, lo)
    at = np.concatenate([lo[:, 0] * (cols + 1) + lo[:, 1], lo[:, 0] * (cols + 1) + hi[:, 1],
                         hi[:, 0] * (cols + 1) + lo[:, 1], hi[:, 0] * (cols + 1) + hi[:, 1]])
    sign = np.repeat(np.array([1.0, -1.0, -1.0, 1.0], np.float32), len(lo))
    # Small integers: exact in float32.
    corners = np.bincount(at, sign, minlength=(rows + 1) * (cols + 1)).astype(np.float32).reshape(rows + 1, cols + 1)
    return cv2.integral(corners, sdepth=cv2.CV_32F)[1:rows + 1, 1:cols + 1] > 0


def _canonical_scene(meshes: ActorMeshes, model: int) -> o3d.t.geometry.RaycastingScene:
    """The Embree scene of one model's canonical mesh (an index into ``meshes.models``), cached on the library."""
    if model not in meshes.scene_cache:
        mesh = meshes.models[model]
        meshes.scene_cache[model] = _embree(mesh.vertices, mesh.triangles)
    return meshes.scene_cache[model]


def _rider_scene(meshes: ActorMeshes, model: int) -> o3d.t.geometry.RaycastingScene | None:
    """The Embree scene of one model's rider alone (its triangles of part RIDER), cached on the library; None for a
    model without a rider."""
    key = ("rider", model)
    if key not in meshes.scene_cache:
        mesh = meshes.models[model]
        rider = mesh.part == RIDER
        meshes.scene_cache[key] = _embree(mesh.vertices, mesh.triangles[rider]) if rider.any() else None
    return meshes.scene_cache[key]


@dataclass(frozen=True)
class _ClassTables:
    """Every model's canonical triangles numbered in one sequence (model by model, as ``ActorMeshes.models``):
    offsets (M,) the first number of each model, semantic (T,) uint8 (a rider's triangles RIDER) and material (T,)
    int32 per triangle."""

    offsets: np.ndarray
    semantic: np.ndarray
    material: np.ndarray


def _class_tables(meshes: ActorMeshes) -> _ClassTables:
    """The :class:`_ClassTables` of ``meshes``, cached on them."""
    if "tables" not in meshes.scene_cache:
        parts = meshes.models
        counts = np.array([len(m.triangles) for m in parts], np.int64)
        meshes.scene_cache["tables"] = _ClassTables(
            np.concatenate([[0], np.cumsum(counts)[:-1]]),
            np.concatenate([m.triangle_semantic for m in parts]),
            np.concatenate([np.asarray(m.material, np.int32) for m in parts]))
    return meshes.scene_cache["tables"]


# Chunks of the static world (StaticScene.chunk_boxes): only how tight the camera's skip test is depends on them.
CHUNK_M = 20.0  # triangles whose centres share a CHUNK_M cell get one box ...
LOW_CHUNK_M = 80.0  # ... or a LOW_CHUNK_M cell where they lie at most LOW_M above the world's lowest point:
LOW_M = 1.0  # ground, roads, markings, kerbs and barriers stay below a camera's horizon however wide their box
SUBSET_MAX = 0.8  # StaticScene.cast casts all the rays where ``where`` keeps more than this fraction of them
CHUNK_PAD_M = 1e-3  # boxes are grown by this, far beyond Embree's float32 rounding of the vertices
# The grid of FrameScene.sun_actor_candidates: only how tight that test is depends on them.
SHADOW_CELL_M = 0.5  # cells at least this wide ...
SHADOW_MAX_CELLS = 250_000  # ... and at most about this many


def chunk_boxes(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (C, 3) float64: axis-aligned boxes that together contain every triangle (T, 3) of
    ``vertices`` (V, 3), one per group of nearby triangles (see CHUNK_M); a triangle longer than its cell gets
    a box of its own, so one long ground strip does not make a tall group wide."""
    if not len(triangles):
        return np.zeros((0, 3)), np.zeros((0, 3))
    lo, hi = triangle_bounds(vertices, triangles)
    low = hi[:, 2] <= lo[:, 2].min() + LOW_M
    cell_m = np.where(low, LOW_CHUNK_M, CHUNK_M)
    cell = np.floor((lo[:, :2] + hi[:, :2]) / (2.0 * cell_m[:, None])).astype(np.int64)
    cell -= cell.min(axis=0)
    # One int64 key per triangle: its cell (and whether low), or its own index where it is alone.
    key = (cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]) * 2 + low
    alone = (hi - lo)[:, :2].max(axis=1) > cell_m
    key[alone] = key.max() + 1 + np.flatnonzero(alone)
    order = np.argsort(key, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
    box_lo = np.minimum.reduceat(lo[order], starts, axis=0)
    box_hi = np.maximum.reduceat(hi[order], starts, axis=0)
    return box_lo - CHUNK_PAD_M, box_hi + CHUNK_PAD_M


# Static materials shaded with smooth normals (pipeline.world.smooth_normals): tree crowns and trunks are coarse
# polyhedra (pipeline.world.trees) that should read as round clumps and round trunks; creases sharper than
# SMOOTH_CREASE_DEG (a conifer tier's rim) stay sharp.
SMOOTH_MATERIALS = ("foliage", "foliage_light", "foliage_dark", "bark")
SMOOTH_CREASE_DEG = 80.0


class StaticGeometry:
    """What a :class:`StaticScene` keeps of the static world besides its Embree scene: the meshes merged, with their
    materials, classes, smooth normals' corner table, chunk boxes, and the sun maps' triangle index per sun disc
    (:meth:`sun_tiles`). None of it needs Embree, so a render builds it once before its pool forks the workers
    (:func:`pipeline.stages.render_frames.prepared_state`; ~0.2-0.3 s of each worker's start-up, docs/performance.md),
    and each worker builds only its Embree scene over it. Read-only once built: a :class:`StaticScene` copies what
    it changes (its triangles' materials).

    Attributes:
        mesh_offsets: (M + 1,) int64 first merged triangle of each input mesh (input order), then T.
        num_triangles: T. vertices: (V, 3) float64 and triangles: (T, 3) int64 of the merged meshes (of the
            non-empty ones, in order). triangle_material: (T,) int32; triangle_semantic: (T,) uint8.
        smooth_row: (T,) int64 row of ``corner_normals`` per triangle (-1: shaded flat); corner_normals: (S, 3, 3)
            float32 (:func:`pipeline.world.smooth_normals.corner_normals` of the SMOOTH_MATERIALS' triangles).
        chunk_boxes: (lo, hi) (:func:`chunk_boxes`); floor_z_m: the lowest z of any vertex (inf without triangles).
    """

    def __init__(self, meshes: list[Mesh]) -> None:
        self.mesh_offsets = np.cumsum([0] + [len(m) for m in meshes]).astype(np.int64)
        self._sun_tiles: dict[bytes, SunTiles] = {}
        meshes = [m for m in meshes if len(m)]
        self.num_triangles = sum(len(m) for m in meshes)
        if meshes:
            merged = Mesh.concatenate(meshes)
            self.triangle_material = merged.material
            self.triangle_semantic = np.concatenate([np.full(len(m), int(m.semantic), np.uint8) for m in meshes])
            self.vertices, self.triangles = merged.vertices, merged.triangles
            smooth = np.flatnonzero(np.isin(merged.material, [material_index(n) for n in SMOOTH_MATERIALS]))
            self.smooth_row = np.full(self.num_triangles, -1, np.int64)  # triangle -> row of corner_normals
            self.smooth_row[smooth] = np.arange(len(smooth))
            self.corner_normals = smooth_normals.corner_normals(
                merged.vertices, merged.triangles[smooth], np.ones(3), SMOOTH_CREASE_DEG) if len(smooth) else \
                np.zeros((0, 3, 3), np.float32)
            self.chunk_boxes = chunk_boxes(merged.vertices, merged.triangles)
            self.floor_z_m = float(np.min(merged.vertices[:, 2]))
        else:
            self.floor_z_m = np.inf
            self.triangle_material = np.zeros(0, np.int32)
            self.triangle_semantic = np.zeros(0, np.uint8)
            self.vertices, self.triangles = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
            self.smooth_row, self.corner_normals = np.zeros(0, np.int64), np.zeros((0, 3, 3), np.float32)
            self.chunk_boxes = (np.zeros((0, 3)), np.zeros((0, 3)))

    def sun_tiles(self, disc: np.ndarray) -> SunTiles:
        """The :class:`pipeline.world.sunmap.SunTiles` of the triangles over the sun directions ``disc`` ((S, 3):
        a sun's disc, :func:`pipeline.sensors.shadows.sun_disc`), built on first use and kept."""
        group = np.asarray(disc, np.float64).reshape(-1, 3)
        key = group.tobytes()
        if key not in self._sun_tiles:
            self._sun_tiles[key] = SunTiles(self.vertices, self.triangles,
                                            np.array([sun_slope(d) for d in group]).reshape(-1, 2))
        return self._sun_tiles[key]


class StaticScene:
    """The static world (built once per run): all meshes merged into one Embree geometry. Hits on SMOOTH_MATERIALS
    get interpolated corner normals (as actors' do), the others their triangle's normal. ``geometry``: the
    :class:`StaticGeometry` of ``meshes``, when it was built already (else built here).

    Attributes:
        triangle_material: (T,) int32 (this scene's own copy: :meth:`set_triangle_materials` changes it);
            triangle_semantic: (T,) uint8; num_triangles: T.
        mesh_offsets: (M + 1,) int64 first merged triangle of each input mesh (input order), then T.
        chunk_boxes: (lo, hi), each (C, 3) float64 world metres: boxes that contain all the triangles
            (:func:`chunk_boxes`); a ray that meets none of them cannot hit the static world.
        floor_z_m: the lowest z of any vertex, metres (inf without triangles).
    """

    def __init__(self, meshes: list[Mesh], geometry: StaticGeometry | None = None) -> None:
        geometry = StaticGeometry(meshes) if geometry is None else geometry
        if len(geometry.mesh_offsets) != len(meshes) + 1 or geometry.num_triangles != sum(len(m) for m in meshes):
            raise ValueError(f"the static geometry holds {len(geometry.mesh_offsets) - 1} meshes of "
                             f"{geometry.num_triangles} triangles, not these {len(meshes)} meshes")
        self._geometry = geometry
        self.mesh_offsets, self.num_triangles = geometry.mesh_offsets, geometry.num_triangles
        self._sun_maps: dict[tuple[float, ...], SunMap] = {}  # see sun_candidates
        self.triangle_material = geometry.triangle_material.copy()
        self.triangle_semantic = geometry.triangle_semantic
        self._vertices, self._triangles = geometry.vertices, geometry.triangles
        self._smooth_row, self._corner_normals = geometry.smooth_row, geometry.corner_normals
        self.chunk_boxes, self.floor_z_m = geometry.chunk_boxes, geometry.floor_z_m
        self._scene = _embree(self._vertices, self._triangles) if self.num_triangles else None

    def set_triangle_materials(self, mesh_index: int, triangles: np.ndarray, material: np.ndarray | int) -> None:
        """Change the material of some triangles of input mesh ``mesh_index`` (indices within that mesh), e.g.
        the signal lamps' state per frame; the geometry, and so the Embree scene, stays as built."""
        triangles = np.asarray(triangles, dtype=np.int64)
        start, stop = self.mesh_offsets[mesh_index], self.mesh_offsets[mesh_index + 1]
        if len(triangles) and (triangles.min() < 0 or triangles.max() >= stop - start):
            raise ValueError(f"triangle indices out of range for mesh {mesh_index} of {stop - start} triangles")
        self.triangle_material[start + triangles] = material

    def cast(
        self, rays: np.ndarray, threads: int = 0, where: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw cast of (N, 6) float32 rays: t (inf = miss), primitive id (Embree's invalid id on a miss),
        normal (0 on a miss). ``where`` (N,) bool, optional: cast only these rays; the others are reported as
        misses, so it must contain every ray that can hit (e.g. from :attr:`chunk_boxes`)."""
        n = len(rays)
        if self._scene is not None and (where is None or np.count_nonzero(where) > SUBSET_MAX * n):
            # All the rays: gathering and scattering would cost more than they save.
            return self._smoothed(rays, *_cast(self._scene, rays, threads, uv=True))
        sub = np.flatnonzero(where) if self._scene is not None else np.zeros(0, np.int64)
        if not len(sub):
            return spread_cast(n, sub, *_NO_HITS)
        picked = np.take(rays, sub, axis=0)
        return spread_cast(n, sub, *self._smoothed(picked, *_cast(self._scene, picked, threads, uv=True)))

    def _smoothed(self, rays: np.ndarray, t: np.ndarray, prim: np.ndarray, normal: np.ndarray, uv: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, prim, normal) of a cast of ``rays``, the normals of hits on smooth triangles interpolated."""
        if not len(self._corner_normals):
            return t, prim, normal
        hit = np.flatnonzero(np.isfinite(t))
        row = self._smooth_row[prim[hit]]
        on = hit[row >= 0]
        if len(on):
            normal[on] = smooth_normals.interpolated(as_input(self._corner_normals, np.float32),
                                                     as_input(row[row >= 0], np.int64),
                                                     as_input(uv[on], np.float32), as_input(normal[on], np.float32),
                                                     as_input(rays[on, 3:], np.float32))
        return t, prim, normal

    def occluded(self, rays: np.ndarray, t_max_m: float, threads: int = 0, where: np.ndarray | None = None
                 ) -> np.ndarray:
        """(N,) bool: the static world lies on each of the (N, 6) float32 rays within ``t_max_m``. ``where`` (N,)
        bool, optional: test only these rays; the others are reported clear, so it must contain every ray that can
        be blocked (e.g. :meth:`sun_candidates`)."""
        if self._scene is None:
            return np.zeros(len(rays), bool)
        if where is None:
            return _occluded(self._scene, rays, t_max_m, threads)
        blocked = np.zeros(len(rays), bool)
        sub = np.flatnonzero(where)
        if len(sub):
            blocked[sub] = _occluded(self._scene, rays, t_max_m, threads, sub)
        return blocked

    def sun_candidates(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, sun: np.ndarray,
                       rows: np.ndarray | None = None, disc: np.ndarray | None = None) -> np.ndarray:
        """(M,) bool, conservative: which rays from the world points (x, y, z) (each (N,) float32) along the upward
        unit direction ``sun`` (3,) may meet the static world (:class:`pipeline.world.sunmap.SunMap`, one per sun
        direction, its tiles drawn as points fall in them and kept for the next frames); of the points ``rows``
        ((M,) int64) only, if given. ``disc`` ((S, 3), optional): the directions ``sun`` is one of (a sun's disc),
        whose maps share one index of the triangles per tile (:class:`pipeline.world.sunmap.SunTiles`)."""
        key = tuple(np.asarray(sun, np.float64).tolist())
        if key not in self._sun_maps:
            index = None if disc is None else self._geometry.sun_tiles(disc)
            self._sun_maps[key] = SunMap(self._vertices, self._triangles, np.asarray(sun, np.float64), index)
        return self._sun_maps[key].candidates(x, y, z, rows)


ORIGIN_MIN_RAYS = 1000  # rays from one origin worth a frame's lists of directions (a few ms to build)


class FrameScene:
    """The world of one frame: a :class:`StaticScene` (shared) plus the frame's actors (one merged geometry).

    ``meshes`` chooses the canonical mesh per class (the built-in procedural ones by default); ``threads``
    caps Embree's threads per cast (0 = all cores; use 1 per worker in a process pool to avoid
    oversubscription). ``active`` (A,) bool, optional: the actors that rays may reach (a conservative mask, e.g.
    :func:`pipeline.sensors.reach.actors_in_reach`); only they are placed (``geometry``) and met by the rays of
    :meth:`cast_rays` and :meth:`occluded_rays`. The others stay in ``actors`` and :meth:`cast_alone` still sees
    them.
    """

    def __init__(
        self, static: StaticScene, actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, threads: int = 0,
        active: np.ndarray | None = None,
    ) -> None:
        if threads < 0:
            raise ValueError(f"threads must be >= 0 (0 = all cores), got {threads}")
        self.threads = threads
        self.static = static
        self.actors = actors
        self.meshes = meshes
        self.active = np.ones(len(actors), bool) if active is None else np.asarray(active, bool)
        if self.active.shape != (len(actors),):
            raise ValueError(f"active must be ({len(actors)},) bool, one per actor; got shape {self.active.shape}")
        self._model = meshes.model_codes(actors)
        # The placed actors' hull vertices (every actor's extremes, in any direction): what the frame's tests and
        # amodal boxes need; whole meshes are placed only on demand (geometry).
        self.hull_vertices, self.hull_actor = place_hulls(actors, meshes, self.active, self._model)
        self._placed = np.flatnonzero(self.active)  # the actors rays can meet (each as its model's canonical mesh)
        mats = material_arrays()
        self._albedo = as_input(mats["albedo"], np.float32)
        tinted = [material_index(n) for n in TINTED_MATERIALS]  # their colour is the actor's
        self._tinted = as_input(np.isin(np.arange(len(mats["albedo"])), tinted), np.bool_)
        self._actor_color = as_input(actors.color_rgb, np.float32)
        # Precompute the inverse placement of each actor: p_unit = A^-1 (p - centre).
        affine = unit_to_world(actors.boxes)
        self._inv_linear = as_input(np.linalg.inv(affine[:, :, :3]) if len(actors) else np.zeros((0, 3, 3)),
                                    np.float64)
        self._center = as_input(affine[:, :, 3], np.float64)
        # Holds the unit box grown by BOX_MARGIN: half its diagonal, grown, and a little more for rounding.
        self._radius = as_input(0.5 * np.linalg.norm(actors.boxes.size, axis=1) * (1.0 + 2.0 * BOX_MARGIN) + 1e-6,
                                np.float64)
        self._top_z = float(self.hull_vertices[:, 2].max()) if len(self.hull_vertices) else -np.inf
        self._footprints: dict[tuple[float, ...], tuple[np.ndarray, np.ndarray]] = {}  # see _sun_footprints
        self._grid: tuple | None = None  # see _pairs
        self._origin_lists: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}  # see _pairs

    @property
    def model_codes(self) -> np.ndarray:
        """(A,) int64 each actor's model (:meth:`ActorMeshes.model_codes`)."""
        return self._model

    @functools.cached_property
    def geometry(self) -> ActorGeometry:
        """The placed (``active``) actors' whole meshes merged (:func:`pipeline.world.actors.place_actors`), placed on
        first use: the frame's casts need none of it (each actor is its model's canonical mesh), its tests and boxes
        only the hull vertices (``hull_vertices`` (H, 3) float64, ``hull_actor`` (H,) int32: those of ``geometry``
        on the hull, in its order)."""
        return place_actors(self.actors, self.meshes, self.active, self._model)

    def cast(self, origins: np.ndarray, directions: np.ndarray, actor_rays: np.ndarray | None = None) -> Hits:
        """First hits of rays: (N, 3) world origins and directions (normalised here). See :meth:`cast_rays`."""
        return self.cast_rays(_rays(origins, directions), actor_rays)

    def cast_rays(
        self, rays: np.ndarray, actor_rays: np.ndarray | None = None, static_rays: np.ndarray | None = None
    ) -> Hits:
        """First hits of (N, 6) float32 rays [origin | unit direction] (world; directions are trusted unit).

        ``actor_rays`` (N,) bool, optional: a conservative mask of the rays that may hit an actor; the
        others skip the actor cast. Without it every ray is cast against the actors. ``static_rays`` likewise
        for the static world (e.g. :meth:`pipeline.sensors.camera.Camera.boxes_pixel_mask` of its
        :attr:`StaticScene.chunk_boxes`).
        """
        n = len(rays)
        rays = as_input(rays, np.float32)
        t, prim, normal = self.static.cast(rays, self.threads, static_rays)
        sub = np.zeros(0, np.int64)
        if len(self._placed):
            sub = np.arange(n) if actor_rays is None else np.flatnonzero(actor_rays)
        # An actor hit counts only where it is nearer than the static one (resolve_hits): the static hit bounds the
        # span of each ray that the actors are tested in.
        t_actor, prim_actor, normal_actor, hit_actor = self._cast_actors(rays, sub, t[sub].astype(np.float64))
        hit, instance_id, actor_index = np.zeros(n, bool), np.zeros(n, np.int32), np.zeros(n, np.int32)
        semantic, material, color = np.zeros(n, np.uint8), np.zeros(n, np.int32), np.zeros((n, 3), np.float32)
        static, tables = self.static, _class_tables(self.meshes)
        resolve_hits(rays, t, prim, normal, as_input(static.triangle_semantic, np.uint8),
                     as_input(static.triangle_material, np.int32), self._albedo, sub, t_actor, prim_actor,
                     normal_actor, hit_actor, tables.semantic, tables.material,
                     as_input(self.actors.track_id, np.int32), self._actor_color, self._tinted,
                     hit, instance_id, actor_index, semantic, material, color)
        return Hits(t, hit, instance_id, actor_index, semantic, material, normal, color)

    def cast_alone(
        self, origins: np.ndarray, directions: np.ndarray, actor_index: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Cast each ray against one actor alone (nothing else in the world).

        Args:
            origins, directions: (N, 3) world rays (directions normalised here).
            actor_index: (N,) int, the actor (position in :class:`Actors`) each ray is tested against.

        Returns:
            hit (N,) bool and t_m (N,) float32 metres (inf where not hit).
        """
        return self.cast_alone_rays(_rays(origins, directions), actor_index)

    def cast_alone_rays(self, rays: np.ndarray, actor_index: np.ndarray, rider: bool = False
                        ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cast_alone` for prebuilt (N, 6) float32 rays [origin | unit direction]; with ``rider``, against
        each actor's rider alone (nothing hit for an actor without one)."""
        actor_index = np.asarray(actor_index, dtype=np.int64).reshape(-1)
        if len(actor_index) != len(rays):
            raise ValueError(f"{len(actor_index)} actor indices for {len(rays)} rays")
        if len(actor_index) and (actor_index.min() < 0 or actor_index.max() >= len(self.actors)):
            raise ValueError(f"actor_index out of range for {len(self.actors)} actors")
        t = np.full(len(rays), np.inf, np.float32)
        local = unit_frame_rays(as_input(rays, np.float32), actor_index, self._inv_linear, self._center)
        for model, sel in self._pairs_by_model(actor_index):
            # Directions stay non-unit in the unit box frame, so t is still in world metres.
            scene = _rider_scene(self.meshes, model) if rider else _canonical_scene(self.meshes, model)
            if scene is not None:
                t[sel] = _cast(scene, np.take(local, sel, axis=0), self.threads)[0]
        return np.isfinite(t), t

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max_m: float = np.inf) -> np.ndarray:
        """(N,) bool: something (static or actor) lies on each ray within ``t_max_m`` (shadow rays)."""
        return self.occluded_rays(_rays(origins, directions), t_max_m)

    def occluded_rays(self, rays: np.ndarray, t_max_m: float = np.inf, actor_rays: np.ndarray | None = None,
                      static_rays: np.ndarray | None = None, toward: tuple[np.ndarray, float] | None = None
                      ) -> np.ndarray:
        """:meth:`occluded` for prebuilt (N, 6) float32 rays [origin | unit direction]. ``actor_rays`` (N,) bool,
        optional: a conservative mask of the rays that may meet an actor (e.g. :meth:`sun_actor_candidates`); the
        others are tested against the static world only. ``static_rays`` likewise for the static world (e.g.
        :meth:`StaticScene.sun_candidates`). ``toward`` (q (3,), s metres), optional: every ray up to ``t_max_m``
        stays within s of the line from the point q through its origin (segments towards one lamp): their actors are
        found from lists of direction bins about q (:meth:`_pairs`)."""
        blocked = self.static.occluded(rays, t_max_m, self.threads, static_rays)
        if not len(self._placed):
            return blocked
        sub = np.flatnonzero(~blocked if actor_rays is None else actor_rays & ~blocked)
        rays = as_input(rays, np.float32)
        # Segments (sky occlusion, shadows towards a lamp) test only the actors of the grid cells they cross.
        # Short ones (a pixel's sky-occlusion rays share an origin) take the actors within their reach of it, once;
        # those towards one point (``toward``), the actors of their direction's bin about it.
        pair_row, pair_actor, local = self._pairs(rays, sub, np.full(len(sub), float(t_max_m)), near=True,
                                                  toward=toward)
        hit_pair = np.zeros(len(pair_row), bool)
        for model, sel in self._pairs_by_model(pair_actor):
            # t along the unit-frame ray is in world metres, so t_max_m applies as it is.
            hit_pair[sel] = _occluded(_canonical_scene(self.meshes, model), local, t_max_m, self.threads, sel)
        blocked[sub[pair_row[hit_pair]]] = True
        return blocked

    def _pairs_by_model(self, pair_actor: np.ndarray):
        """(model, the positions (int64) of that model's entries) for each model among the actors ``pair_actor``."""
        return code_groups(self._model[pair_actor])

    def _pairs(self, rays: np.ndarray, sub: np.ndarray, t_limit: np.ndarray, near: bool = False,
               toward: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, ...]:
        """:func:`pipeline.world.actor_casts.actor_pairs` of the rays ``sub`` of the (N, 6) float32 ``rays`` and
        the placed actors, less the pairs that cannot be hit at t <= ``t_limit`` ((K,) float64, inf: no limit), each
        ray tested only against the actors of the grid cells it crosses (:func:`grid_actor_pairs`; the grid is
        built once per frame). With ``near`` (occlusion tests only: it may keep a pair entered just beyond the
        limit), a ray that reaches no farther than a cell takes the actors within its reach of its origin. Many
        rays from one origin (a camera's, a LiDAR's) take instead the actors listed for their direction's bin
        (:func:`origin_actor_pairs`; the lists built once per frame and origin): the same pairs, without walking
        the grid. Many segments that end near one point (``toward``: the point q and how far, s, each may stray from
        the line from q through its origin; with ``near`` only) take the actors listed for the bin of their origin's
        direction from q, in lists built at q with every sphere grown by s: the walk's pairs, and possibly some
        entered between the limit and its margin, as ``near`` keeps them."""
        if not len(self._placed) or not len(sub):
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 6), np.float32)
        sub = as_input(sub, np.int64)
        bins = None
        if near and toward is not None and len(sub) >= ORIGIN_MIN_RAYS:
            point, stray = np.asarray(toward[0], np.float64).reshape(3), float(toward[1])
            key = ("toward", *point.tolist(), stray)
            if key not in self._origin_lists:
                self._origin_lists[key] = origin_lists(*point.tolist(), self._placed, self._center,
                                                       self._radius + stray, ORIGIN_BIN_RAD, *origin_bins())
            bins = self._origin_lists[key], point
        elif not near and len(sub) >= ORIGIN_MIN_RAYS and shared_origin(rays, sub):
            origin = tuple(float(v) for v in rays[sub[0], :3])
            if origin not in self._origin_lists:
                self._origin_lists[origin] = origin_lists(*origin, self._placed, self._center, self._radius,
                                                          ORIGIN_BIN_RAD, *origin_bins())
            bins = self._origin_lists[origin], np.full(3, np.nan)
        if bins is not None:
            return origin_actor_pairs(rays, sub, self._placed, self._inv_linear, self._center, self._radius,
                                      as_input(t_limit, np.float64), ORIGIN_BIN_RAD, *origin_bins(), *bins[0],
                                      bins[1])
        if self._grid is None:
            self._grid = actor_grid(self._center, self._radius, self._placed)
        return grid_actor_pairs(rays, sub, self._placed, self._inv_linear, self._center,
                                self._radius, as_input(t_limit, np.float64), *self._grid,
                                self._grid[2] if near else 0.0)

    def _cast_actors(self, rays: np.ndarray, sub: np.ndarray, t_limit: np.ndarray) -> tuple[np.ndarray, ...]:
        """The nearest actor hit of each ray ``sub`` of the (N, 6) float32 ``rays`` where it may lie at t <=
        ``t_limit`` ((K,) float64; a hit found farther may be reported or not): t (K,) float32 (inf = none), triangle
        (K,) uint32 (numbered as in :func:`_class_tables`), world normal (K, 3) float32 and actor (K,) int32 (see
        :mod:`pipeline.world.actor_casts`)."""
        pair_row, pair_actor, local = self._pairs(rays, sub, t_limit)
        t = np.full(len(pair_row), np.inf, np.float32)
        prim = np.zeros(len(pair_row), np.uint32)
        normal = np.zeros((len(pair_row), 3), np.float32)
        offsets = _class_tables(self.meshes).offsets
        for model, sel in self._pairs_by_model(pair_actor):
            scene = _canonical_scene(self.meshes, model)
            model_rays = np.take(local, sel, axis=0)
            t[sel], model_prim, face, uv = _cast(scene, model_rays, self.threads, uv=True)
            # Shading normals: the model's corner normals interpolated at the hits (pipeline.world.smooth_normals).
            hit = np.flatnonzero(np.isfinite(t[sel]))
            face[hit] = smooth_normals.interpolated(as_input(self.meshes.corner_normals(model), np.float32),
                                                    as_input(model_prim[hit], np.int64), as_input(uv[hit], np.float32),
                                                    as_input(face[hit], np.float32),
                                                    as_input(model_rays[hit, 3:], np.float32))
            normal[sel] = face
            prim[sel] = model_prim + np.uint32(offsets[model])  # hits only are read
        return nearest_actor_hits(len(sub), pair_row, pair_actor, t, prim, normal, self._inv_linear)

    def sun_actor_candidates(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, sun: np.ndarray) -> np.ndarray:
        """(M,) bool, conservative: which rays from the world points (x, y, z) (each (M,) float32) along the upward
        unit direction ``sun`` (3,) may meet an actor; the others cannot (a mask for :meth:`occluded_rays`).

        Along ``sun``, a point p projects onto the plane z = 0 at p_xy - p_z * sun_xy / sun_z, and so does every
        point of its ray: a ray that meets an actor projects inside the projection of that actor's vertices, and
        so inside their 2D bounding box. Those boxes are marked on a grid over the points' projections (cells of
        at least SHADOW_CELL_M; each box grown by a cell, far beyond rounding) and each point looks up its cell. A
        point above every actor's highest vertex is no candidate: its ray only rises.
        """
        return self._footprint_candidates(x, y, z, sun_slope(sun), 0.0)

    def near_actors(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, radius_m: float) -> np.ndarray:
        """(M,) bool, conservative: which world points (x, y, z) (each (M,) float32) lie within ``radius_m`` of a
        placed actor's footprint (the 2D bounds of its vertices, grown by ``radius_m``) and no higher than
        ``radius_m`` above the actors' highest vertex; the others are farther from every actor (e.g. their sky
        occlusion rays of that length cannot meet one)."""
        return self._footprint_candidates(x, y, z, np.zeros(2), float(radius_m))

    def sun_disc_actor_candidates(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, suns: np.ndarray,
                                  which: np.ndarray) -> np.ndarray:
        """:meth:`sun_actor_candidates` of rays along several directions: the ray from point j along ``suns[which[j]]``
        ((S, 3) upward unit directions, ``which`` (M,) int64), all looked up in one grid, on which each actor's box is
        the union of its boxes along the S directions (a superset of each direction's: still conservative). One grid
        instead of S: the directions over the sun's disc differ by a fraction of a degree."""
        which = np.asarray(which, np.int64)
        groups = [(sun_slope(sun), np.flatnonzero(which == k)) for k, sun in enumerate(np.asarray(suns))]
        return self._footprint_candidates(x, y, z, None, 0.0, [(g, rows) for g, rows in groups if len(rows)])

    def _footprint_candidates(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, slope: np.ndarray | None,
                              grow_m: float, groups: list[tuple[np.ndarray, np.ndarray]] | None = None) -> np.ndarray:
        """:meth:`sun_actor_candidates` for the sun's ``slope`` (:func:`sun_slope`; 0 = straight up), the actors'
        projected bounds and their top grown by ``grow_m``; or, with ``groups`` ((slope, rows (K,) int64) pairs that
        share out the points), each group's points along its own slope, on one grid of the union of the groups'
        actor bounds."""
        if not len(self._placed) or not len(x):
            return np.zeros(len(x), bool)
        # float32: rounding (~1e-4 m at 2 km) is far below the cell the boxes are grown by.
        x, y, z = (as_view_input(c, np.float32) for c in (x, y, z))
        if groups is None:
            groups, whole = [(np.asarray(slope, np.float64), None)], True
        else:
            whole = False
        if not groups:
            return np.zeros(len(x), bool)
        lo, hi = self._sun_footprints(np.array([np.asarray(g, np.float64) for g, _ in groups]))
        bounds = []
        for g_slope, rows in groups:
            sx, sy = np.asarray(g_slope, np.float32)
            picked = (x, y, z) if whole else (x[rows], y[rows], z[rows])
            bounds.append((picked, sx, sy, _projection_bounds(*picked, sx, sy)))
        lo, hi = lo - grow_m, hi + grow_m
        all_bounds = np.array([b[3] for b in bounds], np.float32)
        p_lo = np.minimum.reduce(all_bounds[:, :2]).astype(np.float64)
        p_hi = np.maximum.reduce(all_bounds[:, 2:]).astype(np.float64)
        near = np.flatnonzero(np.all(hi >= p_lo, axis=1) & np.all(lo <= p_hi, axis=1))
        if not len(near):
            return np.zeros(len(x), bool)
        cell = max(SHADOW_CELL_M, float(np.sqrt(np.prod(p_hi - p_lo + SHADOW_CELL_M) / SHADOW_MAX_CELLS)))
        n_rows, n_cols = (np.floor((p_hi - p_lo) / cell).astype(np.int64) + 1).tolist()
        # Cell (i, j) covers [p_lo + (i, j) * cell, p_lo + (i + 1, j + 1) * cell).
        grid = rectangles_mask(n_rows, n_cols, np.floor((lo[near] - p_lo) / cell).astype(np.int64) - 1,
                               np.floor((hi[near] - p_lo) / cell).astype(np.int64) + 2)
        lookup = (np.float32(p_lo[0]), np.float32(p_lo[1]), np.float32(1.0 / cell), grid,
                  np.float32(self._top_z + grow_m + CHUNK_PAD_M))
        if whole:
            picked, sx, sy, _ = bounds[0]
            return _in_marked_cells(*picked, sx, sy, *lookup)
        out = np.zeros(len(x), bool)
        for (_, rows), (picked, sx, sy, _) in zip(groups, bounds, strict=True):
            out[rows] = _in_marked_cells(*picked, sx, sy, *lookup)
        return out

    def _sun_footprints(self, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (A, 2): 2D bounds of each actor's vertices projected onto z = 0 along every sun whose slope
        (:func:`sun_slope`) lies in the box of the (S, 2) ``slopes`` (one sun, or the sun's disc), in one pass
        (:func:`_run_bounds_along_suns`: the same bits as one pass per slope and their union); computed once per
        set of suns and frame."""
        lo_s, hi_s = slopes.min(axis=0), slopes.max(axis=0)
        key = (*lo_s.tolist(), *hi_s.tolist())
        if key not in self._footprints:
            # Each actor's vertices are one run (place_hulls): bounds per run.
            starts = np.flatnonzero(np.r_[True, np.diff(self.hull_actor) != 0])
            self._footprints[key] = _run_bounds_along_suns(self.hull_vertices, starts, *lo_s, *hi_s)
        return self._footprints[key]


@kernel("float32[::1](float32[:], float32[:], float32[:], float32, float32)")
def _projection_bounds(x, y, z, sx, sy):
    """[min px, min py, max px, max py] (float32) of the points (x, y, z) projected along the sun (slope (sx,
    sy)) onto z = 0 (:func:`pipeline.world.sunmap.along_sun`, in float32)."""
    out = np.empty(4, np.float32)
    out[0] = out[1] = np.inf
    out[2] = out[3] = -np.inf
    for i in range(x.size):
        px = x[i] - z[i] * sx
        py = y[i] - z[i] * sy
        out[0] = min(out[0], px)
        out[1] = min(out[1], py)
        out[2] = max(out[2], px)
        out[3] = max(out[3], py)
    return out


@kernel("bool_[::1](float32[:], float32[:], float32[:], float32, float32, float32, float32, float32, bool_[:, ::1], "
        "float32)")
def _in_marked_cells(x, y, z, sx, sy, x0, y0, scale, grid, top_z):
    """(N,) bool: the point's projection along the sun (slope (sx, sy)) falls in a marked cell of ``grid`` (cells
    ``1 / scale`` wide from (x0, y0), the projections' lower bounds; the last row and column take what rounding
    puts past them) and the point lies no higher than ``top_z``."""
    rows, cols = grid.shape
    out = np.empty(x.size, np.bool_)
    for k in range(x.size):
        i = min(np.int64(np.int32((x[k] - z[k] * sx - x0) * scale)), rows - 1)
        j = min(np.int64(np.int32((y[k] - z[k] * sy - y0) * scale)), cols - 1)
        out[k] = grid[i, j] and z[k] <= top_z
    return out


@kernel("Tuple((float64[:, ::1], float64[:, ::1]))(float64[:, ::1], int64[::1], float64, float64, float64, float64)")
def _run_bounds_along_suns(vertices, starts, sx_lo, sy_lo, sx_hi, sy_hi):
    """(lo, hi), each (R, 2) float64: the bounds of each run of the (V, 3) float64 ``vertices`` (run r from
    ``starts[r]`` to the next start) projected along every sun of slope in [sx_lo, sx_hi] x [sy_lo, sy_hi] onto
    z = 0, each point as :func:`pipeline.world.sunmap.along_sun` computes it (x - z sx, y - z sy); a vertex's extremes
    lie at the end of the slopes' range that its z (its sign) picks. One pass instead of two vertex-sized columns and
    two reductions per sun direction; one sun: equal ends."""
    r_count = starts.size
    lo = np.empty((r_count, 2))
    hi = np.empty((r_count, 2))
    for r in range(r_count):
        end = starts[r + 1] if r + 1 < r_count else vertices.shape[0]
        lx, ly, hx, hy = np.inf, np.inf, -np.inf, -np.inf
        for v in range(starts[r], end):
            x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
            up = z > 0
            lx = min(lx, x - z * (sx_hi if up else sx_lo))
            hx = max(hx, x - z * (sx_lo if up else sx_hi))
            ly = min(ly, y - z * (sy_hi if up else sy_lo))
            hy = max(hy, y - z * (sy_lo if up else sy_hi))
        lo[r, 0], lo[r, 1], hi[r, 0], hi[r, 1] = lx, ly, hx, hy
    return lo, hi

