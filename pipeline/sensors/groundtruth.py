"""Camera ground truth computed from rays, never estimated (docs/design.md, "Ground truth is computed").

Per frame and camera, one row per actor whose own (unoccluded) projection covers at least one pixel
centre of the image:

- visible pixels: pixels whose centre ray hits the actor first (the instance image);
- tight box: from the visible pixels, continuous (x1, y1, x2, y2) with x2 = last covered column + 1;
- amodal box: bounding box of the projected mesh (vertices, plus the points where mesh edges cross the
  near plane, plus 8 samples per edge when the lens distorts straight edges), unclipped and clipped;
- unoccluded pixels: the pixels of the (clipped) amodal region whose centre ray hits the actor *alone*
  (:meth:`FrameScene.cast_alone`); visible pixels count as unoccluded by definition;
- occlusion = 1 - visible / unoccluded;
- truncation = 1 - unoccluded / full, where "full" counts the actor's pixels on a *virtual image plane*
  extending the sensor over the whole unclipped amodal box (same pixel grid, same lens model, rays cast
  against the actor alone). Off-image parts larger than a quarter image are sampled with a stride s and
  each sample weighted s*s (documented estimate; the in-image part is always exact). Parts behind the near
  plane, and virtual pixels beyond the fold of a strong distortion polynomial, are not counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.core.jit import as_input, kernel
from pipeline.sensors.camera import Camera
from pipeline.world.actors import place_actors, place_riders, rider_boxes
from pipeline.world.scene import FrameScene, make_rays, rectangles_mask

VIRTUAL_SAMPLES_PER_IMAGE = 0.25
"""Off-image parts of the virtual plane are sampled with at most this many images' worth of rays per object."""


@dataclass(frozen=True)
class AmodalBoxes:
    """Projected extent of every actor of the frame (K actors).

    Attributes:
        box: (K, 4) float64 unclipped (x1, y1, x2, y2) pixels; valid where ``valid``.
        valid: (K,) bool, some part of the actor lies in front of the near plane.
    """

    box: np.ndarray
    valid: np.ndarray

    def clipped(self, width: int, height: int) -> np.ndarray:
        """(K, 4) float64 boxes clipped to the image [0, width] x [0, height]."""
        return np.clip(self.box, 0.0, [width, height, width, height])

    def pixel_mask(self, width: int, height: int, margin_px: int = 1) -> np.ndarray:
        """(H*W,) bool row-major union of the boxes' pixels (grown by ``margin_px``): rays that may hit actors."""
        box = self.clipped(width, height)[self.valid]
        lo = np.column_stack([np.floor(box[:, 1]), np.floor(box[:, 0])]).astype(np.int64) - margin_px
        hi = np.column_stack([np.ceil(box[:, 3]), np.ceil(box[:, 2])]).astype(np.int64) + margin_px
        return rectangles_mask(height, width, lo, hi).reshape(-1)


def project_actors(scene: FrameScene, camera: Camera, cam_to_world: Transform) -> AmodalBoxes:
    """Amodal 2D boxes of all actors from their placed meshes (vectorised over all vertices).

    Actors whose bounding sphere lies outside the camera's frustum (behind the near plane or beyond the
    widest border ray) are culled first: no ray of the image can reach them, so they get no box.
    """
    k = len(scene.actors)
    world_to_cam = cam_to_world.inverse()
    centre = world_to_cam.apply(scene.actors.boxes.center)
    radius = 0.5 * np.linalg.norm(scene.actors.boxes.size, axis=1)
    near = camera.clip_near_m
    in_view = camera.spheres_in_view(centre, radius)
    left_out = np.flatnonzero(in_view & ~scene.active)
    if len(left_out):
        raise ValueError(f"camera {camera.config.name!r} sees actors {scene.actors.track_id[left_out].tolist()} (track "
                         "ids) that the frame scene left out (FrameScene active); pass a mask "
                         "from pipeline.sensors.reach.actors_in_reach with this camera")
    # An actor wholly in front of the near plane projects within the projection of its convex hull's vertices
    # (exactly: they are some of its vertices); one that crosses the plane (or any, through a distorting lens, whose
    # edges project to curves) needs all its vertices and the points where its edges cross the plane.
    whole = in_view & ((centre[:, 2] - radius > near) if not camera.has_distortion else np.zeros(k, bool))
    clipped = in_view & ~whole
    # The whole actors' hull vertices (FrameScene.hull_vertices), the others' whole meshes, placed for them only.
    on_hull = np.flatnonzero(whole[scene.hull_actor])
    geo = place_actors(scene.actors, scene.meshes, clipped) if clipped.any() else None
    verts = world_to_cam.apply(geo.vertices) if geo is not None else np.zeros((0, 3))
    tris = geo.triangles.astype(np.int64) if geo is not None else np.zeros((0, 3), np.int64)
    vertex_actor = geo.vertex_actor if geo is not None else np.zeros(0, np.int32)
    return _projected_bounds(camera, k, [world_to_cam.apply(scene.hull_vertices[on_hull])], [scene.hull_actor[on_hull]],
                             verts, tris, vertex_actor)


