"""The sky (pipeline.sensors.sky): Preetham et al.'s formulas at hand-computed values, the compiled sky against its
float64 definition, the shape of the daylight sky (symmetric about the sun's vertical plane, brightest at the sun,
bluer overhead), its scale, and the gradient exactly as it was."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sensors.conditions import get_condition
from pipeline.sensors.post import luminance
from pipeline.sensors.sky import (
    gradient_params,
    perez,
    perez_coefficients,
    preetham_params,
    sky_rays,
    xyy_to_rgb,
    zenith_chromaticity,
    zenith_luminance_kcd,
)
from tests.sensors.conftest import condition


def _direction(elevation_deg, azimuth_deg):
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)


SUN = _direction(30.0, 40.0)


def test_zenith_luminance_at_hand_computed_values():
    # T = 3, theta_s = 45 deg: chi = (4/9 - 3/120) (pi - pi/2) = 0.658862, tan chi = 0.774283,
    # Y_z = (4.0453 * 3 - 4.9710) * 0.774283 - 0.2155 * 3 + 2.4192 = 7.32036 kcd/m^2.
    assert zenith_luminance_kcd(3.0, np.pi / 4) == pytest.approx(7.32036, abs=1e-5)
    # T = 2, sun overhead: chi = (4/9 - 2/120) pi = 1.343904, tan chi = 4.33129; Y_z = 3.1196 * 4.33129 + 1.9882.
    assert zenith_luminance_kcd(2.0, 0.0) == pytest.approx(15.50067, abs=1e-4)


def test_zenith_chromaticity_at_hand_computed_values():
    # Sun overhead (theta_s = 0): only the last column of each matrix: x = 0.00394 T + 0.25886, y = 0.00516 T + 0.26688.
    assert zenith_chromaticity(2.0, 0.0) == pytest.approx((0.26674, 0.27720), abs=1e-9)
    # T = 4, theta_s = 1 rad: the T^2 row of x sums to 0; x = 4 * 0.00666 + 0.22435, y = 16 * -0.00018 + 4 * 0.01119
    # + 0.21948.
    assert zenith_chromaticity(4.0, 1.0) == pytest.approx((0.25099, 0.26136), abs=1e-9)


def test_perez_coefficients_and_function_at_known_angles():
    c = perez_coefficients(2.0)
    # The luminance row of the paper's table at T = 2: 0.1787 T - 1.4630, -0.3554 T + 0.4275, ...
    np.testing.assert_allclose(c[0], [-1.1056, -0.2833, 5.2797, -2.3359, 0.2363], atol=1e-12)
    a, b, cc, d, e = c[0]
    # Zenith towards the sun: F(0, 0) = (1 + A e^B) (1 + C + E).
    assert perez(c[0], 0.0, 0.0) == pytest.approx((1 + a * np.exp(b)) * (1 + cc + e), rel=1e-12)
    # At the horizon the gradation term vanishes (B < 0): F(pi/2, gamma) = 1 + C e^(D gamma) + E cos^2 gamma.
    gamma = np.radians(70.0)
    assert perez(c[0], np.pi / 2, gamma) == pytest.approx(1 + cc * np.exp(d * gamma) + e * np.cos(gamma) ** 2,
                                                          rel=1e-12)


def test_compiled_sky_follows_its_definition():
    """Ray by ray, the float32 kernel equals Y = Y_z F(theta, gamma) / F(0, theta_s) (and x, y likewise) through
    xyY -> XYZ -> linear sRGB, times the scale (float64 reference, 2e-4 relative)."""
    turbidity = 2.7
    params = preetham_params(SUN, turbidity, 0.4)
    el, az = np.meshgrid(np.linspace(1.0, 89.0, 23), np.linspace(-180.0, 180.0, 37))
    d = _direction(el.ravel(), az.ravel())
    theta, gamma = np.arccos(d[:, 2]), np.arccos(np.clip(d @ SUN, -1.0, 1.0))
    theta_s = np.arccos(SUN[2])
    c = perez_coefficients(turbidity)
    zenith = [zenith_luminance_kcd(turbidity, theta_s), *zenith_chromaticity(turbidity, theta_s)]
    lum, x, y = (z * perez(c[k], theta, gamma) / perez(c[k], 0.0, theta_s) for k, z in enumerate(zenith))
    unscaled = xyy_to_rgb(x, y, lum)
    got = sky_rays(d, params).astype(np.float64)
    scale = got[:, 1].sum() / unscaled[:, 1].sum()
    np.testing.assert_allclose(got, np.maximum(unscaled * scale, 0.0), rtol=2e-4, atol=1e-6)


def test_daylight_sky_is_symmetric_about_the_suns_vertical_plane():
    params = preetham_params(SUN, 3.0, 0.4)
    el, off = np.meshgrid(np.linspace(0.0, 85.0, 18), np.linspace(5.0, 175.0, 18))
    left = sky_rays(_direction(el.ravel(), 40.0 + off.ravel()), params)
    right = sky_rays(_direction(el.ravel(), 40.0 - off.ravel()), params)
    np.testing.assert_allclose(left, right, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("sun_elevation_deg", [12.0, 30.0, 65.0])
def test_daylight_sky_is_brightest_at_the_sun_and_bluest_overhead_away_from_it(sun_elevation_deg):
    sun = _direction(sun_elevation_deg, 40.0)
    params = preetham_params(sun, 2.5, 0.4)
    el, az = np.meshgrid(np.linspace(0.0, 90.0, 181), np.linspace(-180.0, 180.0, 721))
    d = _direction(el.ravel(), az.ravel())
    lum = luminance(sky_rays(d, params))
    brightest = d[np.argmax(lum)]
    assert np.degrees(np.arccos(np.clip(brightest @ sun, -1, 1))) < 5.0
    # Away from the sun: brighter and whiter (a smaller blue share) at the horizon than high up; bluest overhead.
    away = _direction(np.array([0.0, 40.0, 90.0]), 220.0)
    horizon, high, zenith = sky_rays(away, params)
    assert luminance(horizon) > luminance(high)
    blue = [v[2] / v.sum() for v in (horizon, high, zenith)]
    assert blue[0] < blue[1] and blue[0] < blue[2]
    # Around the sun brighter than at the same elevation opposite it.
    near, opposite = sky_rays(_direction(np.full(2, sun_elevation_deg), np.array([50.0, 220.0])), params)
    assert luminance(near) > 2.0 * luminance(opposite)


def test_daylight_sky_gives_the_ambients_luminance_to_a_surface_facing_up():
    """Scale: the cosine-weighted mean luminance over the upper hemisphere (the irradiance on a horizontal surface /
    pi) is the target, by an independent quadrature (midpoint rule in theta and phi, not the module's directions)."""
    params = preetham_params(SUN, 3.0, 0.38)
    theta = (np.arange(180) + 0.5) * (np.pi / 2) / 180
    phi = (np.arange(360) + 0.5) * 2 * np.pi / 360
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    lum = luminance(sky_rays(d, params).astype(np.float64)).reshape(t.shape)
    mean = (lum * np.cos(t) * np.sin(t)).sum() * (np.pi / 2 / 180) * (2 * np.pi / 360) / np.pi
    assert mean == pytest.approx(0.38, rel=5e-3)


def test_gradient_sky_is_exactly_the_old_blend():
    zen, hor = np.float32([0.2, 0.32, 0.6]), np.float32([0.85, 0.72, 0.6])
    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    up = np.sqrt(np.clip(d[:, 2], np.float32(0.0), np.float32(1.0)))
    expected = np.stack([hor[k] + (zen[k] - hor[k]) * up for k in range(3)], axis=1)
    np.testing.assert_array_equal(sky_rays(d, gradient_params(zen, hor)), expected)


def test_conditions_choose_their_sky():
    assert get_condition("night").config.sky.model == "gradient"
    for name in ("morning", "noon"):
        lit = get_condition(name)
        assert lit.config.sky.model == "preetham"
        up = sky_rays(np.float32([[0.0, 0.0, 1.0]]), lit.sky_params)[0]
        assert up[2] > up[0]  # blue overhead
    plain = condition(sky={"zenith_rgb": (0.1, 0.2, 0.3), "horizon_rgb": (0.4, 0.5, 0.6)})
    np.testing.assert_array_equal(plain.sky_params, gradient_params((0.1, 0.2, 0.3), (0.4, 0.5, 0.6)))
