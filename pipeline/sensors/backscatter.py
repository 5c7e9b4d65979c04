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

from pipeline.core.jit import kernel

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


def cell_weights(extinction_per_m: float, overlap_m: tuple[float, float], step_m: float,
                 cells: int) -> np.ndarray:
    """(cells,) float64 each range cell's weight in the soft target's echo before its back-scatter: xi(t) exp(-2
    alpha t) / t^2 x the cell's length, at the centres t of cells of ``step_m`` from the sensor, xi the overlap rising
    linearly from r1 to r2 (``overlap_m``; a step at r1 where they are equal)."""
    t = (np.arange(cells) + 0.5) * step_m
    r1, r2 = overlap_m
    xi = np.clip((t - r1) / (r2 - r1), 0.0, 1.0) if r2 > r1 else (t >= r1).astype(np.float64)
    return xi * np.exp(-2.0 * extinction_per_m * t) / (t * t) * step_m


def window_phases(window_m: float, step_m: float, cells: int) -> tuple[np.ndarray, ...]:
    """The cosines and sines of 2 pi x / w at the cells' centres ((cells,) each) and at their edges ((cells + window
    + 1,) each: the window's ends), for :func:`waveform_peak`."""
    centres = 2.0 * np.pi * (np.arange(cells) + 0.5) * step_m / window_m
    edges = 2.0 * np.pi * np.arange(cells + int(window_m / step_m + 0.5) + 1) * step_m / window_m
    return np.cos(centres), np.sin(centres), np.cos(edges), np.sin(edges)


@kernel("UniTuple(float64, 2)(float64[::1], int64, int64, float64[::1], float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1], float64[::1])")
def waveform_peak(f, m, window, cos_cell, sin_cell, cos_edge, sin_edge, s0, sc, ss):
    """The soft target's strongest echo from its first ``m`` cells' densities ``f`` (cells of length h; the pulse
    ``window`` cells long): over the window ends at the cells' edges e = 1 .. m + window, the sum over the cells s in
    [e - window, e) of f_s sin^2(pi (e h - t_s) / w), from three running sums (sin^2 x = (1 - cos 2x) / 2, the
    phases from :func:`window_phases`; ``s0``, ``sc``, ``ss`` (>= m + 1,) scratch). Returns the peak power and the
    edge index of its window's end (0 and 0 where nothing echoes); the first of equal peaks."""
    s0[0] = sc[0] = ss[0] = 0.0
    for s in range(m):
        s0[s + 1] = s0[s] + f[s]
        sc[s + 1] = sc[s] + f[s] * cos_cell[s]
        ss[s + 1] = ss[s] + f[s] * sin_cell[s]
    best = 0.0
    best_end = 0
    for e in range(1, m + window + 1):
        low, high = max(e - window, 0), min(e, m)
        p = 0.5 * ((s0[high] - s0[low]) - cos_edge[e] * (sc[high] - sc[low]) - sin_edge[e] * (ss[high] - ss[low]))
        if p > best:
            best, best_end = p, e
    return best, np.float64(best_end)


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
    cells = math.ceil((FAR_M + overlap_full_m + w) / h)
    f = cell_weights(extinction_per_m, (overlap_start_m, overlap_full_m), h, cells) * backscatter_per_m_sr
    phases = window_phases(w, h, cells)
    window = round(w / h)
    scratch = [np.zeros(cells + 1) for _ in range(3)]
    free, end = waveform_peak(f, cells, window, *phases, *scratch)  # no surface in any window
    # A surface at R0 cuts every window at R0 (the cells below it echo): tabulate R0 on the cells' edges up to the
    # free peak's window end, from which on the cut leaves the peak as it is.
    peaks = [waveform_peak(f, cut, window, *phases, *scratch) for cut in range(int(end))] + [(free, end)]
    powers = np.array([p for p, _ in peaks])
    ranges = np.array([e * h - 0.5 * w for _, e in peaks])
    return SoftReturns(power=powers, range_m=np.maximum(ranges, 0.0), step_m=h)