def project_riders(scene: FrameScene, camera: Camera, cam_to_world: Transform, where: np.ndarray,
                   cycles: bool = False) -> AmodalBoxes:
    """Amodal 2D boxes of the riders of the actors ``where`` ((K,) bool; K the frame's actors; ``cycles``: of their
    cycles without the rider): the projection of each one's rider mesh (:func:`pipeline.world.actors.place_riders`)
    as :func:`project_actors` projects a mesh that crosses the near plane (all its vertices, and the points where its
    edges cross the plane). Not valid for an actor without a rider or one left out."""
    verts, tris, owner = place_riders(scene.actors, scene.meshes, where & scene.active, scene.model_codes, cycles)
    return _projected_bounds(camera, len(scene.actors), [], [], cam_to_world.inverse().apply(verts), tris, owner)


def _projected_bounds(camera: Camera, k: int, points: list[np.ndarray], owner: list[np.ndarray], verts: np.ndarray,
                      tris: np.ndarray, vertex_actor: np.ndarray) -> AmodalBoxes:
    """The bounds of the projections of ``points`` (optical frame, each with its ``owner`` of 0..k-1, all in front
    of the near plane) and of the meshes ``verts`` (V, 3) (optical frame), ``tris`` (T, 3) int64, ``vertex_actor``
    (V,): their vertices in front of the near plane, the points where their edges cross it, and 8 samples per edge
    through a distorting lens."""
    near = camera.clip_near_m
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    z0, z1 = verts[edges[:, 0], 2], verts[edges[:, 1], 2]
    cross = (z0 > near) != (z1 > near)
    a, b = verts[edges[cross, 0]], verts[edges[cross, 1]]
    clip_pts = a + ((near - a[:, 2]) / (b[:, 2] - a[:, 2]))[:, None] * (b - a)
    points = [*points, verts, clip_pts]
    owner = [*owner, vertex_actor, vertex_actor[edges[cross, 0]]]
    if camera.has_distortion:  # straight edges project to curves: sample them
        front = (z0 > near) & (z1 > near)
        s = np.linspace(0.0, 1.0, 10)[1:-1]
        a, b = verts[edges[front, 0]], verts[edges[front, 1]]
        points.append((a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3))
        owner.append(np.repeat(vertex_actor[edges[front, 0]], len(s)))
    pts, own = np.concatenate(points), np.concatenate(owner)
    keep = pts[:, 2] >= near * (1.0 - 1e-9)
    uv, _ = camera.project(np.where(keep[:, None], pts, [[0.0, 0.0, 1.0]]))
    uv, own = uv[keep], own[keep]
    box = np.full((k, 4), np.nan)
    lo, hi = _group_bounds(as_input(own, np.int64), as_input(uv, np.float64), k)
    valid = np.isfinite(lo[:, 0])
    box[valid] = np.column_stack([lo[valid], hi[valid]])
    return AmodalBoxes(box, valid)


