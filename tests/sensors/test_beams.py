"""Beams in fog (pipeline.sensors.beams): single scattering out of spot lights, against closed forms and an
independent dense quadrature of the same integrand built from the surfaces' own spot-light model."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.geometry import Transform
from pipeline.sensors.beams import (
    beams,
    coarse_grid,
    distance_edges,
    henyey_greenstein,
    inscatter_tables,
)
from pipeline.sensors.conditions import get_condition
from pipeline.sensors.lights import (
    MIN_DISTANCE_M,
    cone_terms,
    ego_headlights,
    light_params,
    spot_strength,
    street_lamp_lights,
)


def _lamp_above(height_m: float, foot_m: float, intensity: float = 1000.0):
    """A downward lamp whose cone covers the whole lower half-space, uniform, unbounded in practice."""
    cfg = get_condition("night").street_lamps.model_copy(update={"half_angle_deg": 89.9, "range_m": 1e5,
                                                                   "intensity_cd": 1.0})
    lights = street_lamp_lights(np.array([[foot_m, 0.0, height_m]]), cfg, np.zeros(3))
    scale = intensity / float(lights.rgb[0].max())
    return lights.__class__(**{**lights.__dict__, "rgb": (lights.rgb * scale).astype(np.float32),
                               "soft": np.array([1e-3])})


def test_henyey_greenstein_integrates_to_one_and_is_isotropic_at_g_zero():
    mu = np.linspace(-1, 1, 200001, dtype=np.float64)
    for g in (0.0, 0.5, 0.85):
        p = henyey_greenstein(mu.astype(np.float32), g).astype(np.float64)
        assert 2 * np.pi * np.trapezoid(p, mu) == pytest.approx(1.0, rel=1e-3)
    assert np.allclose(henyey_greenstein(np.float32([-1, 0, 1]), 0.0), 1 / (4 * np.pi))


def test_a_ray_past_a_point_light_gathers_its_closed_form():
    """Isotropic light of intensity I at height h above a ray, isotropic phase, no extinction to speak of: the ray
    gathers pi * beta * I / (4 pi) * (atan((T - f) / h) + atan(f / h)) / h up to distance T (f: the foot)."""
    h, foot, intensity, beta = 2.0, 30.0, 1000.0, 1e-7
    lights = _lamp_above(h, foot, intensity)
    edges = distance_edges(200.0)
    table = inscatter_tables(np.zeros(3), np.array([[1.0, 0.0, 0.0]]), lights, beta, edges, g=0.0,
                             forward_lobe_deg=0.0)[0, :, 0]
    for k in (20, 40, 64):
        t = float(edges[k])
        expected = beta / 4 * intensity * (np.arctan((t - foot) / h) + np.arctan(foot / h)) / h
        assert table[k] == pytest.approx(expected, rel=5e-3), t  # within a sample of the edge
    assert table[0] == 0 and np.all(np.diff(table) >= 0)


def test_the_closest_approach_is_clamped_as_the_surfaces_shading_clamps_it():
    lights = _lamp_above(0.05, 10.0)
    edges = distance_edges(100.0)
    near = inscatter_tables(np.zeros(3), np.array([[1.0, 0.0, 0.0]]), lights, 1e-7, edges, g=0.0,
                            forward_lobe_deg=0.0)[0, -1, 0]
    bound = 1e-7 / 4 * 1000.0 * np.pi / MIN_DISTANCE_M
    assert near <= bound * 1.001 and near > 0.5 * bound


def test_the_compiled_cone_is_the_surfaces_spot_strength_without_the_inverse_square():
    condition = get_condition("night")
    pose = Transform.from_xyz_rpy([3.0, -1.0, 0.75], [0.0, 0.0, 0.3])
    lights = ego_headlights(pose, condition.headlights)
    lights = lights.concatenate([lights, street_lamp_lights(np.array([[10.0, 5.0, 6.7]]), condition.street_lamps,
                                                            np.zeros(3))])
    rng = np.random.default_rng(0)
    points = rng.uniform([-5, -20, -1], [60, 20, 8], (4000, 3))
    for k in range(len(lights)):
        p = light_params(lights, k)
        v = (lights.position_m[k] - points).astype(np.float32)
        d2 = (v * v).sum(axis=1)
        axial = -(v @ lights.axis[k].astype(np.float32))
        front = np.flatnonzero((axial > 0) & (d2 < np.float32(lights.range_m[k] ** 2)))
        numpy = spot_strength(lights, k, [v[front, c] for c in range(3)], d2[front], axial[front])
        numpy = numpy * np.maximum(d2[front], np.float32(MIN_DISTANCE_M ** 2))
        compiled = np.array([np.prod(cone_terms(p, *v[i], d2[i], axial[i])) for i in front], np.float32)
        assert np.count_nonzero(compiled) > 50
        assert np.allclose(compiled, numpy, rtol=1e-5, atol=1e-7)


def test_low_beams_in_fog_match_a_dense_quadrature_of_the_same_integrand():
    """The ego's low beams seen from its camera, HG phase, the forward lobe left out, 150 m fog: the equiangular
    tables against 400k midpoint samples of the integrand written here from the surfaces' spot_strength."""
    condition = get_condition("night-fog")
    beta = condition.extinction_per_m()
    pose = Transform.from_xyz_rpy([0.0, 0.0, 0.75], [0.0, 0.0, 0.0])
    lights = ego_headlights(pose, condition.headlights)
    origin = np.array([0.6, 0.0, 1.4])
    directions = np.array([[1.0, 0.0, -0.08], [1.0, 0.1, -0.03], [1.0, -0.2, -0.05]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    edges = distance_edges(130.0)
    tables = inscatter_tables(origin, directions, lights, beta, edges)
    g, cos_min = 0.85, np.cos(np.radians(20.0))
    s = (np.arange(400000) + 0.5) * (130.0 / 400000)
    assert len(lights) == 2  # the beam and the light above its cut-off, both at the lamps
    for d, table in zip(directions, tables, strict=True):
        x = origin + s[:, None] * d
        f = np.zeros(len(s), np.float64)
        for k in range(len(lights)):
            v = (lights.position_m[k] - x).astype(np.float32)
            d2 = (v * v).sum(axis=1)
            axial = -(v @ lights.axis[k].astype(np.float32))
            e = np.zeros(len(s), np.float64)
            front = np.flatnonzero((axial > 0) & (d2 < lights.range_m[k] ** 2))
            e[front] = spot_strength(lights, k, [v[front, c] for c in range(3)], d2[front], axial[front])
            cos_theta = (v @ d.astype(np.float32)) / np.sqrt(d2)
            phase = np.where(cos_theta < cos_min, henyey_greenstein(cos_theta, g), 0.0)
            f += np.pi * beta * phase * e * np.exp(-beta * (s + np.sqrt(d2))) * float(lights.rgb[k, 0])
        reference = np.concatenate([[0.0], np.cumsum(f) * (130.0 / 400000)])
        for k in (30, 45, 64):
            want = reference[round(float(edges[k]) / 130.0 * 400000)]
            assert want > 0
            assert table[k, 0] == pytest.approx(want, rel=0.01), (d, float(edges[k]))


def test_each_pixel_reads_the_tables_at_its_own_distance():
    condition = get_condition("night-fog")
    lights = ego_headlights(Transform.from_xyz_rpy([0.0, 0.0, 0.75], [0.0, 0.0, 0.0]), condition.headlights)
    h, w = 17, 25
    yy, xx = np.mgrid[0:h, 0:w]
    directions = np.stack([np.ones((h, w)), -(xx - 12) * 0.02, -(yy - 8) * 0.02 - 0.02], axis=-1).reshape(-1, 3)
    directions = (directions / np.linalg.norm(directions, axis=1, keepdims=True)).astype(np.float32)
    origin = np.array([0.6, 0.0, 1.4])
    distance = np.where(np.arange(h * w) % 3 == 0, np.inf, 5.0 + (np.arange(h * w) % 7)).astype(np.float32)
    image = beams(origin, directions, distance, (h, w), lights, condition.extinction_per_m(), step=8)
    rows, cols = coarse_grid(h, w, 8)
    assert list(rows) == [0, 8, 16] and list(cols) == [0, 8, 16, 24]
    reach = float(np.linalg.norm(lights.position_m[0] - origin) + lights.range_m[0])
    edges = distance_edges(reach)
    coarse = directions.reshape(h, w, 3)[rows][:, cols].reshape(-1, 3)
    tables = inscatter_tables(origin, coarse, lights, condition.extinction_per_m(), edges).reshape(3, 4, -1, 3)

    def read(r, c, t):
        return np.array([np.interp(min(t, edges[-1]), edges, tables[r, c, :, ch]) for ch in range(3)])

    for y, x in [(8, 16), (0, 0), (16, 24)]:  # on the grid: its own table
        i = y * w + x
        assert image[i] == pytest.approx(read(list(rows).index(y), list(cols).index(x), distance[i]), rel=1e-5)
    y, x = 8, 20  # halfway between two columns of the grid: the mean of the two tables at its distance
    i = y * w + x
    assert image[i] == pytest.approx(0.5 * (read(1, 2, distance[i]) + read(1, 3, distance[i])), rel=1e-5)
    assert image.max() > 0


def test_no_lights_or_no_fog_scatter_nothing():
    lights = _lamp_above(2.0, 10.0)
    d = np.array([[1.0, 0.0, 0.0]], np.float32)
    assert not beams(np.zeros(3), d, np.array([50.0], np.float32), (1, 1), lights, 0.0).any()
    assert not beams(np.zeros(3), d, np.array([50.0], np.float32), (1, 1), lights.empty(), 0.02).any()


def test_an_image_of_one_row_reads_its_own_tables():
    lights = _lamp_above(2.0, 10.0)
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.1, 0.0], [1.0, 0.2, 0.0]], np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out = beams(np.zeros(3), d, np.full(3, 30.0, np.float32), (1, 3), lights, 0.01, step=2)
    assert np.isfinite(out).all() and (out > 0).all() and out[0, 0] > out[2, 0]
