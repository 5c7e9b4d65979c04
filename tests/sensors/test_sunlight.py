"""The compiled sun and sky passes in closed form: which hits face the sun, where their shadow rays start, and the
radiance of lit, shadowed, glossy and missed rays."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sensors.shadows import sun_rays
from pipeline.sensors.sky import gradient_params
from pipeline.sensors.sunlight import sky_and_sun

SUN = np.array([0.0, 0.6, 0.8], np.float32)
SUN_RGB, AMBIENT = np.array([2.0, 1.5, 1.0], np.float32), np.array([0.5, 0.25, 0.125], np.float32)
ZENITH, HORIZON = np.array([0.1, 0.2, 0.6], np.float32), np.array([0.7, 0.8, 0.9], np.float32)
POINT_SUN = SUN[None]  # a point sun: every shadow ray along SUN


def _rays(directions):
    d = np.asarray(directions, np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.concatenate([np.tile(np.float32([1.0, 2.0, 3.0]), (len(d), 1)), d], axis=1)


def test_hits_facing_the_sun_get_shadow_rays_from_just_above_the_hit():
    rays = _rays([[1, 0, -1], [1, 0, -1], [0, 1, 0], [0, 0, 1]])
    normal = np.float32([[0, 0, 1], [0, 0, -1], [0, -1, 0], [0, 0, 0]])  # up; down; towards y-; a miss
    t = np.float32([10.0, 10.0, 20.0, np.inf])
    n_dot_l, lit, shadow, which = sun_rays(rays, normal, t, SUN, POINT_SUN, 0, len(rays))
    np.testing.assert_allclose(n_dot_l, [0.8, -0.8, -0.6, 0.0], atol=1e-7)
    assert lit.tolist() == [0]
    hit_point = rays[0, :3] + 10.0 * rays[0, 3:]
    np.testing.assert_allclose(shadow[0, :3], hit_point + (1e-3 + 1e-4 * 10.0) * normal[0], atol=1e-6)
    np.testing.assert_array_equal(shadow[0, 3:], SUN)
    assert which.tolist() == [0]


def test_shadow_rays_follow_the_disc_cell_of_their_pixel():
    # A 4 x 4 image of ground lit from above: pixel (x, y) takes disc row 4 v + u, u and v from x and y modulo 4
    # (bit-reversed: each 2 x 2 block covers both halves of the disc in both axes).
    rays = _rays([[0, 0, -1]] * 16)
    normal = np.tile(np.float32([0, 0, 1]), (16, 1))
    disc = np.arange(48, dtype=np.float32).reshape(16, 3)  # stand-ins: only which row is copied matters
    _, lit, shadow, which = sun_rays(rays, normal, np.full(16, 2.0, np.float32), SUN, disc, 4, 16)
    reversed2 = [0, 2, 1, 3]
    expected = [4 * reversed2[y] + reversed2[x] for y in range(4) for x in range(4)]
    assert lit.tolist() == list(range(16)) and which.tolist() == expected
    np.testing.assert_array_equal(shadow[:, 3:], disc[expected])
    for y in range(3):
        for x in range(3):  # every 2 x 2 block: both halves of the disc in u and in v
            block = [which[(y + a) * 4 + x + b] for a in (0, 1) for b in (0, 1)]
            assert sorted((k % 4) // 2 + 2 * ((k // 4) // 2) for k in block) == [0, 1, 2, 3]


def test_stacked_passes_choose_their_disc_rows_as_each_pass_alone():
    # Rays of no image (width 0: as if in rows of 4), 10 a pass, stacked three times (the anti-aliasing samples,
    # shaded in one call with period 10): each pass takes the rows it would take alone.
    rays = _rays([[0, 0, -1]] * 10)
    normal = np.tile(np.float32([0, 0, 1]), (10, 1))
    disc = np.arange(48, dtype=np.float32).reshape(16, 3)
    t = np.full(10, 2.0, np.float32)
    _, _, _, alone = sun_rays(rays, normal, t, SUN, disc, 0, 10)
    _, _, _, stacked = sun_rays(np.tile(rays, (3, 1)), np.tile(normal, (3, 1)), np.tile(t, 3), SUN, disc, 0, 10)
    np.testing.assert_array_equal(stacked, np.tile(alone, 3))
    _, _, _, one_pass = sun_rays(np.tile(rays, (3, 1)), np.tile(normal, (3, 1)), np.tile(t, 3), SUN, disc, 0, 30)
    assert not np.array_equal(one_pass, stacked)


def _shade(rays, hit, normal, material, color, unshadowed, specular, shininess):
    n_dot_l, lit, _, _ = sun_rays(rays, normal, np.full(len(rays), 5.0, np.float32), SUN, POINT_SUN, 0,
                              len(rays))
    return sky_and_sun(rays, np.asarray(hit), normal, np.asarray(material, np.int32), np.asarray(color, np.float32),
                       n_dot_l, lit, np.asarray(unshadowed, np.float32)[: len(lit)], np.asarray(specular, np.float32),
                       np.asarray(shininess, np.float32), SUN, SUN_RGB, AMBIENT, gradient_params(ZENITH, HORIZON))


def test_lambert_shadow_highlight_and_sky():
    # Ray 0 looks straight down at ground whose normal points at the sun: n.l = 1. Ray 1 the same, shadowed. Ray 2
    # looks at flat ground (normal +z) along the sun's mirror image, so the half-vector is +z: n.h = 1, a full
    # highlight, and n.l = 0.8. Rays 3 and 4 miss, looking straight up and along the horizon.
    rays = _rays([[0, 0, -1], [0, 0, -1], [0, 0.6, -0.8], [0, 0, 1], [1, 0, 0]])
    normal = np.float32([SUN, SUN, [0, 0, 1], [0, 0, 0], [0, 0, 0]])
    color = np.float32([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.2, 0.2, 0.2], [0, 0, 0], [0, 0, 0]])
    out = _shade(rays, [True, True, True, False, False], normal, [0, 0, 1, 0, 0], color,
                 unshadowed=[True, False, True], specular=[0.0, 0.5], shininess=[1.0, 40.0])
    np.testing.assert_allclose(out[0], 0.5 * (AMBIENT + SUN_RGB), rtol=1e-6)
    np.testing.assert_allclose(out[1], 0.5 * AMBIENT, rtol=1e-6)
    np.testing.assert_allclose(out[2], 0.2 * (AMBIENT + SUN_RGB * 0.8) + SUN_RGB * 0.5, rtol=1e-5)
    np.testing.assert_allclose(out[3], ZENITH, rtol=1e-6)
    np.testing.assert_allclose(out[4], HORIZON, rtol=1e-6)


@pytest.mark.parametrize("shininess", [1.0, 10.0, 80.0])
def test_highlight_falls_off_as_n_dot_h_to_the_shininess(shininess):
    rays = _rays([[0, 0, -1]])
    tilt = np.radians(20.0)  # the normal 20 deg off the half-vector of the sun and the straight-down view
    half = (SUN + np.float32([0, 0, 1])) / np.linalg.norm(SUN + np.float32([0, 0, 1]))
    axis = np.cross(half, [1.0, 0.0, 0.0])
    axis /= np.linalg.norm(axis)
    normal = (half * np.cos(tilt) + np.cross(axis, half) * np.sin(tilt)).astype(np.float32)[None]
    out = _shade(rays, [True], normal, [1], [[0.0, 0.0, 0.0]], [True], [0.0, 0.5], [1.0, shininess])
    np.testing.assert_allclose(out[0], SUN_RGB * 0.5 * np.cos(tilt) ** shininess, rtol=1e-4)


@pytest.mark.parametrize("exponent", [1.0, 16.0, 48.0, 96.0, 1024.0, 2.5, 2000.0])
def test_power_is_within_a_few_ulps_of_the_exact_power(exponent):
    from pipeline.sensors.sunlight import _power

    x = np.linspace(0.0, 1.0, 1001).astype(np.float32)
    got = np.array([_power(v, np.float32(exponent)) for v in x], np.float64)
    exact = x.astype(np.float64) ** exponent
    tiny = exact < 1e-30  # float32 underflow: both ~0
    np.testing.assert_allclose(got[~tiny], exact[~tiny], rtol=4e-5 if exponent <= 1024 else 1e-6)
    assert np.all(got[tiny] < 1e-30) and got[0] == 0.0 and got[-1] == 1.0


def test_a_partly_seen_sun_scales_its_light_and_highlight():
    # As ray 2 of test_lambert_shadow_highlight_and_sky (n.l = 0.8, a full highlight), with a quarter of the sun's
    # disc seen: sun light and highlight x 0.25, the ambient unchanged.
    rays = _rays([[0, 0.6, -0.8]])
    out = _shade(rays, [True], np.float32([[0, 0, 1]]), [1], [[0.2, 0.2, 0.2]], unshadowed=[0.25],
                 specular=[0.0, 0.5], shininess=[1.0, 40.0])
    np.testing.assert_allclose(out[0], 0.2 * (AMBIENT + SUN_RGB * 0.8 * 0.25) + SUN_RGB * 0.5 * 0.25, rtol=1e-5)