@dataclass(frozen=True)
class CameraLabels:
    """One row per labelled actor (N rows). Boxes are continuous pixels (x1, y1, x2, y2).

    Attributes:
        actor_index: (N,) int32 position in the frame's Actors; track_id: (N,) int32.
        center_cam: (N, 3) float64 box centre in the optical frame, metres.
        rotation_cam: (N, 3, 3) float64 rotation from the box frame (x fwd, y left, z up) to the optical frame.
        size: (N, 3) float64 (length, width, height), metres.
        box_tight: (N, 4) float64 from visible pixels; valid where ``visible``.
        box_amodal: (N, 4) float64 full projection, unclipped; box_amodal_clipped: clipped to the image.
        visible: (N,) bool, at least one visible pixel.
        visible_px, unoccluded_px: (N,) int64 pixel counts inside the image.
        full_px: (N,) float64 pixels of the whole unclipped projection (virtual image plane).
        occlusion, truncation: (N,) float32 fractions in [0, 1].
        distance_m: (N,) float32 from the optical centre to the box centre.
        rider: (N,) bool the row is the rider of the actor ``actor_index`` (its 3D box the rider's, its pixels the
            rider's, its occlusion by everything but the rider itself); these rows follow the actors'.
        box_cycle: (N, 4) float64 a ridden bicycle's or motorcycle's tight box without its rider (from its pixels
            that do not show the rider, as COCO boxes a bicycle); NaN on other rows and where none shows.
        box_cycle_amodal: (N, 4) float64 the same cycle's amodal box without its rider (the projection of its
            triangles that are not the rider's), unclipped; NaN on other rows.
    """

    actor_index: np.ndarray
    track_id: np.ndarray
    center_cam: np.ndarray
    rotation_cam: np.ndarray
    size: np.ndarray
    box_tight: np.ndarray
    box_amodal: np.ndarray
    box_amodal_clipped: np.ndarray
    visible: np.ndarray
    visible_px: np.ndarray
    unoccluded_px: np.ndarray
    full_px: np.ndarray
    occlusion: np.ndarray
    truncation: np.ndarray
    distance_m: np.ndarray
    rider: np.ndarray
    box_cycle: np.ndarray
    box_cycle_amodal: np.ndarray

    def __len__(self) -> int:
        return len(self.actor_index)


@kernel("Tuple((float64[:, ::1], float64[:, ::1]))(int64[::1], float64[:, ::1], int64)")
def _group_bounds(group, points, k):
    """Per group 0..k-1, the element-wise min and max of its (M, 2) float64 ``points`` ((M,) int64 ``group``):
    (k, 2) lo and hi, inf and -inf for an empty group, NaN where a point had NaN (as numpy's minimum / maximum)."""
    lo = np.full((k, 2), np.inf)
    hi = np.full((k, 2), -np.inf)
    for j in range(group.size):
        g = group[j]
        for c in range(2):
            v = points[j, c]
            if not np.isnan(lo[g, c]) and not lo[g, c] <= v:
                lo[g, c] = v
            if not np.isnan(hi[g, c]) and not hi[g, c] >= v:
                hi[g, c] = v
    return lo, hi


@kernel("Tuple((int64[::1], float64[:, ::1]))(int32[:, ::1], int64)")
def _pixel_boxes(instance, k):
    """Pixel counts (k,) int64 and tight boxes (k, 4) float64 (x1, y1, x2, y2: the pixels' outer edges; NaN
    where absent) of dense ids 1..k in an (H, W) int32 image (0 = none), in one pass over it."""
    count = np.zeros(k, np.int64)
    box = np.full((k, 4), np.nan)
    for y in range(instance.shape[0]):
        for x in range(instance.shape[1]):
            i = instance[y, x] - 1
            if i < 0:
                continue
            if i >= k:
                raise ValueError("an id in the image is above k")
            if count[i] == 0:
                box[i, 0], box[i, 1], box[i, 2], box[i, 3] = x, y, x + 1, y + 1
            else:
                box[i, 0] = min(box[i, 0], x)
                box[i, 2] = max(box[i, 2], x + 1)
                box[i, 3] = y + 1  # rows come in order
            count[i] += 1
    return count, box


def _grid_pairs(x0: np.ndarray, y0: np.ndarray, nx: np.ndarray, ny: np.ndarray, stride: np.ndarray) -> tuple:
    """All (object, col, row) of per-object strided pixel grids, vectorised: (obj, cols, rows) int64."""
    counts = nx * ny
    obj = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    ly, lx = np.divmod(local, nx[obj])
    return obj, x0[obj] + lx * stride[obj], y0[obj] + ly * stride[obj]


