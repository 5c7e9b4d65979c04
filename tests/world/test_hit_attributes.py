"""resolve_hits, the compiled merge of the static and actor casts, against its definition ray by ray."""

from __future__ import annotations

import numpy as np

from pipeline.world.hit_attributes import resolve_hits, spread_cast

PAINT, GARMENT = 2, 4
TINTED = np.isin(np.arange(6), [PAINT, GARMENT])


def _inputs(rng: np.random.Generator, n: int = 2000, triangles: int = 50, actor_triangles: int = 40, actors: int = 5):
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = np.concatenate([rng.normal(size=(n, 3)).astype(np.float32), d], axis=1)
    t = np.where(rng.random(n) < 0.7, rng.uniform(1, 50, n), np.inf).astype(np.float32)
    prim = np.where(np.isfinite(t), rng.integers(0, triangles, n), np.iinfo(np.uint32).max).astype(np.uint32)
    normal = np.where(np.isfinite(t)[:, None], rng.normal(size=(n, 3)), 0.0).astype(np.float32)
    sub = np.flatnonzero(rng.random(n) < 0.5).astype(np.int64)
    t_actor = np.where(rng.random(len(sub)) < 0.6, rng.uniform(1, 50, len(sub)), np.inf).astype(np.float32)
    actor = {
        "sub": sub, "t_actor": t_actor,
        "prim_actor": rng.integers(0, actor_triangles, len(sub)).astype(np.uint32),
        "normal_actor": rng.normal(size=(len(sub), 3)).astype(np.float32),
        "hit_actor": rng.integers(0, actors, len(sub)).astype(np.int32),
        "actor_semantic": rng.integers(1, 20, actor_triangles).astype(np.uint8),
        "actor_material": rng.integers(0, 6, actor_triangles).astype(np.int32),  # PAINT and GARMENT among the 6
        "track_id": rng.permutation(np.arange(100, 100 + actors)).astype(np.int32),
        "actor_color": rng.random((actors, 3)).astype(np.float32),
    }
    static = {"static_semantic": rng.integers(1, 20, triangles).astype(np.uint8),
              "static_material": rng.integers(0, 6, triangles).astype(np.int32),
              "albedo": rng.random((6, 3)).astype(np.float32)}
    return rays, t, prim, normal, static, actor


def _resolve(rays, t, prim, normal, static, actor):
    n = len(t)
    out = {"hit": np.zeros(n, bool), "instance_id": np.zeros(n, np.int32), "actor_index": np.zeros(n, np.int32),
           "semantic": np.zeros(n, np.uint8), "material": np.zeros(n, np.int32), "color": np.zeros((n, 3), np.float32)}
    t, normal = t.copy(), normal.copy()
    resolve_hits(rays, t, prim, normal, static["static_semantic"], static["static_material"], static["albedo"],
                 actor["sub"], actor["t_actor"], actor["prim_actor"], actor["normal_actor"], actor["hit_actor"],
                 actor["actor_semantic"], actor["actor_material"], actor["track_id"], actor["actor_color"], TINTED,
                 out["hit"], out["instance_id"], out["actor_index"], out["semantic"], out["material"], out["color"])
    return t, normal, out


def test_each_ray_keeps_its_nearer_hit_with_that_triangles_attributes():
    rays, t, prim, normal, static, actor = _inputs(np.random.default_rng(7))
    t_out, normal_out, out = _resolve(rays, t, prim, normal, static, actor)
    actor_at = {int(i): j for j, i in enumerate(actor["sub"])}
    for i in range(len(t)):
        j = actor_at.get(i)
        if j is not None and actor["t_actor"][j] < t[i]:  # the actor is nearer (or the static cast missed)
            p = actor["prim_actor"][j]
            a = actor["hit_actor"][j]
            m = actor["actor_material"][p]
            expected = (actor["t_actor"][j], True, actor["track_id"][a], a, actor["actor_semantic"][p], m,
                        actor["actor_color"][a] if m in (PAINT, GARMENT) else static["albedo"][m],
                        actor["normal_actor"][j])
        elif np.isfinite(t[i]):
            m = static["static_material"][prim[i]]
            expected = (t[i], True, 0, 0, static["static_semantic"][prim[i]], m, static["albedo"][m], normal[i])
        else:
            expected = (np.inf, False, 0, 0, 0, 0, np.zeros(3), np.zeros(3))
        t_e, hit_e, inst_e, index_e, sem_e, mat_e, color_e, normal_e = expected
        assert t_out[i] == t_e
        assert (out["hit"][i], out["instance_id"][i], out["actor_index"][i]) == (hit_e, inst_e, index_e)
        assert (out["semantic"][i], out["material"][i]) == (sem_e, mat_e)
        np.testing.assert_array_equal(out["color"][i], color_e)
        # The normal faces the ray's origin: the hit triangle's, negated when it faced along the ray.
        sign = -1.0 if float(np.dot(normal_e.astype(np.float64), rays[i, 3:].astype(np.float64))) > 0 else 1.0
        np.testing.assert_array_equal(normal_out[i], sign * normal_e)
        assert float(np.dot(normal_out[i], rays[i, 3:])) <= 1e-6


def test_no_actor_rays_and_no_hits():
    rays, t, prim, normal, static, actor = _inputs(np.random.default_rng(8), n=50)
    t[:] = np.inf
    normal[:] = 0.0
    actor["sub"], actor["t_actor"] = actor["sub"][:0], actor["t_actor"][:0]
    actor["prim_actor"], actor["normal_actor"] = actor["prim_actor"][:0], actor["normal_actor"][:0]
    actor["hit_actor"] = actor["hit_actor"][:0]
    t_out, normal_out, out = _resolve(rays, t, prim, normal, static, actor)
    assert np.all(np.isinf(t_out)) and not out["hit"].any() and not normal_out.any() and not out["color"].any()


def test_a_cast_of_some_rays_spreads_back_among_all():
    rows = np.array([4, 0, 7], np.int64)
    t = np.float32([1.5, 2.5, np.inf])
    prim = np.array([3, 9, np.iinfo(np.uint32).max], np.uint32)
    normal = np.float32([[0, 0, 1], [1, 0, 0], [0, 0, 0]])
    t_all, prim_all, normal_all = spread_cast(8, rows, t, prim, normal)
    assert t_all.tolist() == [2.5, np.inf, np.inf, np.inf, 1.5, np.inf, np.inf, np.inf]
    assert prim_all.tolist() == [9] + [2**32 - 1] * 3 + [3] + [2**32 - 1] * 3
    np.testing.assert_array_equal(normal_all[[4, 0]], normal[:2])
    assert not np.delete(normal_all, [4, 0], axis=0).any()
    empty = spread_cast(3, np.zeros(0, np.int64), t[:0], prim[:0], normal[:0])
    assert np.isinf(empty[0]).all() and (empty[1] == 2**32 - 1).all() and empty[2].shape == (3, 3)
