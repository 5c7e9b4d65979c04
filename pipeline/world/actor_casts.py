"""Rays against the frame's actors without building a frame-wide BVH: each actor is its class's canonical mesh.

An actor's mesh is its class's canonical mesh, spanning the unit box [-0.5, 0.5]^3, under the affine map
``p = A u + c`` (:func:`pipeline.world.actors.unit_to_world`). So a ray meets the actor where the ray mapped back
into the unit frame, ``u = A^-1 (p - c)`` with direction ``A^-1 d`` (left unnormalised, so that t stays in world
metres), meets the canonical mesh, whose Embree scene is built once per class and process. Building a BVH over
every placed actor instead cost, per frame, more than all the actor rays it served (docs/performance.md).

:func:`actor_pairs` lists which (ray, actor) pairs can meet (an exact slab test against the unit box, with a
margin) with the pairs' rays in the unit frame; the caller casts each class's pairs against its canonical scene;
:func:`nearest_actor_hits` keeps each ray's nearest hit and turns its normal into the world frame. Compiled
(:mod:`pipeline.core.jit`).
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import kernel

BOX_MARGIN = 1e-3  # the slab test's box is the unit box grown by this much (unit-frame units) on every side


@kernel("void(float64[:, ::1], float64, float64, float64, float64, float64, float64, float32[::1])")
def _unit_ray(inv, v0, v1, v2, d0, d1, d2, out):
    """A world ray in an actor's unit frame, into ``out`` (6,) float32: origin A^-1 (o - c) from v = c - o, and
    direction A^-1 d (not normalised, so t stays in world metres); ``inv`` (3, 3) float64 is A^-1."""
    for k in range(3):
        out[k] = np.float32(-(inv[k, 0] * v0 + inv[k, 1] * v1 + inv[k, 2] * v2))
        out[3 + k] = np.float32(inv[k, 0] * d0 + inv[k, 1] * d1 + inv[k, 2] * d2)


@kernel("float32[:, ::1](float32[:, ::1], int64[::1], float64[:, :, ::1], float64[:, ::1])")
def unit_frame_rays(rays, actor, inv_linear, centre):
    """(N, 6) float32: each of the (N, 6) float32 world ``rays`` in the unit frame of its ``actor`` ((N,) int64),
    as :func:`actor_pairs` maps them (A^-1 per actor ``inv_linear`` (A, 3, 3), c ``centre`` (A, 3))."""
    out = np.empty((rays.shape[0], 6), np.float32)
    for i in range(rays.shape[0]):
        a = actor[i]
        _unit_ray(inv_linear[a], centre[a, 0] - np.float64(rays[i, 0]), centre[a, 1] - np.float64(rays[i, 1]),
                  centre[a, 2] - np.float64(rays[i, 2]), np.float64(rays[i, 3]), np.float64(rays[i, 4]),
                  np.float64(rays[i, 5]), out[i])
    return out


@kernel("boolean(float32[::1])")
def _meets_unit_box(ray):
    """Whether the ray [origin | direction] (float32, unit frame) meets the grown unit box at some t >= 0."""
    half = 0.5 + BOX_MARGIN
    t_in, t_out = 0.0, np.inf
    for c in range(3):
        o, d = np.float64(ray[c]), np.float64(ray[3 + c])
        if d == 0.0:
            if o < -half or o > half:
                return False
            continue
        t0, t1 = (-half - o) / d, (half - o) / d
        if t0 > t1:
            t0, t1 = t1, t0
        t_in, t_out = max(t_in, t0), min(t_out, t1)
        if t_in > t_out:
            return False
    return True


@kernel("int64[::1](int64[::1], int64)")
def _grown(a, size):
    """``a`` copied into a longer array of ``size`` items."""
    out = np.empty(size, np.int64)
    out[: a.size] = a
    return out


@kernel("float32[:, ::1](float32[:, ::1], int64)")
def _grown_rows(a, size):
    """``a`` copied into an array of ``size`` rows."""
    out = np.empty((size, a.shape[1]), np.float32)
    out[: a.shape[0]] = a
    return out


@kernel("boolean(float64, float64, float64, float64, float64, float64, float64, float64, float64)")
def _off_sphere(v0, v1, v2, v3, d0, d1, d2, dd, r):
    """Whether a ray surely misses the sphere of radius r about an actor's centre c (which holds its grown unit
    box): the sphere lies behind the origin (along < -r |d|) or off the line (distance^2 > r^2). v = c - o, v3
    its squared length, d the ray's direction, dd its squared length. The cheap first test: most pairs fail it."""
    along = v0 * d0 + v1 * d1 + v2 * d2
    return (along * along > r * r * dd and along < 0) or (v3 - r * r) * dd > along * along


