"""Smooth closed solids and the two-bone joints of figures: closed-form volumes, watertight outward surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.figures import bend
from pipeline.world.solids import capsule, cylinder, ellipsoid, signed_volume, sweep, torus


def _watertight(triangles: np.ndarray) -> bool:
    edges = [(int(a), int(b)) for t in triangles for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))]
    unique = set(edges)
    return len(unique) == len(edges) and all((b, a) in unique for a, b in edges)


def _inscribed(n: int) -> float:
    """Area of a regular n-gon inscribed in the unit circle, over pi: a polygonal cross-section's share."""
    return n * np.sin(2.0 * np.pi / n) / (2.0 * np.pi)


@pytest.mark.parametrize(("part", "exact", "rel"), [
    # Fine sweeps approach the smooth solids (inscribed polygons: within 1 % at 32 to 64 points round); a cylinder is
    # exactly a prism on a regular polygon.
    (ellipsoid((1.0, 2.0, 3.0), (0.3, 0.2, 0.5), "skin", n=64, m=64), 4.0 / 3.0 * np.pi * 0.03, 1e-2),
    (torus((0.0, 0.0, 0.3), 0.3, 0.02, "rubber", 96, 32), 2.0 * np.pi**2 * 0.3 * 0.02**2, 1e-2),
    (capsule((0, 0, 0), (0, 0, 1.0), 0.1, 0.1, "skin", n=64, rings=16), np.pi * 0.01 + 4.0 / 3.0 * np.pi * 1e-3,
     1e-2),
    (cylinder((0, 0, 0), (0, 2.0, 0), 0.1, "metal", n=12), 2.0 * np.pi * 0.01 * _inscribed(12), 1e-9),
])
def test_solids_enclose_their_closed_form_volume_and_face_out(part, exact, rel):
    vertices, triangles, material = part
    assert _watertight(triangles) and len(material) == len(triangles)
    assert signed_volume(vertices, triangles) == pytest.approx(exact, rel=rel)


def test_a_sweep_keeps_outward_winding_along_any_path_and_labels_intervals():
    path = [(0.0, 0.0, 0.0), (0.3, 0.1, -0.4), (0.2, 0.5, -0.9)]
    v, t, m = sweep(path, [0.0, 0.1, 0.0], ["cloth", "skin"], n=8, ref=(1.0, 0.0, 0.0))
    assert _watertight(t) and signed_volume(v, t) > 0
    assert len(set(m.tolist())) == 2
    with pytest.raises(ValueError, match="interval materials"):
        sweep(path, [0.1, 0.1, 0.1], ["cloth"])


def test_bend_keeps_bone_lengths_and_bends_towards_the_given_side():
    hip, ankle = np.array([0.0, 0.1, 0.9]), np.array([0.2, 0.1, 0.15])
    knee = bend(hip, ankle, 0.43, 0.43, (1.0, 0.0, 0.0))
    assert np.linalg.norm(knee - hip) == pytest.approx(0.43) and np.linalg.norm(ankle - knee) == pytest.approx(0.43)
    assert knee[0] > 0.5 * (hip[0] + ankle[0])  # forward of the hip-ankle line
    straight = bend(hip, hip + [0.0, 0.0, -2.0], 0.43, 0.43, (1.0, 0.0, 0.0))  # out of reach: nearly straight
    assert straight[0] == pytest.approx(0.0, abs=0.02) and straight[2] == pytest.approx(0.9 - 0.43, abs=1e-3)
