"""Post effects: vignetting factor, shot + read noise statistics, seeded rain, motion blur, bloom, the optics'
point-spread function."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pipeline.core.config.sensors import ImageSensorConfig, LensConfig
from pipeline.sensors.exposure import exposure_for
from pipeline.sensors.post import (
    apply_post,
    bloom,
    motion_blur,
    motion_flow,
    point_spread,
    psf_taps,
    sensor_noise,
    standard_normal,
    vignette,
)

H, W = 600, 800


def test_vignetting_darkens_corners_by_the_configured_factor():
    image = np.ones((H, W, 3), np.float32)
    out = vignette(image, 0.3)
    for row, col in ((0, 0), (0, W - 1), (H - 1, 0), (H - 1, W - 1)):
        # The corner pixel's centre lies half a pixel inside the corner: within 0.5 % of 1 - 0.3.
        assert out[row, col, 0] == pytest.approx(0.7, rel=5e-3)
    assert out[H // 2, W // 2, 0] == pytest.approx(1.0, abs=1e-5)
    assert np.all(np.diff(out[H // 2, W // 2:, 0]) <= 0)  # monotone towards the edge
    lens = LensConfig(vignetting=0.3)
    post = apply_post(image, lens, None)
    np.testing.assert_allclose(post, out)


EXPOSURE = exposure_for(ImageSensorConfig(), 1 / 60, 4.0)  # a dim frame's exposure: visible noise


def test_noise_follows_the_shot_plus_read_model():
    for gain, level in ((1.0, 0.2), (16.0, 0.05)):
        exposure = exposure_for(ImageSensorConfig(), 1 / 100, gain)
        image = np.full((400, 400, 3), level, np.float32)
        noisy = sensor_noise(image, exposure, np.random.default_rng(1))
        expected = np.sqrt(exposure.shot_scale * level + exposure.read_variance)
        assert noisy.std() == pytest.approx(expected, rel=0.02)
        assert noisy.mean() == pytest.approx(level, abs=3 * expected / 400)


def test_each_pixel_gets_its_own_sigma_times_one_draw():
    rng = np.random.default_rng(4)
    image = (rng.random((30, 40, 3)) * 1.2 - 0.2).astype(np.float32)  # some below 0: read noise only there
    noisy = sensor_noise(image, EXPOSURE, np.random.default_rng(5))
    draws = standard_normal(image.shape, np.random.default_rng(5))  # the same draws: the same generator state
    sigma = np.sqrt(EXPOSURE.shot_scale * np.maximum(image.astype(np.float64), 0.0) + EXPOSURE.read_variance)
    np.testing.assert_allclose(noisy, image + draws * sigma, rtol=1e-5, atol=1e-6)


def test_same_seed_same_post_and_streaks_blend_towards_the_drops_radiance():
    rng_image = np.random.default_rng(9).random((120, 160, 3)).astype(np.float32) * 0.5
    lens = LensConfig(vignetting=0.2, bloom_strength=0.3, lens_flare=0.1)
    a = apply_post(rng_image, lens, np.random.default_rng(3), lens_drops=3, sensor=EXPOSURE)
    b = apply_post(rng_image, lens, np.random.default_rng(3), lens_drops=3, sensor=EXPOSURE)
    c = apply_post(rng_image, lens, np.random.default_rng(4), lens_drops=3, sensor=EXPOSURE)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # A pixel covered by drops for a share a of the exposure: (1 - a) of the scene, a of the drops' radiance.
    plain = LensConfig(vignetting=0.0)
    cover = np.zeros((120, 160), np.float32)
    cover[10, 20], cover[30, 40] = 0.25, 1.0
    out = apply_post(rng_image, plain, None, streaks=cover, streak_radiance=0.8, gain=2.0)
    ref = apply_post(rng_image, plain, None, gain=2.0)
    np.testing.assert_allclose(out[10, 20], 0.75 * ref[10, 20] + 0.25 * 1.6, rtol=1e-5)
    np.testing.assert_allclose(out[30, 40], 1.6, rtol=1e-5)
    untouched = cover == 0
    np.testing.assert_array_equal(out[untouched], ref[untouched])


def test_motion_flow_closed_form_and_blur():
    # Moving 1 m forward: a point 10 m ahead on the axis stays put, one 1 m to the right moves outwards by
    # fx * (1/9 - 1/10) pixels.
    flow = motion_flow(np.array([[0.0, 0.0, 10.0], [1.0, 0.0, 10.0], [np.inf, np.inf, np.inf]]),
                       np.array([0.0, 0.0, 1.0]), 400.0, 400.0)
    np.testing.assert_allclose(flow, [[0, 0], [400.0 * (1 / 9 - 1 / 10), 0], [0, 0]], atol=1e-4)
    # One shift per point (a road user moving with its pixels): each as if alone; across the near plane, none.
    points = np.array([[1.0, 2.0, 10.0], [-3.0, 1.0, 5.0], [0.5, 0.5, 0.5]])
    shifts = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, -2.0], [0.0, 0.0, 0.45]])
    per_point = motion_flow(points, shifts, 400.0, 300.0)
    for k in range(2):
        np.testing.assert_array_equal(per_point[k], motion_flow(points[k:k + 1], shifts[k], 400.0, 300.0)[0])
    np.testing.assert_allclose(per_point[1], [400.0 * (-3.5 / 7 + 3 / 5), 300.0 * (1 / 7 - 1 / 5)], rtol=1e-6)
    assert per_point[2].tolist() == [0.0, 0.0]  # q_z = 0.05 m: behind the near plane after the move
    with pytest.raises(ValueError, match="shift_cam"):
        motion_flow(points, shifts[:2], 400.0, 300.0)
    edge = np.zeros((40, 40, 3), np.float32)
    edge[:, 20:] = 1.0
    assert motion_blur(edge, np.zeros((40, 40, 2), np.float32)) is edge
    blurred = motion_blur(edge, np.tile(np.array([8.0, 0.0], np.float32), (40, 40, 1)))
    row = blurred[20, :, 0]
    assert row[10] == 0.0 and row[30] == 1.0 and 0.2 < row[19] < 0.8 and 0.2 < row[20] < 0.8
    np.testing.assert_allclose(blurred.mean(), edge.mean(), atol=0.02)


def test_bloom_adds_light_only_around_bright_sources():
    image = np.full((120, 160, 3), 0.1, np.float32)
    image[60, 80] = 50.0
    out = bloom(image, threshold=1.0, strength=0.5, sigma_px=6.0)
    assert out[60, 86, 0] > 0.1 + 1e-3  # glow a few pixels away
    np.testing.assert_allclose(out[5, 5], image[5, 5], atol=1e-4)  # far away: (nearly) untouched
    np.testing.assert_array_equal(bloom(image, 1.0, 0.0, 6.0), image)


def test_standard_normal_is_seeded_and_standard_in_every_channel():
    from pipeline.sensors.post import standard_normal

    a = standard_normal((300, 400, 3), np.random.default_rng(7))
    np.testing.assert_array_equal(a, standard_normal((300, 400, 3), np.random.default_rng(7)))
    assert not np.array_equal(a, standard_normal((300, 400, 3), np.random.default_rng(8)))
    n = a[..., 0].size
    for channel in np.moveaxis(a, -1, 0):
        assert abs(channel.mean()) < 5 / np.sqrt(n)
        assert channel.std() == pytest.approx(1.0, abs=5 * np.sqrt(0.5 / n))
    x = a.reshape(-1).astype(np.float64)
    assert np.mean(x**4) == pytest.approx(3.0, abs=5 * np.sqrt(96 / x.size))  # Gaussian tails
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 5 / np.sqrt(x.size)  # no correlation between neighbours


def test_normal_draws_are_splitmix64_quarters_indexing_the_quantiles():
    from scipy.stats import norm

    from pipeline.sensors.post import NORMAL_QUANTILES, _normal_draws, _splitmix64

    # SplitMix64's published outputs for seed 0 (Vigna's splitmix64.c).
    assert _splitmix64(np.uint64(0), 0) == 16294208416658607535
    assert _splitmix64(np.uint64(0), 1) == 7960286522194355700
    np.testing.assert_allclose(NORMAL_QUANTILES[[0, 32767, 32768, 65535]],
                               norm.ppf(np.array([0.5, 32767.5, 32768.5, 65535.5]) / 65536), rtol=1e-6)
    np.testing.assert_array_equal(NORMAL_QUANTILES, -NORMAL_QUANTILES[::-1])  # symmetric
    key = np.uint64(123456789)
    draws = np.empty(11, np.float32)
    _normal_draws(draws, key, NORMAL_QUANTILES.copy())
    bits = [int(_splitmix64(key, k)) for k in range(3)]
    expected = [NORMAL_QUANTILES[(bits[i // 4] >> (16 * (i % 4))) & 0xFFFF] for i in range(11)]
    np.testing.assert_array_equal(draws, expected)  # the last three from a part of the third output


def test_post_scales_by_the_gain_before_the_sensors_noise():
    lens = LensConfig(vignetting=0.0, bloom_strength=0.0)
    read_only = replace(exposure_for(ImageSensorConfig(read_noise_e=100.0), 1 / 100, 1.0), shot_scale=0.0)
    image = np.full((40, 50, 3), 0.05, np.float32)
    plain = apply_post(image, lens, np.random.default_rng(3), sensor=read_only)
    bright = apply_post(image, lens, np.random.default_rng(3), gain=3.0, sensor=read_only)
    np.testing.assert_allclose(bright - 0.15, plain - 0.05, atol=1e-6)  # same noise draws, scaled image


def test_wide_dynamic_range_is_a_power_law_about_the_pivot_that_keeps_hue():
    from pipeline.sensors.post import WDR_PIVOT, wide_dynamic_range

    colour = np.array([0.5, 1.0, 2.0], np.float32)  # one hue at three brightnesses
    luma = float(colour @ np.array([0.2126, 0.7152, 0.0722], np.float32))
    levels = np.array([WDR_PIVOT / 64, WDR_PIVOT / 4, WDR_PIVOT, 8 * WDR_PIVOT], np.float32)
    image = (levels[:, None] / luma * colour[None, :]).reshape(1, 4, 3).astype(np.float32)
    out = wide_dynamic_range(image, 0.5)[0]
    out_luma = out @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    # L -> p (L / p)^0.5: 1/64 of the pivot becomes 1/8 of it, 8x the pivot becomes 2.83x; the pivot stays
    np.testing.assert_allclose(out_luma, WDR_PIVOT * (levels / WDR_PIVOT) ** 0.5, rtol=1e-5)
    np.testing.assert_allclose(out / out[:, 1:2], image[0] / image[0][:, 1:2], rtol=1e-5)  # channel ratios kept
    assert wide_dynamic_range(image, 1.0) is image  # off: untouched


def test_post_adds_the_sensors_noise_before_the_wdr_curve():
    """The sensor reads the image, then the image processor's curve lifts it: the noise is lifted with it."""
    lens = LensConfig(vignetting=0.0, bloom_strength=0.0, wdr_gamma=0.5)
    read_only = replace(exposure_for(ImageSensorConfig(read_noise_e=100.0), 1 / 100, 1.0), shot_scale=0.0)
    image = np.full((40, 50, 3), 0.5 / 16, np.float32)  # grey at 1/16 of the pivot: lifted 4x to 1/4 of it
    noisy = apply_post(image, LensConfig(vignetting=0.0, bloom_strength=0.0), np.random.default_rng(3),
                       sensor=read_only)
    lifted = apply_post(image, lens, np.random.default_rng(3), sensor=read_only)
    from pipeline.sensors.post import wide_dynamic_range

    np.testing.assert_allclose(lifted, wide_dynamic_range(noisy, 0.5), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("sigma", [0.4, 0.65, 1.3])
def test_point_spread_is_scipys_gaussian_filter_with_mirrored_borders(sigma):
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(7)
    image = rng.random((37, 53, 3), dtype=np.float32) * 4.0
    radius = len(psf_taps(sigma)) // 2
    # scipy's "mirror" is numpy's "reflect" (the edge pixel not repeated); truncate so both stop at the same tap.
    expected = gaussian_filter(image.astype(np.float64), (sigma, sigma, 0), mode="mirror", truncate=radius / sigma)
    np.testing.assert_allclose(point_spread(image, sigma), expected, rtol=0, atol=2e-6)


def test_point_spread_of_a_point_is_the_sampled_gaussian_and_keeps_the_light():
    image = np.zeros((21, 21, 3), np.float32)
    image[10, 10] = (1.0, 2.0, 4.0)
    out = point_spread(image, 0.65)
    taps = psf_taps(0.65)
    assert len(taps) == 5 and taps.sum() == pytest.approx(1.0, abs=1e-6)
    # Closed form: the tap at offset k is exp(-k^2 / (2 sigma^2)) over the sum of all five.
    norm = sum(np.exp(-0.5 * (k / 0.65) ** 2) for k in range(-2, 3))
    assert taps[3] == pytest.approx(np.exp(-0.5 / 0.65 ** 2) / norm, rel=1e-6)
    np.testing.assert_allclose(out[8:13, 8:13, 0], np.outer(taps, taps), rtol=1e-5)
    np.testing.assert_allclose(out.sum(axis=(0, 1)), (1.0, 2.0, 4.0), rtol=1e-5)
    assert np.count_nonzero(out[..., 0]) == 25  # nothing beyond 3 sigma
    # An edge: 10-90 % rise over 2 x 1.2816 sigma (1.7 px at 0.65), the figure the docs give.
    edge = np.zeros((5, 40, 1), np.float32)
    edge[:, 20:] = 1.0
    profile = point_spread(edge, 0.65)[2, :, 0]
    assert profile[17] < 0.1 and profile[22] > 0.9 and 0.1 < profile[19] < profile[20] < 0.9


def test_point_spread_off_changes_nothing_and_bad_sigmas_fail():
    image = np.random.default_rng(2).random((12, 9, 3), dtype=np.float32)
    assert point_spread(image, 0.0) is image
    with pytest.raises(ValueError, match="sigma_px must be > 0"):
        psf_taps(-0.5)
    with pytest.raises(ValueError, match="too small"):
        point_spread(image[:2], 0.65)


def test_post_applies_the_cameras_point_spread_function():
    image = np.zeros((40, 40, 3), np.float32)
    image[:, 20:] = 1.0
    lens = LensConfig(vignetting=0.0, bloom_strength=0.0)
    sharp = apply_post(image, lens, None)
    soft = apply_post(image, lens, None, psf_sigma_px=0.65)
    np.testing.assert_array_equal(sharp, image)
    np.testing.assert_allclose(soft, point_spread(image, 0.65))


def test_the_point_spread_function_softens_the_image_and_leaves_the_labels(box_meshes, actors_factory, wall):
    from scipy.ndimage import maximum_filter, minimum_filter

    from pipeline.core.geometry import Transform
    from pipeline.sensors.camera import Camera
    from pipeline.sensors.render import render_camera
    from pipeline.world.scene import FrameScene, StaticScene
    from tests.sensors.conftest import camera_config

    actors = actors_factory([[15.0, 1.0, 0.0]], [[4.0, 2.0, 1.5]], yaws=[0.35], colors=[[0.9, 0.05, 0.05]])
    scene = FrameScene(StaticScene([wall(40.0)]), actors, box_meshes)
    sharp, soft = (render_camera(scene, Camera(camera_config(width_px=200, height_px=150, quality="fast",
                                                              psf_sigma_px=sigma)), Transform.identity())
                   for sigma in (0.0, 0.65))
    for name in ("instance_id", "semantic", "depth_m"):
        np.testing.assert_array_equal(getattr(sharp, name), getattr(soft, name))
    np.testing.assert_array_equal(sharp.labels.box_tight, soft.labels.box_tight)
    diff = np.abs(sharp.rgb.astype(int) - soft.rgb.astype(int)).max(axis=2)
    assert diff.max() >= 20  # the box's silhouette against the wall
    # Where the sharp image varies by at most 2 levels over the 5 x 5 pixels the function reaches, so does the soft.
    rgb = sharp.rgb.astype(int)
    spread = (maximum_filter(rgb, size=(5, 5, 1)) - minimum_filter(rgb, size=(5, 5, 1))).max(axis=2)
    flat = spread <= 2
    assert flat.sum() > 0.5 * diff.size and diff[flat].max() <= 2


def test_highlights_beyond_white_keep_their_hue_and_bloom_no_more_than_white():
    """A red lamp 10x beyond the output's white stays red (scaled to white, channel ratios kept) instead of
    clipping each channel to white; what is below white is untouched. Its bloom is that of a white pixel."""
    from pipeline.sensors.post import BLOOM_CEILING, bloom, hold_hue

    image = np.full((20, 30, 3), 0.1, np.float32)
    image[5, 5] = (40.0, 2.0, 1.0)
    out = hold_hue(image, BLOOM_CEILING)
    np.testing.assert_allclose(out[5, 5], np.array([40.0, 2.0, 1.0]) * BLOOM_CEILING / 40.0, rtol=1e-6)
    mask = np.ones((20, 30), bool)
    mask[5, 5] = False
    np.testing.assert_array_equal(out[mask], image[mask])
    at_white = image.copy()
    at_white[5, 5] = (BLOOM_CEILING, 2.0, 1.0)
    glow, glow_at_white = (bloom(x, 1.2, 0.5, 2.0) - x for x in (image, at_white))
    assert glow.max() > 0.01
    np.testing.assert_allclose(glow, glow_at_white, rtol=1e-5, atol=1e-5)  # float32 sums near 40 round at 4e-6


def test_channel_max_equals_numpys_reduce_over_the_channels():
    """The element-wise maxima of whole channels give numpy's ``max(axis=2)`` exactly: float32 with NaN (which both
    propagate), infinities and signed zeros, uint8, and a strided view."""
    from pipeline.sensors.post import channel_max

    rng = np.random.default_rng(3)
    image = rng.normal(size=(31, 47, 3)).astype(np.float32)
    image[2, 3, 1] = np.nan
    image[4, 5] = (np.inf, -np.inf, 0.0)
    image[6, 7] = (-0.0, 0.0, -1.0)
    bytes8 = rng.integers(0, 256, size=(31, 47, 3), dtype=np.uint8)
    for a in (image, bytes8, image[::2, ::3], rng.normal(size=(5, 6, 4))):
        got = channel_max(a)
        assert got.dtype == a.dtype and got.shape == a.shape[:2]
        np.testing.assert_array_equal(got, a.max(axis=2))
    assert np.isnan(channel_max(image)[2, 3])