@kernel("Tuple((int64[::1], int64[::1], float32[:, ::1]))(float32[:, ::1], int64[::1], int64[::1], "
        "float64[:, :, ::1], float64[:, ::1], float64[::1])")
def actor_pairs(rays, rows, actors, inv_linear, centre, radius):
    """The (ray, actor) pairs whose ray meets the actor's unit box (grown by BOX_MARGIN) at t >= 0.

    Args:
        rays: (N, 6) float32 world rays [origin | direction] (any length); rows: (K,) int64 the rays to test.
        actors: (B,) int64 the actors to test (positions in the frame's actors).
        inv_linear: (A, 3, 3) float64 A^-1 per actor; centre: (A, 3) float64 c per actor; radius: (A,) float64
            a radius about c that holds the grown box (a first, cheaper test: most pairs fail it).

    Returns:
        pair_row (P,) int64 (a position in ``rows``), pair_actor (P,) int64 and the pairs' rays in the actor's
        unit frame (P, 6) float32 (direction A^-1 d, not normalised), ordered by row, then as in ``actors``.
    """
    local = np.empty(6, np.float32)
    nb = actors.size
    # c - o per actor, for the current ray's origin: recomputed only when the origin changes (a camera's or a
    # LiDAR's rays share theirs).
    v = np.empty((4, nb))  # rows: x, y, z, squared length
    r = np.empty(nb)
    for b in range(nb):
        r[b] = radius[actors[b]]
    count = 0
    pair_row = np.empty(rows.size, np.int64)  # grown (doubled) as needed: most rays meet no actor, some one
    pair_actor = np.empty(rows.size, np.int64)
    pair_rays = np.empty((rows.size, 6), np.float32)
    last = np.full(3, np.nan)
    for j in range(rows.size):
        i = rows[j]
        o0, o1, o2 = np.float64(rays[i, 0]), np.float64(rays[i, 1]), np.float64(rays[i, 2])
        d0, d1, d2 = np.float64(rays[i, 3]), np.float64(rays[i, 4]), np.float64(rays[i, 5])
        if o0 != last[0] or o1 != last[1] or o2 != last[2]:
            last[0], last[1], last[2] = o0, o1, o2
            for b in range(nb):
                a = actors[b]
                v[0, b], v[1, b], v[2, b] = centre[a, 0] - o0, centre[a, 1] - o1, centre[a, 2] - o2
                v[3, b] = v[0, b] * v[0, b] + v[1, b] * v[1, b] + v[2, b] * v[2, b]
        dd = d0 * d0 + d1 * d1 + d2 * d2  # not always 1: e.g. shadow rays towards a lamp, t_max = 1
        for b in range(nb):
            if _off_sphere(v[0, b], v[1, b], v[2, b], v[3, b], d0, d1, d2, dd, r[b]):
                continue
            a = actors[b]
            _unit_ray(inv_linear[a], v[0, b], v[1, b], v[2, b], d0, d1, d2, local)
            if not _meets_unit_box(local):
                continue
            if count == pair_row.size:
                size = max(2 * count, 16)
                pair_row, pair_actor, pair_rays = (_grown(pair_row, size), _grown(pair_actor, size),
                                                   _grown_rows(pair_rays, size))
            pair_row[count] = j
            pair_actor[count] = a
            for c in range(6):
                pair_rays[count, c] = local[c]
            count += 1
    pair_row, pair_actor, pair_rays = pair_row[:count].copy(), pair_actor[:count].copy(), pair_rays[:count].copy()
    return pair_row, pair_actor, pair_rays


