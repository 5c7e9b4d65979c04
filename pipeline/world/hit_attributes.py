"""What a ray hit, from the raw casts against the static world and the actors: compiled passes over the rays.

:meth:`pipeline.world.scene.FrameScene.cast_rays` casts every ray against the static world and some against the
frame's actors; :func:`resolve_hits` keeps the nearer hit of each ray and reads the hit triangle's semantic class,
material and albedo (an actor's paint or garment: its own colour), and turns the normal towards the ray's origin. In
numpy this took a dozen image-sized temporaries; compiled (:mod:`pipeline.core.jit`), one pass over the rays.
:func:`spread_cast` puts a cast of some of the rays back in place among all of them.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import kernel


@kernel("void(float32[:, ::1], float32[::1], uint32[::1], float32[:, ::1], uint8[::1], int32[::1], float32[:, ::1], "
        "int64[::1], float32[::1], uint32[::1], float32[:, ::1], int32[::1], uint8[::1], int32[::1], int32[::1], "
        "float32[:, ::1], bool_[::1], "
        "bool_[::1], int32[::1], int32[::1], uint8[::1], int32[::1], float32[:, ::1])")
def resolve_hits(rays, t, prim, normal, static_semantic, static_material, albedo,
                 sub, t_actor, prim_actor, normal_actor, hit_actor, actor_semantic, actor_material, track_id,
                 actor_color, tinted,
                 hit, instance_id, actor_index, semantic, material, color):
    """Merge the casts of N rays and fill their attributes, in place.

    Args:
        rays: (N, 6) float32 [origin | unit direction].
        t, prim, normal: the static cast, (N,) float32 (inf = miss), (N,) uint32 triangle, (N, 3) float32 normal
            (Embree's winding; 0 on a miss). On return: the nearer of the two casts, normals facing the origin.
        static_semantic, static_material: (T,) uint8 and int32, per static triangle.
        albedo: (M, 3) float32 linear albedo per material.
        sub: (K,) int64 the rays cast against the actors, and t_actor, prim_actor, normal_actor their cast as above
            (the normal in the world frame), hit_actor (K,) int32 the actor hit (position in the frame's actors).
        actor_semantic, actor_material: (U,) uint8 and int32 per actor triangle (as numbered in ``prim_actor``).
        track_id: (A,) int32 per actor; actor_color: (A, 3) float32 linear colour, which replaces the albedo of
            the materials where ``tinted`` ((M,) bool) is set (``paint``, ``garment``).
        hit, instance_id, actor_index, semantic, material, color: outputs, (N,) bool, int32, int32, uint8, int32
            and (N, 3) float32 arrays of zeros (False): written where a ray hit (instance id and actor index where
            it hit an actor), left as they are elsewhere.
    """
    for i in range(t.size):
        if t[i] < np.inf:
            hit[i] = True
            m = static_material[prim[i]]
            semantic[i] = static_semantic[prim[i]]
            material[i] = m
            for k in range(3):
                color[i, k] = albedo[m, k]
    for j in range(sub.size):
        i = sub[j]
        if t_actor[j] < t[i]:
            p = prim_actor[j]
            a = hit_actor[j]
            m = actor_material[p]
            t[i] = t_actor[j]
            hit[i] = True
            instance_id[i] = track_id[a]
            actor_index[i] = a
            semantic[i] = actor_semantic[p]
            material[i] = m
            for k in range(3):
                normal[i, k] = normal_actor[j, k]
                color[i, k] = actor_color[a, k] if tinted[m] else albedo[m, k]
    for i in range(t.size):
        if normal[i, 0] * rays[i, 3] + normal[i, 1] * rays[i, 4] + normal[i, 2] * rays[i, 5] > 0:
            for k in range(3):
                normal[i, k] = -normal[i, k]


@kernel("Tuple((float32[::1], uint32[::1], float32[:, ::1]))(int64, int64[::1], float32[::1], uint32[::1], "
        "float32[:, ::1])")
def spread_cast(n, rows, t, prim, normal):
    """A cast of the rays ``rows`` ((K,) int64 of N) among all N: t (N,) float32 (inf elsewhere), prim (N,) uint32
    (Embree's invalid id, 2^32 - 1, elsewhere) and normal (N, 3) float32 (0 elsewhere), from the K rows' own."""
    t_all = np.full(n, np.inf, np.float32)
    prim_all = np.full(n, np.uint32(0xFFFFFFFF), np.uint32)
    normal_all = np.zeros((n, 3), np.float32)
    for j in range(rows.size):
        i = rows[j]
        t_all[i] = t[j]
        prim_all[i] = prim[j]
        for k in range(3):
            normal_all[i, k] = normal[j, k]
    return t_all, prim_all, normal_all
