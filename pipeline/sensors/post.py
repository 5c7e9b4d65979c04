"""Image post effects on linear radiance (after exposure, before tone mapping), with OpenCV, seeded.

Order, following the light: motion blur over the shutter time, rain (streaks in the air:
:mod:`pipeline.sensors.rain`; drops on the lens), lens effects (bloom, flare ghosts, point spread, vignetting), the
sensor's noise, then the image processor (wide-dynamic-range curve, highlights compressed keeping their hue). Images
are (H, W, 3) float32 linear RGB; every random draw comes from the caller's generator, in a fixed order (image-sized
Gaussian fields from a counter-based generator keyed by one draw of it: :func:`standard_normal`), so the same
generator state gives the same image. Effects that need randomness are skipped when no generator is given.

- Vignetting: gain(r) = 1 - v * (r / r_corner)^2 with r the distance from the image centre; the corners
  keep exactly 1 - v.
- Noise: the sensor's photon shot noise and read noise at the frame's exposure (:mod:`pipeline.sensors.exposure`):
  sigma^2 = shot_scale * max(s, 0) + read_variance per channel and pixel.
- Motion blur: per-pixel image motion during the exposure time (from depth, the ego's velocity and, on a road user,
  its own), averaged over samples along it with ``cv2.remap``.
- Wide dynamic range (``wdr_gamma`` < 1): automotive cameras are HDR sensors whose processing compresses a scene's
  range (at night, from unlit verges to lamps) into the output: luminance L becomes p (L / p)^gamma about the pivot
  p = WDR_PIVOT, every channel scaled alike (hue kept): what is darker than the pivot is lifted, what is brighter
  held back.
- Bloom: light above a threshold, blurred (at quarter resolution) and added back. Lens flare: ghosts of the
  brightest sources mirrored through the image centre.
- Point-spread function: no real camera's pixel is a perfect box. The lens, the sensor's optical low-pass filter and
  the demosaicing of its colour filter array spread a point over neighbouring pixels; a Gaussian of ``sigma`` pixels
  (the camera's ``psf_sigma_px``) stands for all three, sampled at integer offsets out to 3 sigma and normalised,
  applied along rows then columns with mirrored borders. Its MTF is exp(-2 pi^2 sigma^2 f^2): at sigma 0.65 a
  contrast of 50 % at 0.29 cycles per pixel and an edge rising from 10 to 90 % over 1.7 pixels.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import cv2
import numpy as np
from scipy.special import ndtri

from pipeline.core.config.sensors import LensConfig
from pipeline.core.jit import as_input, kernel

if TYPE_CHECKING:
    from pipeline.sensors.exposure import Exposure

MOTION_BLUR_SAMPLES = 16
FLARE_SOURCES = 4
FLARE_GHOSTS = ((0.55, 0.05, (0.6, 0.8, 1.0)), (1.3, 0.03, (1.0, 0.7, 0.4)), (1.8, 0.08, (0.5, 1.0, 0.6)),
                (2.3, 0.04, (0.9, 0.6, 1.0)))  # (position along source -> mirror, radius / image diagonal, tint)


WDR_PIVOT = 0.5  # linear luminance that wide-dynamic-range processing leaves as it is


@functools.lru_cache(maxsize=8)
def vignette_gain(height: int, width: int, strength: float) -> np.ndarray:
    """(H, W, 3) float32 gain 1 - strength * (r / r_corner)^2 (pixel centres; exactly 1 - strength at corners), the
    same in each channel: numpy multiplies equal shapes much faster than it broadcasts an (H, W, 1) array."""
    y = (np.arange(height, dtype=np.float64) + 0.5 - 0.5 * height) / (0.5 * height)
    x = (np.arange(width, dtype=np.float64) + 0.5 - 0.5 * width) / (0.5 * width)
    aspect = width / height
    r2 = ((x[None, :] * aspect) ** 2 + y[:, None] ** 2) / (aspect ** 2 + 1.0)
    gain = per_channel((1.0 - strength * r2).astype(np.float32))
    gain.flags.writeable = False  # cached and shared
    return gain


def per_channel(a: np.ndarray) -> np.ndarray:
    """(..., 3) float32: ``a`` (any shape) repeated in 3 channels, so that a pixel-wise product or sum with an image
    runs on equal shapes (OpenCV's merge: much faster than numpy's repeat)."""
    a = np.ascontiguousarray(a, np.float32)
    return cv2.merge([a.reshape(-1, 1)] * 3).reshape(*a.shape, 3)


def vignette(image: np.ndarray, strength: float) -> np.ndarray:
    """Darken towards the corners by ``strength`` (fraction lost at a corner)."""
    if strength == 0:
        return image
    return image * vignette_gain(image.shape[0], image.shape[1], float(strength))


def luminance(image: np.ndarray) -> np.ndarray:
    """(...) float32 Rec. 709 luminance of a (..., 3) float32 linear RGB image."""
    return image[..., 0] * np.float32(0.2126) + image[..., 1] * np.float32(0.7152) + image[..., 2] * np.float32(0.0722)


def wide_dynamic_range(image: np.ndarray, gamma: float) -> np.ndarray:
    """Compress the (H, W, 3) float32 linear ``image``'s range: each pixel scaled by (L / WDR_PIVOT)^(gamma - 1),
    L its :func:`luminance` (floored at 1e-6); gamma 1 returns the image unchanged."""
    if gamma == 1.0:
        return image
    scale = np.power(np.maximum(luminance(image), np.float32(1e-6)) / np.float32(WDR_PIVOT), np.float32(gamma - 1.0))
    return image * per_channel(scale.astype(np.float32))


# Normal draws by table: the 2^16 equiprobable quantiles of the standard normal, Phi^-1((j + 0.5) / 2^16), so
# |z| <= 4.17 (a cut of the tails that no 8-bit pixel shows: 3 in 100,000 draws lie beyond).
NORMAL_QUANTILES = ndtri((np.arange(1 << 16) + 0.5) / (1 << 16)).astype(np.float32)
NORMAL_QUANTILES.flags.writeable = False
_QUANTILES = NORMAL_QUANTILES.copy()  # the kernels' copy: numba types a read-only array apart


def standard_normal(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """``shape`` float32 standard normal draws (:func:`_normal_draws`), keyed by one draw of ``rng``.

    Faster than OpenCV's ``randn`` and numpy's float32 normals (docs/performance.md), and as reproducible: a fixed
    algorithm of integers and a table.
    """
    out = np.empty(shape, np.float32)
    _normal_draws(out.reshape(-1), np.uint64(rng.integers(1 << 63)), _QUANTILES)
    return out


# SplitMix64 (Steele, Lea & Flood, "Fast splittable pseudorandom number generators", OOPSLA 2014): a Weyl sequence
# of 64-bit keys, each through a mixing function; its outputs pass BigCrush. Output k of key s is the mix of
# s + (k + 1) * GAMMA; its four 16-bit quarters, low first, index NORMAL_QUANTILES for draws 4k to 4k + 3.
_GAMMA = np.uint64(0x9E3779B97F4A7C15)


@kernel("uint64(uint64, int64)")
def _splitmix64(key, k):
    """Output ``k`` of the SplitMix64 stream of ``key``."""
    z = key + np.uint64(k + 1) * _GAMMA
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@kernel("float32(uint64, int64, float32[::1])")
def _draw(bits, j, quantiles):
    """The draw of the ``j``-th 16-bit quarter (low first) of the SplitMix64 output ``bits``."""
    return quantiles[np.int64((bits >> np.uint64(16 * j)) & np.uint64(0xFFFF))]


@kernel("void(float32[::1], uint64, float32[::1])")
def _normal_draws(out, key, quantiles):
    """Fill ``out`` (N,) with standard normal draws: draw i is ``quantiles`` at the (i % 4)-th 16-bit quarter of
    SplitMix64 output i // 4 of ``key``."""
    n = out.size
    for k in range(n // 4):  # whole outputs (a loop the compiler unrolls), then the last few draws
        bits = _splitmix64(key, k)
        for j in range(4):
            out[4 * k + j] = _draw(bits, j, quantiles)
    for i in range(n - n % 4, n):
        out[i] = _draw(_splitmix64(key, i // 4), i % 4, quantiles)


def sensor_noise(image: np.ndarray, exposure: Exposure, rng: np.random.Generator) -> np.ndarray:
    """``image`` + z sqrt(shot_scale max(image, 0) + read_variance) of the ``exposure``, z the draws of
    :func:`standard_normal` (made where they are used)."""
    image = as_input(image, np.float32)
    out = np.empty(image.shape, np.float32)
    _add_noise(image.reshape(-1), out.reshape(-1), np.float32(exposure.shot_scale), np.float32(exposure.read_variance),
               np.uint64(rng.integers(1 << 63)), _QUANTILES)
    return out


@kernel("void(float32[::1], float32[::1], int64, float32, float32, float32)")
def _noisy(image, out, i, z, shot_scale, read_variance):
    """``out[i]`` of :func:`_add_noise` for the draw ``z``."""
    x = image[i]
    variance = (x if x > 0 else np.float32(0)) * shot_scale + read_variance
    out[i] = z * np.sqrt(variance) + x


@kernel("void(float32[::1], float32[::1], float32, float32, uint64, float32[::1])")
def _add_noise(image, out, shot_scale, read_variance, key, quantiles):
    """``out = image + z * sqrt(shot_scale * max(image, 0) + read_variance)``, (N,) float32, with z the draws of
    :func:`_normal_draws` for ``key``: one pass (in numpy, six over the image and one for the draws)."""
    n = image.size
    for k in range(n // 4):
        bits = _splitmix64(key, k)
        for j in range(4):
            _noisy(image, out, 4 * k + j, _draw(bits, j, quantiles), shot_scale, read_variance)
    for i in range(n - n % 4, n):
        _noisy(image, out, i, _draw(_splitmix64(key, i // 4), i % 4, quantiles), shot_scale, read_variance)


def motion_flow(points_cam: np.ndarray, shift_cam: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """(N, 2) float32 image motion (pixels, pinhole) of (N, 3) optical-frame points when the camera moves by
    ``shift_cam`` metres (optical frame) relative to them: (3,) for all, or (N, 3), one per point (a moving road
    user's points move with it); zero for points at infinity or that cross the near plane."""
    p = as_input(np.asarray(points_cam).reshape(-1, 3), np.float64)
    shift = as_input(np.asarray(shift_cam, np.float64).reshape(-1, 3), np.float64)
    if len(shift) not in (1, len(p)):
        raise ValueError(f"shift_cam: expected (3,) or ({len(p)}, 3), got {np.shape(shift_cam)}")
    return _flow(p, shift, float(fx), float(fy))


@kernel("float32[:, ::1](float64[:, ::1], float64[:, ::1], float64, float64)")
def _flow(p, shift, fx, fy):
    """:func:`motion_flow` in one pass, in its float64 arithmetic (q = p - shift; fx (q_x / q_z - p_x / p_z))."""
    n = p.shape[0]
    flow = np.zeros((n, 2), np.float32)
    for i in range(n):
        k = i if shift.shape[0] > 1 else 0
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)) or not pz > 0.1:
            continue
        qx, qy, qz = px - shift[k, 0], py - shift[k, 1], pz - shift[k, 2]
        if not qz > 0.1:
            continue
        flow[i, 0] = np.float32(fx * (qx / qz - px / pz))
        flow[i, 1] = np.float32(fy * (qy / qz - py / pz))
    return flow


def motion_blur(image: np.ndarray, flow: np.ndarray, samples: int | None = None) -> np.ndarray:
    """Average ``image`` (H, W, 3) over ``samples`` positions along each pixel's (H, W, 2) motion during the shutter
    (centred), gathering with ``cv2.remap``; by default one sample per ~2 pixels of the largest motion
    (3 to MOTION_BLUR_SAMPLES)."""
    h, w = image.shape[:2]
    if not np.any(flow):
        return image
    if samples is None:
        longest = float(np.sqrt((flow * flow).sum(axis=2).max()))
        samples = int(np.clip(np.ceil(longest / 2.0), 3, MOTION_BLUR_SAMPLES))
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    out = np.zeros_like(image)
    for s in np.linspace(-0.5, 0.5, samples, dtype=np.float32):  # loop over samples; pixels vectorised
        out += cv2.remap(image, gx + s * flow[:, :, 0], gy + s * flow[:, :, 1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)
    return out / np.float32(samples)


def psf_taps(sigma_px: float) -> np.ndarray:
    """(2r + 1,) float32 weights of a Gaussian of ``sigma_px`` sampled at the offsets -r..r, r = ceil(3 sigma) (at
    least 1), summing to 1."""
    if sigma_px <= 0:
        raise ValueError(f"sigma_px must be > 0, got {sigma_px}")
    r = max(int(np.ceil(3.0 * sigma_px)), 1)
    x = np.arange(-r, r + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma_px) ** 2)
    return (w / w.sum()).astype(np.float32)


def point_spread(image: np.ndarray, sigma_px: float) -> np.ndarray:
    """``image`` (H, W, C) float32 blurred by the optics' Gaussian point-spread function (:func:`psf_taps`),
    separably, borders mirrored (``np.pad``'s reflect: the edge pixel is not repeated). numpy's element-wise
    products and sums in a fixed tap order round each operation once, so the bytes do not depend on the processor
    (OpenCV's filters take SIMD paths of their own). ``sigma_px`` 0: the image as it is."""
    if sigma_px == 0:
        return image
    taps = psf_taps(sigma_px)
    r = len(taps) // 2
    out = np.asarray(image, np.float32)
    for axis in (0, 1):
        n = out.shape[axis]
        if n <= r:
            raise ValueError(f"image of {out.shape[:2]} pixels is too small for a point-spread function of sigma "
                             f"{sigma_px} px ({r} pixels each side)")
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        padded = np.pad(out, pad, mode="reflect")
        acc = np.zeros_like(out)
        for k, weight in enumerate(taps):  # loop over the few taps; pixels vectorised
            window = [slice(None)] * out.ndim
            window[axis] = slice(k, k + n)
            acc += weight * padded[tuple(window)]
        out = acc
    return out


LINEAR_WHITE = 4.0  # the tone curves' top (pipeline.sensors.shading.to_srgb8): brighter linear values come out white
BLOOM_CEILING = LINEAR_WHITE  # what the camera renders white blooms no more than white


def channel_max(image: np.ndarray) -> np.ndarray:
    """(H, W): the greatest of an (H, W, C) image's channels per pixel, as ``image.max(axis=2)`` (the same values,
    NaN propagating alike), as element-wise maxima of whole channels: numpy's reduce over a short last axis walks
    the pixels one by one, ~15x slower on an 800x600 frame."""
    out = image[..., 0].copy()
    for c in range(1, image.shape[2]):
        np.maximum(out, image[..., c], out=out)
    return out


def hold_hue(image: np.ndarray, white: float) -> np.ndarray:
    """Scale down each pixel of the (H, W, 3) float32 linear ``image`` whose brightest channel exceeds ``white`` so
    that it equals ``white``, keeping its hue: an HDR camera's image processor compresses what its sensor holds
    beyond the output's range instead of clipping each channel (a red lamp stays red, not white)."""
    peak = channel_max(image)
    over = peak > np.float32(white)
    if not over.any():
        return image
    out = image.copy()
    out[over] *= (np.float32(white) / peak[over])[:, None]
    return out


def bloom(image: np.ndarray, threshold: float, strength: float, sigma_px: float) -> np.ndarray:
    """Add the blurred excess above ``threshold`` (glow of lamps, headlights, the sun's reflections), of the image
    clipped at BLOOM_CEILING: the glow of what the camera renders white. (At night the sensor's longest exposure
    and highest gain scale a lamp's face to thousands; the lens's veiling glare of such sources is not modelled.)"""
    if strength == 0:
        return image
    h, w = image.shape[:2]
    # The part above the threshold: OpenCV's threshold to zero is faster than numpy's maximum.
    clipped = cv2.threshold(image, BLOOM_CEILING, 0.0, cv2.THRESH_TRUNC)[1]
    excess = cv2.threshold(clipped - np.float32(threshold), 0.0, 0.0, cv2.THRESH_TOZERO)[1]
    small = cv2.resize(excess, (max(w // 4, 1), max(h // 4, 1)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), max(sigma_px / 4.0, 0.5)) + cv2.GaussianBlur(
        small, (0, 0), max(sigma_px, 0.5)) * np.float32(0.5)
    return image + cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(strength)


def lens_flare(image: np.ndarray, strength: float, threshold: float) -> np.ndarray:
    """Ghosts of the brightest sources (above ``threshold``) along the line through the image centre."""
    if strength == 0:
        return image
    h, w = image.shape[:2]
    sw, sh = max(w // 8, 1), max(h // 8, 1)
    small = cv2.resize(image, (sw, sh), interpolation=cv2.INTER_AREA)
    lum = small.max(axis=2)
    mask = (lum > threshold).astype(np.uint8)
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
    if count <= 1:
        return image
    power = stats[1:, cv2.CC_STAT_AREA] * 1.0
    top = np.argsort(-power, kind="stable")[:FLARE_SOURCES]
    layer = np.zeros((sh, sw, 3), np.float32)
    centre = np.array([0.5 * sw, 0.5 * sh])
    diag = np.hypot(sw, sh)
    for k in top:  # a few sources x a few ghosts
        src = centroids[1 + k]
        amp = min(float(power[k]) / (sw * sh) * 40.0, 1.0)
        for pos, radius, tint in FLARE_GHOSTS:
            c = src + (centre - src) * pos
            cv2.circle(layer, (round(c[0]), round(c[1])), max(round(radius * diag), 1),
                       tuple(float(t * amp) for t in tint), -1, cv2.LINE_AA)
    layer = cv2.GaussianBlur(layer, (0, 0), 1.5)
    return image + cv2.resize(layer, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(strength)


def rain_drops(image: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Blurry raindrops on the lens: round soft regions showing a strongly blurred image."""
    if count == 0:
        return image
    h, w = image.shape[:2]
    centres = np.column_stack([rng.uniform(0, w, count), rng.uniform(0, h, count)]).round().astype(int)
    radii = rng.uniform(0.01, 0.035, count) * w
    mask = np.zeros((h, w), np.float32)
    for (cx, cy), r in zip(centres, radii, strict=True):  # one draw per drop (tens), pixels vectorised
        cv2.circle(mask, (int(cx), int(cy)), int(r), (1.0,), -1, cv2.LINE_AA)
    mask = per_channel(cv2.GaussianBlur(mask, (0, 0), 2.0))
    blurred = cv2.GaussianBlur(image, (0, 0), 0.02 * w) * np.float32(1.1)
    return image * (1.0 - mask) + blurred * mask


def apply_post(
    image: np.ndarray,
    lens: LensConfig,
    rng: np.random.Generator | None,
    *,
    flow: np.ndarray | None = None,
    streaks: np.ndarray | None = None,
    streak_radiance: float = 0.0,
    streak_light: np.ndarray | None = None,
    lens_drops: int = 0,
    gain: float = 1.0,
    psf_sigma_px: float = 0.0,
    sensor: Exposure | None = None,
) -> np.ndarray:
    """All post effects of a condition on an (H, W, 3) float32 linear image (see the module docstring).

    ``flow`` (H, W, 2) float32 is the image motion during the shutter (None: no motion blur); ``streaks`` (H, W)
    float32 the share of each pixel's exposure that falling raindrops cover (:mod:`pipeline.sensors.rain`), whose
    radiance is ``streak_radiance``, plus (H, W, 3) ``streak_light`` where lamps light them (their coverage
    included); ``lens_drops`` the raindrops on the lens (drawn from ``rng``); ``gain`` scales
    the image first (the camera's exposure, :mod:`pipeline.sensors.exposure`); ``psf_sigma_px`` the camera's
    point-spread function (:func:`point_spread`), applied with the other optics, before the sensor; ``sensor`` the
    frame's :class:`pipeline.sensors.exposure.Exposure`, whose shot and read noise the sensor adds after the optics
    and before the image processor (None, or no ``rng``: no noise).
    """
    out = np.asarray(image, np.float32)
    if gain != 1.0:
        out = out * np.float32(gain)
    if flow is not None:
        out = motion_blur(out, flow)
    if streaks is not None:  # the drops' own motion is their streak: not blurred again
        cover = per_channel(streaks)
        out = out * (1.0 - cover) + cover * np.float32(streak_radiance * gain)
        if streak_light is not None:
            out = out + streak_light * np.float32(gain)
    out = bloom(out, lens.bloom_threshold, lens.bloom_strength, lens.bloom_sigma_px)
    out = lens_flare(out, lens.lens_flare, 2.0 * lens.bloom_threshold)
    if lens_drops and rng is not None:
        out = rain_drops(out, lens_drops, rng)
    out = point_spread(out, psf_sigma_px)
    out = vignette(out, lens.vignetting)
    if sensor is not None and rng is not None:
        out = sensor_noise(out, sensor, rng)
    return hold_hue(wide_dynamic_range(out, lens.wdr_gamma), BLOOM_CEILING)