@kernel("Tuple((int64[::1], int64[::1]))(int64, int64, int64[:, ::1])")
def cell_lists(rows, cols, spans):
    """Which items cover each cell of a ``rows`` x ``cols`` grid, as compressed rows: item b covers the cells
    [i0, i1) x [j0, j1) of its ``spans[b]`` = (i0, i1, j0, j1) (clipped to the grid here; an empty span covers
    none). Returns ``cell_start`` (rows * cols + 1,) int64 and ``cell_item`` int64: the items of cell i * cols + j
    are ``cell_item[cell_start[c]:cell_start[c + 1]]``, ascending."""
    start = np.zeros(rows * cols + 1, np.int64)
    for b in range(spans.shape[0]):
        for i in range(max(spans[b, 0], 0), min(spans[b, 1], rows)):
            for j in range(max(spans[b, 2], 0), min(spans[b, 3], cols)):
                start[i * cols + j + 1] += 1
    for c in range(rows * cols):
        start[c + 1] += start[c]
    item = np.empty(start[rows * cols], np.int64)
    fill = start[:-1].copy()
    for b in range(spans.shape[0]):
        for i in range(max(spans[b, 0], 0), min(spans[b, 1], rows)):
            for j in range(max(spans[b, 2], 0), min(spans[b, 3], cols)):
                item[fill[i * cols + j]] = b
                fill[i * cols + j] += 1
    return start, item


@kernel("Tuple((float32[::1], uint32[::1], float32[:, ::1], int32[::1]))(int64, int64[::1], int64[::1], "
        "float32[::1], uint32[::1], float32[:, ::1], float64[:, :, ::1])")
def nearest_actor_hits(k, pair_row, pair_actor, t, prim, normal, inv_linear):
    """Each of ``k`` rows' nearest hit among its pairs' casts.

    Args:
        pair_row, pair_actor: (P,) int64 from :func:`actor_pairs`.
        t, prim, normal: the pairs' casts in the unit frame: (P,) float32 t (world metres; inf = miss), (P,)
            uint32 triangle (any numbering, passed through) and (P, 3) float32 unit normal (0 on a miss).
        inv_linear: (A, 3, 3) float64 A^-1 per actor.

    Returns:
        t (k,) float32 (inf = no hit), prim (k,) uint32, normal (k, 3) float32, world frame, unit (0 where no
        hit), actor (k,) int32 (valid where hit). On equal t the pair listed first wins.
    """
    t_best = np.full(k, np.inf, np.float32)
    best = np.full(k, -1, np.int64)
    for p in range(pair_row.size):
        j = pair_row[p]
        if t[p] < t_best[j]:
            t_best[j] = t[p]
            best[j] = p
    prim_best = np.full(k, np.uint32(0xFFFFFFFF), np.uint32)
    normal_best = np.zeros((k, 3), np.float32)
    actor_best = np.zeros(k, np.int32)
    for j in range(k):
        p = best[j]
        if p < 0:
            continue
        a = pair_actor[p]
        prim_best[j] = prim[p]
        actor_best[j] = a
        # A normal maps by the inverse transpose: n_world ~ A^-T n_unit.
        w = np.zeros(3)
        for r in range(3):
            for c in range(3):
                w[c] += inv_linear[a, r, c] * normal[p, r]
        norm = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        if norm > 0:
            for c in range(3):
                normal_best[j, c] = w[c] / norm
    return t_best, prim_best, normal_best, actor_best


@kernel("float64(float32[::1], float64)")
def _unit_box_entry(ray, half):
    """The t >= 0 at which the ray [origin | direction] (float32, unit frame) enters the box [-half, half]^3 (0 from
    inside), NaN where it misses it: :func:`_meets_unit_box`'s slabs, in the same arithmetic."""
    t_in, t_out = 0.0, np.inf
    for c in range(3):
        o, d = np.float64(ray[c]), np.float64(ray[3 + c])
        if d == 0.0:
            if o < -half or o > half:
                return np.nan
            continue
        t0, t1 = (-half - o) / d, (half - o) / d
        if t0 > t1:
            t0, t1 = t1, t0
        t_in, t_out = max(t_in, t0), min(t_out, t1)
        if t_in > t_out:
            return np.nan
    return t_in


