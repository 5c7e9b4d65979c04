"""Sky occlusion and mirror reflections (pipeline.sensors.indirect), and the filmic tone curve: closed forms on
hand-made scenes (real Embree), and their definitions ray by ray."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.sensors.indirect import (
    AO_RADIUS_M,
    AO_SAMPLES,
    AO_STRENGTH,
    INDIRECT_RANGE_M,
    _hemisphere,
    mirror_rays,
    occlusion_rays,
    sky_visibility,
    smooth_visibility,
)
from pipeline.sensors.shading import FILMIC_GAIN, shade, sky, to_srgb8
from pipeline.world.actors import Actors
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import condition


def plane(material: str = "asphalt", half_m: float = 200.0) -> Mesh:
    h = half_m
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index(material), SemanticClass.ROAD)


def down_rays(points_xy: np.ndarray, height_m: float = 5.0) -> np.ndarray:
    """(N, 6) float32 rays straight down onto the ground at the given (x, y)."""
    n = len(points_xy)
    return np.column_stack([points_xy, np.full(n, height_m), np.zeros((n, 2)), -np.ones(n)]).astype(np.float32)


def test_hemisphere_pattern_is_cosine_weighted_and_unit():
    d = _hemisphere(4096)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    assert (d[:, 2] > 0).all()
    # Cosine-weighted: E[cos] = 2/3 and E[cos^2] = 1/2 over the hemisphere.
    assert d[:, 2].mean() == pytest.approx(2.0 / 3.0, abs=2e-3)
    assert (d[:, 2] ** 2).mean() == pytest.approx(0.5, abs=2e-3)


def test_occlusion_rays_leave_the_surface_into_its_hemisphere():
    rng = np.random.default_rng(0)
    n = 500
    normal = rng.normal(size=(n, 3)).astype(np.float32)
    normal[:7] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 0], [0, -1, 0], [-1, 0, 0], [0, 0, -1]]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    rays = np.column_stack([rng.uniform(-5, 5, (n, 3)), -normal]).astype(np.float32)  # looking at the surface
    t = rng.uniform(1.0, 50.0, n).astype(np.float32)
    rows = np.arange(0, n, 2, dtype=np.int64)
    out = occlusion_rays(rays, t, normal, rows, _hemisphere(AO_SAMPLES), n).reshape(len(rows), AO_SAMPLES, 6)
    hit = rays[rows, :3] + rays[rows, 3:] * t[rows, None]
    lift = out[:, :, :3] - hit[:, None, :]
    np.testing.assert_allclose(np.einsum("rsk,rk->rs", lift, normal[rows]),
                               np.broadcast_to((2e-3 + 1e-4 * t[rows])[:, None], lift.shape[:2]), atol=1e-4)
    d = out[:, :, 3:]
    np.testing.assert_allclose(np.linalg.norm(d, axis=2), 1.0, atol=1e-5)
    cos = np.einsum("rsk,rk->rs", d, normal[rows])
    assert (cos > 0).all()
    # The pattern keeps its angles to the normal (it is only rotated about it).
    np.testing.assert_allclose(np.sort(cos, axis=1), np.broadcast_to(np.sort(_hemisphere(AO_SAMPLES)[:, 2]),
                                                                      cos.shape), atol=1e-5)
    # Same row, same rays: the rotation is a function of the row.
    again = occlusion_rays(rays, t, normal, rows, _hemisphere(AO_SAMPLES), n).reshape(len(rows), AO_SAMPLES, 6)
    np.testing.assert_array_equal(out, again)
    # Passes of n rays stacked (the anti-aliasing samples, shaded in one call): each pass's rows as if alone.
    two = occlusion_rays(np.concatenate([rays, rays]), np.concatenate([t, t]), np.concatenate([normal, normal]),
                         np.concatenate([rows, rows + n]), _hemisphere(AO_SAMPLES), n)
    np.testing.assert_array_equal(two.reshape(2, len(rows), AO_SAMPLES, 6), np.stack([out, out]))
    unstacked = occlusion_rays(np.concatenate([rays, rays]), np.concatenate([t, t]), np.concatenate([normal, normal]),
                               rows + n, _hemisphere(AO_SAMPLES), 2 * n).reshape(len(rows), AO_SAMPLES, 6)
    assert not np.array_equal(unstacked, out)  # the row's place sets the rotation


def test_sky_visibility_darkens_the_ground_beside_an_actor_only(box_meshes, actors_factory):
    """A 3 m tall box on open ground: a point 0.2 m from its side loses some sky (never more than AO_STRENGTH), a
    point 2 m beyond the AO radius loses none, and nothing is traced without actors."""
    actors = actors_factory([[0.0, 0.0, 1.5]], [[4.0, 2.0, 3.0]])
    scene = FrameScene(StaticScene([plane()]), actors, box_meshes)
    xy = np.array([[2.2, 0.0], [0.0, 1.2], [2.0 + AO_RADIUS_M + 2.0, 0.0], [30.0, 30.0]])
    rays = down_rays(xy)
    hits = scene.cast_rays(rays)
    v = sky_visibility(scene, rays, hits)
    assert 1.0 - AO_STRENGTH <= v[0] < 0.95 and 1.0 - AO_STRENGTH <= v[1] < 0.95
    assert v[2] == 1.0 and v[3] == 1.0
    empty = FrameScene(StaticScene([plane()]), Actors.empty())
    np.testing.assert_array_equal(sky_visibility(empty, rays, empty.cast_rays(rays)), 1.0)


def test_smooth_visibility_averages_over_one_surface_only():
    """A 6 x 6 grid: a checkerboard of blocked shares on instance 1 (left half, facing up) smooths to the mean of each
    pixel's same-surface neighbours; instance 2 (right half), a pixel facing another way, one at another depth and the
    untraced pixels never mix in."""
    h, w = 6, 6
    yy, xx = np.mgrid[0:h, 0:w]
    blocked = ((yy + xx) % 2).astype(np.float32).ravel()
    instance = np.where(xx < 3, 1, 2).astype(np.int32).ravel()
    normal = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (h * w, 1))
    t_m = np.full(h * w, 10.0, np.float32)
    traced = np.ones(h * w, bool)
    traced[5 * w + 0] = False  # (5, 0) untraced
    normal[0] = (1.0, 0.0, 0.0)  # (0, 0) faces another way
    t_m[1] = 11.0  # (0, 1) lies 10 % farther
    wanted = traced.copy()
    wanted[4 * w + 0] = False  # (4, 0) traced, but its value not asked for
    out = smooth_visibility(blocked, traced, wanted, instance, normal, t_m, h, w, 2, np.float32(0.95),
                            np.float32(0.03))

    def expected(y, x):
        if not wanted[y * w + x]:
            return 0.0
        own = y * w + x
        same = [j for j in range(h * w)
                if abs(j // w - y) <= 2 and abs(j % w - x) <= 2 and traced[j] and instance[j] == instance[own]
                and abs(t_m[j] - t_m[own]) <= 0.03 * t_m[own] and normal[j] @ normal[own] >= 0.95]
        return float(np.mean(blocked[same]))

    np.testing.assert_allclose(out, [expected(y, x) for y in range(h) for x in range(w)], rtol=1e-6)
    assert out[0] == blocked[0] and out[1] == blocked[1]  # alone on their surfaces
    assert out[5 * w] == 0.0 and out[4 * w] == 0.0
    assert 0.3 < out[3 * w + 1] < 0.7  # inside the checkerboard: near the mean, not 0 or 1
    # A wanted pixel takes its traced neighbours' mean though untraced itself; NaN where none is on its surface.
    asked = np.zeros(h * w, bool)
    asked[5 * w] = asked[0] = True
    alone = traced.copy()
    alone[0] = False
    probe = smooth_visibility(blocked, alone, asked, instance, normal, t_m, h, w, 2, np.float32(0.95),
                              np.float32(0.03))
    neighbours = [y * w + x for y in (3, 4, 5) for x in (0, 1, 2) if (y, x) != (5, 0)]  # all on its surface
    assert probe[5 * w] == pytest.approx(np.mean(blocked[neighbours]))
    assert np.isnan(probe[0])  # (0, 0) faces another way than all its neighbours


def test_camera_grid_smoothing_keeps_a_uniform_surface_uniform(box_meshes, actors_factory):
    """A 5 x 4 grid of rays onto the ground beside a box (all traced): smoothing over the grid keeps the mean
    occlusion and narrows its spread; an image shape that does not hold the rays is an error."""
    actors = actors_factory([[0.0, 0.0, 1.5]], [[4.0, 2.0, 3.0]])
    scene = FrameScene(StaticScene([plane()]), actors, box_meshes)
    gx, gy = np.meshgrid(np.linspace(2.1, 2.6, 4), np.linspace(-0.6, 0.6, 5))
    rays = down_rays(np.column_stack([gx.ravel(), gy.ravel()]))
    hits = scene.cast_rays(rays)
    plain, smoothed = sky_visibility(scene, rays, hits), sky_visibility(scene, rays, hits, (5, 4))
    assert (plain < 1.0).all() and (smoothed < 1.0).all()
    # the mean over the grid is kept up to the window's edge weighting, and the spread shrinks
    assert abs(smoothed.mean() - plain.mean()) < 0.05
    assert smoothed.std() <= plain.std()
    with pytest.raises(ValueError, match="does not hold"):
        sky_visibility(scene, rays, hits, (4, 4))


def test_camera_grid_traces_every_other_pixel_and_each_surface_alone(box_meshes, actors_factory, monkeypatch):
    """Of a camera grid's pixels, every other one traces (a checkerboard: (row + column) even) and the others take
    their surface's smoothed mean; a skipped pixel with no traced pixel of its surface nearby traces its own and
    keeps it (its value the unsmoothed one)."""
    import dataclasses

    actors = actors_factory([[0.0, 0.0, 1.5]], [[4.0, 2.0, 3.0]])
    scene = FrameScene(StaticScene([plane()]), actors, box_meshes)
    gx, gy = np.meshgrid(np.linspace(2.1, 2.6, 4), np.linspace(-0.6, 0.6, 5))
    rays = down_rays(np.column_stack([gx.ravel(), gy.ravel()]))
    hits = scene.cast_rays(rays)
    traced = []
    occluded_rays = FrameScene.occluded_rays
    monkeypatch.setattr(FrameScene, "occluded_rays",
                        lambda self, r, *a, **k: traced.append(r[::AO_SAMPLES, :3].copy()) or occluded_rays(self, r, *a,
                                                                                                              **k))
    smoothed = sky_visibility(scene, rays, hits, (5, 4))
    assert sum(len(t) for t in traced) == 10  # the 10 of 20 pixels with (row + column) even
    lone = 1 * 4 + 2  # (1, 2), skipped; tilt its normal away from its neighbours': alone on its surface
    normal = hits.normal.copy()
    normal[lone] = (0.6, 0.0, 0.8)
    tilted = dataclasses.replace(hits, normal=normal)
    traced.clear()
    with_lone = sky_visibility(scene, rays, tilted, (5, 4))
    assert sum(len(t) for t in traced) == 11  # the checkerboard, then the lone pixel
    assert with_lone[lone] == sky_visibility(scene, rays, tilted)[lone]  # its own 8 rays, unsmoothed
    others = np.arange(20) != lone
    np.testing.assert_array_equal(with_lone[others], smoothed[others])  # none of theirs: another surface


def test_sky_visibility_stops_beyond_its_range(box_meshes, actors_factory):
    """Hits farther than INDIRECT_RANGE_M from the camera are not traced (the same geometry, seen from afar)."""
    actors = actors_factory([[0.0, 0.0, 1.5]], [[4.0, 2.0, 3.0]])
    scene = FrameScene(StaticScene([plane()]), actors, box_meshes)
    near, far = down_rays(np.array([[2.2, 0.0]])), down_rays(np.array([[2.2, 0.0]]), INDIRECT_RANGE_M + 5.0)
    assert sky_visibility(scene, near, scene.cast_rays(near))[0] < 1.0
    assert sky_visibility(scene, far, scene.cast_rays(far))[0] == 1.0


def test_mirror_rays_closed_form():
    """A ray at 60 degrees from an upward normal: mirrored about it, F = F0 + (1 - F0) (1 - cos 60)^5."""
    d = np.array([np.sin(np.pi / 3), 0.0, -np.cos(np.pi / 3)])
    rays = np.array([[0.0, 0.0, 10.0, *d]], np.float32)
    t = np.array([10.0 / np.cos(np.pi / 3)], np.float32)
    mirror, weight = mirror_rays(rays, t, np.array([[0.0, 0.0, 1.0]], np.float32), np.array([0]),
                                 np.array([0.05], np.float32), np.zeros(1, np.float32), np.float32(0.02))
    np.testing.assert_allclose(mirror[0, 3:], [d[0], 0.0, -d[2]], atol=1e-6)
    np.testing.assert_allclose(mirror[0, :3], [10.0 * np.tan(np.pi / 3), 0.0, 2e-3 + 1e-4 * t[0]], atol=1e-4)
    assert weight[0] == pytest.approx(0.05 + 0.95 * 0.5 ** 5, rel=1e-5)


def test_paint_under_an_open_sky_mirrors_it():
    """Straight down onto a painted plane, no sun: with reflections the radiance is (1 - F0) x its own plus F0 x
    the sky straight up (F0 at normal incidence); sky occlusion changes nothing (no actors)."""
    lighting = condition(sun={"elevation_deg": -10.0}, sky={"ambient_rgb": (0.4, 0.4, 0.4)})
    scene = FrameScene(StaticScene([plane("paint")]), Actors.empty())
    rays = down_rays(np.array([[0.0, 0.0]]))
    hits = scene.cast_rays(rays)
    direct = shade(scene, rays, hits, lighting)
    indirect = shade(scene, rays, hits, lighting, indirect=True)
    f0 = material_arrays()["fresnel_f0"][material_index("paint")]
    up = sky(np.array([[0.0, 0.0, 1.0]], np.float32), lighting)
    np.testing.assert_allclose(indirect, (1.0 - f0) * direct + f0 * up, rtol=1e-5)
    # Materials without F0 (asphalt) are left as they were.
    matte = FrameScene(StaticScene([plane("asphalt")]), Actors.empty())
    hits = matte.cast_rays(rays)
    np.testing.assert_array_equal(shade(matte, rays, hits, lighting, indirect=True), shade(matte, rays, hits, lighting))


@pytest.mark.parametrize("x", [0.0, 0.01, 0.1, 0.18, 0.5, 1.0, 2.0, 3.9])
def test_filmic_curve_closed_form(x):
    g = FILMIC_GAIN * x
    y = g * (2.51 * g + 0.03) / (g * (2.43 * g + 0.59) + 0.14)
    srgb = 12.92 * y if y <= 0.0031308 else 1.055 * y ** (1 / 2.4) - 0.055
    got = to_srgb8(np.full((1, 3), x, np.float32), "filmic")
    assert np.abs(got.astype(int) - round(255 * min(srgb, 1.0))).max() <= 1


def test_tone_curves_are_monotonic_and_named():
    x = np.linspace(0.0, 4.0, 4001, dtype=np.float32)[:, None].repeat(3, axis=1)
    for curve in ("soft", "filmic"):
        assert (np.diff(to_srgb8(x, curve)[:, 0].astype(int)) >= 0).all()
    with pytest.raises(ValueError, match="unknown tone curve 'aces'; known: soft, filmic"):
        to_srgb8(x, "aces")