def camera_labels(scene: FrameScene, camera: Camera, cam_to_world: Transform, amodal: AmodalBoxes,
                  actor_image: np.ndarray, semantic_image: np.ndarray | None = None) -> CameraLabels:
    """Labels of one camera frame: a row per actor, then a row per rider (``rider`` set) of a bicycle or motorcycle
    in view, its pixels those of its actor that show the rider (``semantic_image`` RIDER), its unoccluded pixels and
    silhouette cast against the rider alone (:meth:`FrameScene.cast_alone_rays`), its amodal box
    :func:`project_riders`', its 3D box :func:`pipeline.world.actors.rider_boxes`'.

    Args:
        actor_image: (H, W) int32 dense actor index + 1 of the first hit per pixel centre (0 = no actor).
        semantic_image: (H, W) uint8 the semantic class of the same hits; None: no rider rows.
    """
    k = len(scene.actors)
    visible_px, tight = _pixel_boxes(as_input(actor_image, np.int32), k)
    unoccluded_px, full_px = _silhouettes(scene, camera, cam_to_world, amodal, actor_image, visible_px, tight, False)
    rows = np.flatnonzero(unoccluded_px > 0)
    has_rider, rider_box = rider_boxes(scene.actors, scene.meshes, scene.model_codes)
    riders = np.zeros(0, np.int64)
    r_amodal, r_visible, r_tight, r_unoccluded, r_full = amodal, visible_px, tight, unoccluded_px, full_px  # none
    c_tight, c_amodal = np.full((k, 4), np.nan), np.full((k, 4), np.nan)
    if semantic_image is not None and has_rider[rows].any():
        where = np.zeros(k, bool)
        where[rows[has_rider[rows]]] = True
        on_rider = semantic_image == SemanticClass.RIDER
        rider_image = np.where(on_rider, actor_image, 0).astype(np.int32)
        c_tight = np.where(where[:, None], _pixel_boxes(as_input(np.where(on_rider, 0, actor_image), np.int32), k)[1],
                           np.nan)
        c_amodal = np.where(where[:, None], project_riders(scene, camera, cam_to_world, where, cycles=True).box, np.nan)
        r_amodal = project_riders(scene, camera, cam_to_world, where)
        r_visible, r_tight = _pixel_boxes(as_input(rider_image, np.int32), k)
        r_unoccluded, r_full = _silhouettes(scene, camera, cam_to_world, r_amodal, rider_image, r_visible, r_tight,
                                            True)
        riders = np.flatnonzero(where & (r_unoccluded > 0))
    world_to_cam = cam_to_world.inverse()
    boxes = scene.actors.boxes
    index = np.concatenate([rows, riders])
    center_world = np.concatenate([boxes.center[rows], rider_box.center[riders]])
    c, s = np.cos(boxes.yaw_rad[index]), np.sin(boxes.yaw_rad[index])
    rot_world = np.zeros((len(index), 3, 3))
    rot_world[:, 0, 0], rot_world[:, 0, 1], rot_world[:, 1, 0], rot_world[:, 1, 1] = c, -s, s, c
    rot_world[:, 2, 2] = 1.0
    rot = world_to_cam.rotation @ rot_world
    center_cam = world_to_cam.apply(center_world)
    w, h = camera.width, camera.height

    def both(actor_values, rider_values):
        return np.concatenate([actor_values[rows], rider_values[riders]])

    vis, unocc, full = both(visible_px, r_visible), both(unoccluded_px, r_unoccluded), both(full_px, r_full)
    return CameraLabels(
        actor_index=index.astype(np.int32),
        track_id=scene.actors.track_id[index],
        center_cam=center_cam,
        rotation_cam=rot,
        size=np.concatenate([boxes.size[rows], rider_box.size[riders]]),
        box_tight=both(tight, r_tight),
        box_amodal=both(amodal.box, r_amodal.box),
        box_amodal_clipped=both(amodal.clipped(w, h), r_amodal.clipped(w, h)),
        visible=vis > 0,
        visible_px=vis,
        unoccluded_px=unocc,
        full_px=full,
        occlusion=(1.0 - vis / unocc).astype(np.float32),
        truncation=np.clip(1.0 - unocc / np.maximum(full, unocc), 0.0, 1.0).astype(np.float32),
        distance_m=np.linalg.norm(center_cam, axis=1).astype(np.float32),
        rider=np.arange(len(index)) >= len(rows),
        box_cycle=np.concatenate([c_tight[rows], np.full((len(riders), 4), np.nan)]),
        box_cycle_amodal=np.concatenate([c_amodal[rows], np.full((len(riders), 4), np.nan)]),
    )