@kernel("void(int64[::1], int64)")
def _ascending(items, n):
    """Sort ``items[:n]`` ascending in place (insertion sort: a handful each)."""
    for p in range(1, n):
        v = items[p]
        q = p - 1
        while q >= 0 and items[q] > v:
            items[q + 1] = items[q]
            q -= 1
        items[q + 1] = v


@kernel("int64(float64, float64, float64, float64, float64, float64, float64, int64, float64[::1], float64[::1], "
        "float64, int64, int64, int64[::1], int64[::1], int64[::1], int64[::1])")
def _walked(o0, o1, o2, d0, d1, d2, t_limit, j, lo, hi, cell, nx, ny, cell_start, cell_item, stamp, cand):
    """:func:`grid_actor_pairs`' walk: into ``cand``, ascending, the actors (positions in its ``actors``) listed for
    the cells that ray ``j`` (origin o, direction d) crosses inside the grid's box with t in [0, ``t_limit``];
    returns how many. ``stamp`` (B,) int64 marks the actors found for ray j."""
    # The span of t in the box and in [0, t_limit] (slabs).
    t0, t1 = 0.0, t_limit
    for c in range(3):
        o, d = (o0, o1, o2)[c], (d0, d1, d2)[c]
        if d == 0.0:
            if o < lo[c] or o > hi[c]:
                return 0
            continue
        ta, tb = (lo[c] - o) / d, (hi[c] - o) / d
        if ta > tb:
            ta, tb = tb, ta
        t0, t1 = max(t0, ta), min(t1, tb)
    if t0 > t1:
        return 0
    dxy = np.sqrt(d0 * d0 + d1 * d1)
    steps = 0
    step = 0.0
    if dxy > 0.0 and t1 > t0:
        step = cell / dxy
        steps = np.int64((t1 - t0) / step) + 1
    n = 0
    last = np.int64(-1)
    for k in range(steps + 1):
        t = min(t0 + k * step, t1)
        ci = min(max(np.int64(np.floor((o0 + t * d0 - lo[0]) / cell)), 0), nx - 1)
        cj = min(max(np.int64(np.floor((o1 + t * d1 - lo[1]) / cell)), 0), ny - 1)
        cc = ci * ny + cj
        if cc == last:
            continue
        last = cc
        for m in range(cell_start[cc], cell_start[cc + 1]):
            b = cell_item[m]
            if stamp[b] != j:
                stamp[b] = j
                cand[n] = b
                n += 1
    _ascending(cand, n)
    return n


@kernel("int64(float64, float64, float64, float64, int64, int64[::1], float64[:, ::1], float64[::1], float64[::1], "
        "float64, int64, int64, int64[::1], int64[::1], int64[::1], int64[::1])")
def _near_origin(o0, o1, o2, reach, j, actors, centre, radius, lo, cell, nx, ny, cell_start, cell_item, stamp, near):
    """:func:`grid_actor_pairs`' short segments: into ``near``, ascending, the actors (positions in ``actors``)
    listed for the cells that the square of half-side ``reach`` about the origin o overlaps whose sphere comes
    within ``reach`` of o (every segment from o no longer than ``reach`` that meets an actor's sphere is among
    them); returns how many. ``stamp`` (B,) int64 marks the actors found for ray j."""
    i0 = max(np.int64(np.floor((o0 - reach - lo[0]) / cell)), 0)
    i1 = min(np.int64(np.floor((o0 + reach - lo[0]) / cell)), nx - 1)
    j0 = max(np.int64(np.floor((o1 - reach - lo[1]) / cell)), 0)
    j1 = min(np.int64(np.floor((o1 + reach - lo[1]) / cell)), ny - 1)
    n = 0
    for ci in range(i0, i1 + 1):
        for cj in range(j0, j1 + 1):
            cc = ci * ny + cj
            for m in range(cell_start[cc], cell_start[cc + 1]):
                b = cell_item[m]
                if stamp[b] == j:
                    continue
                stamp[b] = j
                a = actors[b]
                v0, v1, v2 = centre[a, 0] - o0, centre[a, 1] - o1, centre[a, 2] - o2
                r = radius[a] + reach
                if v0 * v0 + v1 * v1 + v2 * v2 <= r * r:
                    near[n] = b
                    n += 1
    _ascending(near, n)
    return n


