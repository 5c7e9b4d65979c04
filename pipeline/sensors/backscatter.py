"""LiDAR returns from the air itself: the back-scatter of fog, mist and rain droplets near the sensor.

A pulsed time-of-flight LiDAR sees a volume of droplets as a *soft target* (Rasshofer, Spies and Spies 2011,
"Influences of weather phenomena on automotive laser radar systems", Adv. Radio Sci. 9; the model Hahner et al.
2021, "Fog simulation on real LiDAR point clouds for 3D object detection in adverse weather", ICCV, apply). The
power received at the time that corresponds to range R is the pulse convolved with the channel's response:

    P(R) ~ integral over r of  s(R - r)  xi(r)  exp(-2 alpha r) / r^2  H(r) dr

with the pulse s(x) = sin^2(pi x / w) for 0 <= x <= w (w = c tau_H: tau_H the half-power pulse width, 20 ns
for the Velodyne HDL-64 that Hahner et al. model, a window of 6 m), the overlap xi(r) of the transmitted beam and
the receiver's field of view (0 below r1, rising linearly to 1 at r2: Rasshofer et al.'s biaxial crossover), the air's
two-way extinction alpha, and the target's response H: beta0 delta(r - R0) for a surface at R0 (beta0 = Gamma / pi
for a Lambertian reflectivity Gamma), beta for r < R0 for the droplets (their back-scatter coefficient, 1/(m sr)).
Both in the same units (the common factor C_A P0 2/c left out), a surface's peak is Gamma / pi exp(-2 alpha R0) /
R0^2, and the droplets' return is

    P_soft(R) = beta  integral over [max(R - w, 0), min(R, R0)] of sin^2(pi (R - r) / w) xi(r) exp(-2 alpha r) / r^2 dr.

The sensor reports the strongest return (Hahner et al.'s rule): where the droplets' peak over R exceeds the
surface's, the point moves to the droplets' range (R_peak - w/2, where a surface's peak would put it); where no
surface returns (the sky, beyond range), the droplets alone can give a point. Either return needs at least the
power of the detection threshold, that of a surface of the reference reflectivity at the LiDAR's clear-air range.

Back-scatter: beta = 0.046 / MOR 1/(m sr) for fog of meteorological optical range MOR = ln 20 / alpha (Hahner et al.,
after Rasshofer et al.): beta / alpha = 0.046 / ln 20 = 0.0154 1/sr. Mist and rain (the rain's drops are large
against 905 nm, as the fog's) take the same ratio: no back-scatter-to-extinction ratio measured for rain at 905 nm
was at hand. In air of one extinction everything is a function of the soft target's range and the surface's range
only, so it is tabulated once per condition and rig (:func:`soft_returns`) and looked up per ray; a beam through a
vehicle's spray, where the droplets' density varies along it, takes its own waveform
(:func:`pipeline.sensors.spray.sweep_soft_returns`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

LIGHT_M_PER_NS = 0.299792458
# 1/sr: Hahner et al. 2021's beta = 0.046 / MOR with alpha = ln 20 / MOR.
BACKSCATTER_PER_EXTINCTION = 0.046 / math.log(20.0)
STEP_M = 0.01  # the range grid of the tables
FAR_M = 80.0  # the droplets' return is tabulated to this range (past the overlap, it only falls with 1/r^2)


@dataclass(frozen=True)
class SoftReturns:
    """The droplets' strongest return, by the range of the surface behind them (:func:`soft_returns`).

    Attributes:
        power: (K,) float64 the peak power (units of reflectivity / pi / m^2, as a surface's Gamma / pi / R^2)
            when the surface lies at range k * step_m (truncating the droplets there); the last entry holds for
            every farther surface and for none.
        range_m: (K,) float64 the range the sensor reports for that peak (R_peak - w / 2).
        step_m: the grid's step.
    """

    power: np.ndarray
    range_m: np.ndarray
    step_m: float

    def at(self, surface_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The peak power and reported range for surfaces at ``surface_m`` (inf where none): the grid entry at or
        below each range (a nearer cut gives the weaker return)."""
        index = np.minimum(np.floor(np.minimum(surface_m, 1e9) / self.step_m), len(self.power) - 1)
        index = index.astype(np.int64)
        return self.power[index], self.range_m[index]


@functools.lru_cache(maxsize=32)
def soft_returns(extinction_per_m: float, backscatter_per_m_sr: float, pulse_half_width_ns: float,
                 overlap_start_m: float, overlap_full_m: float) -> SoftReturns:
    """Tabulate the droplets' peak return and its reported range by the surface's range (module docstring).

    Args:
        extinction_per_m: the air's extinction alpha at the LiDAR's wavelength (1/m, > 0).
        backscatter_per_m_sr: the droplets' back-scatter beta (1/(m sr)).
        pulse_half_width_ns: tau_H.
        overlap_start_m, overlap_full_m: r1 and r2 of the overlap function (r1 <= r2).
    """
    w = LIGHT_M_PER_NS * pulse_half_width_ns
    h = STEP_M
    far = FAR_M + overlap_full_m + w
    r = (np.arange(math.ceil(far / h)) + 0.5) * h  # cell centres
    if overlap_full_m > overlap_start_m:
        xi = np.clip((r - overlap_start_m) / (overlap_full_m - overlap_start_m), 0.0, 1.0)
    else:
        xi = (r >= overlap_start_m).astype(np.float64)
    f = xi * np.exp(-2.0 * extinction_per_m * r) / (r * r) * h
    phase = 2.0 * np.pi * r / w
    # sin^2(pi (R - r) / w) = (1 - cos(2 pi R / w) cos(2 pi r / w) - sin(2 pi R / w) sin(2 pi r / w)) / 2: the window
    # sums from three running sums.
    sums = [np.concatenate([[0.0], np.cumsum(g)]) for g in (f, f * np.cos(phase), f * np.sin(phase))]
    window = round(w / h)
    ends = np.arange(1, len(r) + 1)  # the window [R - w, R) ends at edge j: R = j h
    big_r = ends * h
    cos_r, sin_r = np.cos(2.0 * np.pi * big_r / w), np.sin(2.0 * np.pi * big_r / w)

    def power(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        s0, sc, ss = (s[hi] - s[lo] for s in sums)
        return np.maximum(0.5 * (s0 - cos_r[: len(hi)] * sc - sin_r[: len(hi)] * ss), 0.0) * backscatter_per_m_sr

    lo = np.maximum(ends - window, 0)
    free = power(lo, ends)  # no surface in the window
    peak = int(np.argmax(free))
    # A surface at R0 cuts every window at R0: tabulate R0 up to the free peak's window end, beyond which the cut
    # leaves the peak as it is.
    cuts = np.arange(peak + 2)
    powers = np.empty(len(cuts) + 1)
    ranges = np.empty(len(cuts) + 1)
    span = min(len(ends), peak + window + 2)
    for i, cut in enumerate(cuts):
        p = power(lo[:span], np.minimum(ends[:span], cut))
        j = int(np.argmax(p))
        powers[i], ranges[i] = p[j], big_r[j] - 0.5 * w
    powers[-1], ranges[-1] = free[peak], big_r[peak] - 0.5 * w
    return SoftReturns(power=powers, range_m=np.maximum(ranges, 0.0), step_m=h)