def _silhouettes(scene: FrameScene, camera: Camera, cam_to_world: Transform, amodal: AmodalBoxes,
                 id_image: np.ndarray, visible_px: np.ndarray, tight: np.ndarray, rider: bool
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(unoccluded_px (K,) int64, full_px (K,) float64) of the frame's K actors (with ``rider``: of their riders)
    whose pixels are ``id_image``'s (actor index + 1), visible pixel counts and tight boxes given: the pixels of
    the (clipped) amodal region whose centre ray hits the actor (rider) alone, visible ones counted without a
    cast, and its whole silhouette on the virtual image plane (the module's docstring)."""
    w, h, k = camera.width, camera.height, len(scene.actors)
    flat = id_image.reshape(-1)
    valid = amodal.valid | (visible_px > 0)
    box = np.where(np.isnan(amodal.box), tight, amodal.box)
    box = np.column_stack([np.fmin(box[:, :2], tight[:, :2]), np.fmax(box[:, 2:], tight[:, 2:])])
    x0 = np.floor(np.where(valid, box[:, 0], 0.0)).astype(np.int64)
    y0 = np.floor(np.where(valid, box[:, 1], 0.0)).astype(np.int64)
    x1 = np.where(valid, np.ceil(box[:, 2]), 0.0).astype(np.int64)
    y1 = np.where(valid, np.ceil(box[:, 3]), 0.0).astype(np.int64)
    # In-image part, stride 1: exact unoccluded pixel counts.
    cx0, cy0, cx1, cy1 = np.clip(x0, 0, w), np.clip(y0, 0, h), np.clip(x1, 0, w), np.clip(y1, 0, h)
    obj_in, col_in, row_in = _grid_pairs(cx0, cy0, cx1 - cx0, cy1 - cy0, np.ones(k, np.int64))
    pix_in = row_in * w + col_in
    seen = flat[pix_in] == obj_in + 1  # visible pixels are unoccluded by definition: no need to cast them
    obj_cast, pix_cast = obj_in[~seen], pix_in[~seen]
    rays = make_rays(cam_to_world.translation, np.take(camera.pixel_directions, pix_cast, axis=0),
                     cam_to_world.rotation)
    alone, _ = scene.cast_alone_rays(rays, obj_cast, rider=rider)
    unoccluded_px = visible_px + np.bincount(obj_cast[alone], minlength=k)

    # Off-image part of the virtual plane, only for labelled objects reaching past the image border.
    offside = (unoccluded_px > 0) & ((x0 < 0) | (y0 < 0) | (x1 > w) | (y1 > h))
    x0, y0, x1, y1 = (np.where(offside, a, 0) for a in (x0, y0, x1, y1))
    area = (x1 - x0).astype(np.float64) * (y1 - y0)
    stride = np.maximum(1, np.ceil(np.sqrt(area / (w * h * VIRTUAL_SAMPLES_PER_IMAGE)))).astype(np.int64)
    obj_out, col_out, row_out = _grid_pairs(x0, y0, -(-(x1 - x0) // stride), -(-(y1 - y0) // stride), stride)
    outside = (col_out < 0) | (col_out >= w) | (row_out < 0) | (row_out >= h)
    obj_out, col_out, row_out = obj_out[outside], col_out[outside], row_out[outside]
    dirs_out, invertible = camera.unproject(camera.pixel_uv(col_out, row_out))
    obj_out, dirs_out = obj_out[invertible], dirs_out[invertible]  # beyond the lens fold: no ray, not counted
    rays = make_rays(cam_to_world.translation, dirs_out.astype(np.float32), cam_to_world.rotation)
    alone, _ = scene.cast_alone_rays(rays, obj_out, rider=rider)
    full_px = unoccluded_px + np.bincount(obj_out, weights=alone * stride[obj_out] ** 2, minlength=k)
    return unoccluded_px, full_px