@kernel("Tuple((int64[::1], int64[::1], float32[:, ::1]))(float32[:, ::1], int64[::1], int64[::1], "
        "float64[:, :, ::1], float64[:, ::1], float64[::1], float64[::1], float64[::1], float64[::1], float64, int64, "
        "int64, int64[::1], int64[::1], float64)")
def grid_actor_pairs(rays, rows, actors, inv_linear, centre, radius, t_limit, lo, hi, cell, nx, ny, cell_start,
                     cell_item, near_m):
    """:func:`actor_pairs` of the pairs that can give a ray ``rows[j]`` a hit at t <= ``t_limit[j]``, each ray
    tested only against the actors listed for the grid cells it crosses in that span.

    The grid (:func:`actor_grid`) covers the box ``lo``..``hi`` ((3,) float64: the actors' spheres, x, y and z);
    its ``nx`` x ``ny`` cells, ``cell`` metres wide from (lo[0], lo[1]), list (``cell_start``, ``cell_item``:
    :func:`cell_lists`, positions in ``actors``) the actors whose sphere's square touches the cell or one of its
    8 neighbours. A ray's part inside the box with t in [0, t_limit] is sampled at steps that advance it one cell
    in xy, and its end: every point of it lies within half a cell of a sample, so in a cell next to the sample's,
    and an actor whose sphere the ray meets there is listed for the sample's cell. The candidates are tested as
    :func:`actor_pairs` tests them (the same arithmetic), in the order of ``actors``; a pair whose box the ray
    enters beyond ``t_limit[j]`` (grown by 0.1 % and 1 cm for rounding) is left out: its hit would lie there.

    A short segment, one whose reach (that grown limit times its direction's length) is at most ``near_m``, takes
    instead the actors listed for the cells within its reach of its origin whose sphere comes within its reach of
    the origin: found once for consecutive rays from one origin (a pixel's sky-occlusion segments, which share
    their origin and length), where walking each ray's cells found the same actors again per ray. Both find every
    pair whose box the ray enters by ``t_limit``; the reach's test may also keep one entered between the limit and
    its margin, which the walk leaves out, so give ``near_m`` > 0 only where such a pair cannot change the result
    (an occlusion test up to ``t_limit``) and 0 where it could (a nearest hit).

    Returns what :func:`actor_pairs` returns, less the pairs that cannot be hit within ``t_limit``.
    """
    local = np.empty(6, np.float32)
    nb = actors.size
    stamp = np.full(nb, -1, np.int64)
    cand = np.empty(nb, np.int64)
    count = 0
    pair_row = np.empty(rows.size, np.int64)
    pair_actor = np.empty(rows.size, np.int64)
    pair_rays = np.empty((rows.size, 6), np.float32)
    half = 0.5 + BOX_MARGIN
    # The actors in reach of the last short segment's origin (ascending), and that origin and reach. A row either
    # walks or looks about its origin, so both mark the actors they find in ``stamp`` with the row.
    near = np.empty(nb, np.int64)
    n_near = 0
    near_o0 = near_o1 = near_o2 = np.nan
    near_reach = -1.0
    for j in range(rows.size):
        i = rows[j]
        o0, o1, o2 = np.float64(rays[i, 0]), np.float64(rays[i, 1]), np.float64(rays[i, 2])
        d0, d1, d2 = np.float64(rays[i, 3]), np.float64(rays[i, 4]), np.float64(rays[i, 5])
        dd = d0 * d0 + d1 * d1 + d2 * d2
        limit = np.float64(t_limit[j]) * 1.001 + 0.01
        reach = limit * np.sqrt(dd)
        if reach <= near_m:
            if o0 != near_o0 or o1 != near_o1 or o2 != near_o2 or reach > near_reach:
                near_o0, near_o1, near_o2, near_reach = o0, o1, o2, reach
                n_near = _near_origin(o0, o1, o2, reach, j, actors, centre, radius, lo, cell, nx, ny, cell_start,
                                      cell_item, stamp, near)
            src, n = near, n_near
        else:
            src, n = cand, _walked(o0, o1, o2, d0, d1, d2, np.float64(t_limit[j]), j, lo, hi, cell, nx, ny,
                                   cell_start, cell_item, stamp, cand)
        for p in range(n):
            a = actors[src[p]]
            v0, v1, v2 = centre[a, 0] - o0, centre[a, 1] - o1, centre[a, 2] - o2
            if _off_sphere(v0, v1, v2, v0 * v0 + v1 * v1 + v2 * v2, d0, d1, d2, dd, radius[a]):
                continue
            _unit_ray(inv_linear[a], v0, v1, v2, d0, d1, d2, local)
            t_in = _unit_box_entry(local, half)
            if not t_in <= limit:  # a miss (NaN) or beyond the limit
                continue
            if count == pair_row.size:
                size = max(2 * count, 16)
                pair_row, pair_actor, pair_rays = (_grown(pair_row, size), _grown(pair_actor, size),
                                                   _grown_rows(pair_rays, size))
            pair_row[count] = j
            pair_actor[count] = a
            for m in range(6):
                pair_rays[count, m] = local[m]
            count += 1
    return pair_row[:count].copy(), pair_actor[:count].copy(), pair_rays[:count].copy()


ORIGIN_BIN_RAD = float(np.deg2rad(1.0))  # origin_lists' bins of directions (a camera pixel is ~0.1 deg)


@kernel("Tuple((int64[::1], int64[::1]))(float64, float64, float64, int64[::1], float64[:, ::1], float64[::1], "
        "float64, int64, int64)")
def origin_lists(o0, o1, o2, actors, centre, radius, step, n_el, n_az):
    """For rays that share the origin o (a camera's, a LiDAR's): which actors each bin of directions may meet, as
    compressed rows like :func:`cell_lists`' (cell_start (n_el * n_az + 1,), cell_item: positions in ``actors``,
    ascending). A direction's bin is (elevation, azimuth) in steps of ``step`` radians from (-pi/2, -pi)
    (:func:`_direction_bin`). A ray that meets the sphere (``centre``, ``radius``) of an actor at distance D > 1.5 r
    from o leaves o within asin(r / D) of the centre's direction (:func:`_off_sphere` accepts no other: a ray it
    keeps with the centre behind the origin needs D <= sqrt(2) r), so within that of its elevation and within
    asin(sin a / cos(|elevation| + a)) of its azimuth; the actor is listed for the bins of that range grown by a
    bin on every side (far beyond rounding), for every azimuth near the poles, and for every bin when D <= 1.5 r."""
    n_cells = n_el * n_az
    span = np.empty((actors.size, 4), np.int64)  # elevation bins [e0, e1), azimuth bins a0, a0 + 1, ... (n of them)
    half_pi = 0.5 * np.pi
    for b in range(actors.size):
        a = actors[b]
        v0, v1, v2 = centre[a, 0] - o0, centre[a, 1] - o1, centre[a, 2] - o2
        dist = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        r = radius[a]
        if not dist > 1.5 * r:
            span[b, 0], span[b, 1], span[b, 2], span[b, 3] = 0, n_el, 0, n_az
            continue
        cone = np.arcsin(r / dist)
        elevation = np.arctan2(v2, np.sqrt(v0 * v0 + v1 * v1))
        span[b, 0] = max(np.int64(np.floor((elevation - cone + half_pi) / step)) - 1, 0)
        span[b, 1] = min(np.int64(np.floor((elevation + cone + half_pi) / step)) + 2, n_el)
        if abs(elevation) + cone >= half_pi - 2.0 * step:
            span[b, 2], span[b, 3] = 0, n_az
            continue
        half = np.arcsin(min(1.0, np.sin(cone) / np.cos(abs(elevation) + cone)))
        azimuth = np.arctan2(v1, v0)
        first = np.int64(np.floor((azimuth - half + np.pi) / step)) - 1
        count = np.int64(np.floor((azimuth + half + np.pi) / step)) + 2 - first
        if count >= n_az:
            span[b, 2], span[b, 3] = 0, n_az
        else:
            span[b, 2], span[b, 3] = first % n_az, count
    start = np.zeros(n_cells + 1, np.int64)
    for b in range(actors.size):
        for e in range(span[b, 0], span[b, 1]):
            for k in range(span[b, 3]):
                start[e * n_az + (span[b, 2] + k) % n_az + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    item = np.empty(start[n_cells], np.int64)
    fill = start[:-1].copy()
    for b in range(actors.size):
        for e in range(span[b, 0], span[b, 1]):
            for k in range(span[b, 3]):
                c = e * n_az + (span[b, 2] + k) % n_az
                item[fill[c]] = b
                fill[c] += 1
    return start, item


@kernel("int64(float64, float64, float64, float64, int64, int64)")
def _direction_bin(d0, d1, d2, step, n_el, n_az):
    """:func:`origin_lists`' bin of the direction d: elevation row times ``n_az`` plus azimuth column."""
    elevation = np.arctan2(d2, np.sqrt(d0 * d0 + d1 * d1))
    e = min(max(np.int64(np.floor((elevation + 0.5 * np.pi) / step)), 0), n_el - 1)
    k = np.int64(np.floor((np.arctan2(d1, d0) + np.pi) / step)) % n_az
    return e * n_az + k


@kernel("boolean(float32[:, ::1], int64[::1])")
def shared_origin(rays, rows):
    """Whether the rays ``rows`` of the (N, 6) float32 ``rays`` all leave the same origin (none: False)."""
    if rows.size == 0:
        return False
    i = rows[0]
    for j in range(1, rows.size):
        k = rows[j]
        if rays[k, 0] != rays[i, 0] or rays[k, 1] != rays[i, 1] or rays[k, 2] != rays[i, 2]:
            return False
    return True


def origin_bins(step: float = ORIGIN_BIN_RAD) -> tuple[int, int]:
    """(n_el, n_az): how many elevation and azimuth bins of ``step`` radians :func:`origin_lists` uses."""
    return int(np.ceil(np.pi / step)) + 1, int(np.ceil(2 * np.pi / step))


@kernel("Tuple((int64[::1], int64[::1], float32[:, ::1]))(float32[:, ::1], int64[::1], int64[::1], "
        "float64[:, :, ::1], float64[:, ::1], float64[::1], float64[::1], float64, int64, int64, int64[::1], "
        "int64[::1], float64[::1])")
def origin_actor_pairs(rays, rows, actors, inv_linear, centre, radius, t_limit, step, n_el, n_az, cell_start,
                       cell_item, toward):
    """:func:`grid_actor_pairs` (without ``near_m``) of rays ``rows`` that all leave one origin, each ray tested
    against the actors :func:`origin_lists` (``cell_start``, ``cell_item``, built for that origin) lists for its
    direction's bin instead of those of the grid cells it crosses: the same tests in the same arithmetic, the
    candidates in the same order (ascending in ``actors``), so the same pairs, in the same order, as both lists
    hold every actor whose sphere the ray meets (tested against grid_actor_pairs). A camera's or a LiDAR's ray
    crosses a cell of the grid every 2 m of its way; it has one bin. A bin lists the actors behind the ray's limit
    too (where the walk stops at it): those whose sphere begins beyond the grown limit are dropped first, by one
    comparison (the box test would drop them: the box lies in the sphere).

    ``toward`` (3,) float64, finite: the rays are instead segments that end near one point q (shadow rays towards a
    lamp) and the lists were built at q: each ray takes the bin of the direction from q to its origin. A segment that
    stays within s of the line from q through its origin meets an actor's sphere only if that line meets the sphere
    grown by s, so lists built with the radii grown by s hold every actor it can meet (:meth:`FrameScene._pairs`).
    NaN: the rays' own directions, as above."""
    local = np.empty(6, np.float32)
    count = 0
    pair_row = np.empty(rows.size, np.int64)
    pair_actor = np.empty(rows.size, np.int64)
    pair_rays = np.empty((rows.size, 6), np.float32)
    half = 0.5 + BOX_MARGIN
    for j in range(rows.size):
        i = rows[j]
        o0, o1, o2 = np.float64(rays[i, 0]), np.float64(rays[i, 1]), np.float64(rays[i, 2])
        d0, d1, d2 = np.float64(rays[i, 3]), np.float64(rays[i, 4]), np.float64(rays[i, 5])
        dd = d0 * d0 + d1 * d1 + d2 * d2
        limit = np.float64(t_limit[j]) * 1.001 + 0.01
        reach = limit * np.sqrt(dd)  # the farthest a pair's box may begin (inf without a limit)
        if np.isnan(toward[0]):
            c = _direction_bin(d0, d1, d2, step, n_el, n_az)
        else:
            c = _direction_bin(o0 - toward[0], o1 - toward[1], o2 - toward[2], step, n_el, n_az)
        for m in range(cell_start[c], cell_start[c + 1]):
            a = actors[cell_item[m]]
            v0, v1, v2 = centre[a, 0] - o0, centre[a, 1] - o1, centre[a, 2] - o2
            v3 = v0 * v0 + v1 * v1 + v2 * v2
            far = (reach + radius[a]) * 1.001 + 0.01
            if v3 > far * far:  # its sphere, so its box, begins beyond the limit: the box test would drop it
                continue
            # grid_actor_pairs' tests and append, written out: as calls of shared kernels (per candidate) both
            # functions took ~30 % longer (numba does not inline them).
            if _off_sphere(v0, v1, v2, v3, d0, d1, d2, dd, radius[a]):
                continue
            _unit_ray(inv_linear[a], v0, v1, v2, d0, d1, d2, local)
            t_in = _unit_box_entry(local, half)
            if not t_in <= limit:  # a miss (NaN) or beyond the limit
                continue
            if count == pair_row.size:
                size = max(2 * count, 16)
                pair_row, pair_actor, pair_rays = (_grown(pair_row, size), _grown(pair_actor, size),
                                                   _grown_rows(pair_rays, size))
            pair_row[count] = j
            pair_actor[count] = a
            for k in range(6):
                pair_rays[count, k] = local[k]
            count += 1
    return pair_row[:count].copy(), pair_actor[:count].copy(), pair_rays[:count].copy()


GRID_CELL_M = 2.0  # cells of actor_grid at least this wide ...
GRID_MAX_CELLS = 250_000  # ... and at most about this many


def actor_grid(centre: np.ndarray, radius: np.ndarray, actors: np.ndarray) -> tuple:
    """The grid of :func:`grid_actor_pairs` over the ``actors`` (B,) int64 (positions into ``centre`` (A, 3) float64
    and ``radius`` (A,) float64, the spheres that hold each actor's grown box): (lo, hi, cell, nx, ny, cell_start,
    cell_item), each actor listed for the cells its sphere's xy square touches, grown by a cell on every side
    (:func:`cell_lists`, items positions in ``actors``). The box lo..hi holds every sphere, grown by 1 mm."""
    c, r = centre[actors], radius[actors][:, None]
    lo = (c - r).min(axis=0) - 1e-3
    hi = (c + r).max(axis=0) + 1e-3
    cell = max(GRID_CELL_M, float(np.sqrt(np.prod(hi[:2] - lo[:2] + GRID_CELL_M) / GRID_MAX_CELLS)))
    nx, ny = (np.floor((hi[:2] - lo[:2]) / cell).astype(np.int64) + 1).tolist()
    first = np.floor((c[:, :2] - r - lo[:2]) / cell).astype(np.int64) - 1
    last = np.floor((c[:, :2] + r - lo[:2]) / cell).astype(np.int64) + 2  # exclusive
    spans = np.ascontiguousarray(np.column_stack([first[:, 0], last[:, 0], first[:, 1], last[:, 1]]))
    cell_start, cell_item = cell_lists(nx, ny, spans)
    return (np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64), float(cell), int(nx), int(ny),
            cell_start, cell_item)
