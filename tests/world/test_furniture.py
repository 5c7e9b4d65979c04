"""Street furniture on a real netgenerate grid with sidewalks: signs at the kerb facing their traffic, bus
shelters with glass, bushes off the pavement."""

from __future__ import annotations

import itertools
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.traffic.roadgeometry import load_road_geometry, write_road_geometry
from pipeline.world.furniture import vertical_plates
from pipeline.world.materials import material_index
from pipeline.world.static import build_static_world


@pytest.fixture(scope="module")
def town(tmp_path_factory: pytest.TempPathFactory):
    tool = shutil.which("netgenerate", path=str(Path(sys.executable).parent)) or shutil.which("netgenerate")
    if tool is None:
        pytest.skip("SUMO's netgenerate not found")
    tmp = tmp_path_factory.mktemp("town")
    subprocess.run([tool, "--grid", "--grid.number", "4", "--grid.length", "120", "--default.lanenumber", "2",
                    "--sidewalks.guess", "true", "--crossings.guess", "true", "-o", str(tmp / "g.net.xml"),
                    "--no-warnings"], check=True, capture_output=True)
    write_road_geometry(tmp / "g.net.xml", tmp / "roads")
    return build_static_world(tmp / "roads", seed=3), load_road_geometry(tmp / "roads").lanes


def _nearest_lane(point: np.ndarray, lanes) -> tuple[object, float, np.ndarray]:
    """The lane whose centre line passes nearest to ``point`` (2,), the distance, and its direction there."""
    best = (None, np.inf, np.zeros(2))
    for lane in lanes.itertuples():
        xy = np.stack([lane.shape_x, lane.shape_y], 1)
        for a, b in itertools.pairwise(xy):
            d = b - a
            t = np.clip(np.dot(point - a, d) / max(np.dot(d, d), 1e-12), 0, 1)
            dist = np.linalg.norm(point - (a + t * d))
            if dist < best[1]:
                best = (lane, dist, d / np.linalg.norm(d))
    return best


def test_signs_stand_on_the_kerb_side_of_sidewalks_facing_their_traffic(town):
    world, lanes = town
    pole = world.parts["pole"]
    normal_lanes = lanes[lanes.function == "normal"]
    # White faces of round and triangular signs and rectangles: "plate" triangles of the pole part.
    faces = pole.triangles[pole.material == material_index("plate")]
    assert len(faces) > 20
    tri = pole.vertices[faces]
    centres = tri.mean(axis=1)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    assert np.abs(normals[:, 2]).max() < 1e-9  # vertical plates
    assert (centres[:, 2] > 2.0).all()  # above people's heads
    rng = np.random.default_rng(0)
    for i in rng.choice(len(centres), 15, replace=False):
        lane, dist, direction = _nearest_lane(centres[i, :2], normal_lanes)
        assert lane.kind == "sidewalk" and dist < lane.width_m / 2
        assert np.dot(normals[i, :2], direction) < -0.99  # faces the traffic driving along the edge


def test_shelters_and_bushes_exist(town):
    world, _ = town
    building = world.parts["building"]
    assert (building.material == material_index("glass")).sum() >= 12  # one shelter: back and two sides
    veg = world.parts["vegetation"]
    low = veg.vertices[veg.vertices[:, 2] < 1.6]
    assert len(low) > 12 * 10  # bushes (crowns of trees start above 1.8 m; trunks have 11 vertices below)


def test_vertical_plates_winding_faces_the_given_direction():
    v, t = vertical_plates(np.array([[1.0, 2.0, 3.0]]), np.array([np.pi / 2]),
                           np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]), forward_m=0.1)
    tri = v[t]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    np.testing.assert_allclose(n / np.linalg.norm(n, axis=1, keepdims=True), [[0, 1, 0]] * 2, atol=1e-12)
    np.testing.assert_allclose(v[:, 1], 2.1)  # 0.1 m along the facing direction (north)
    np.testing.assert_allclose(sorted(v[:, 2]), [2.5, 2.5, 3.5, 3.5])
    vb, tb = vertical_plates(np.array([[0.0, 0.0, 0.0]]), np.array([0.0]), np.array([[0, 0], [1, 0], [0, 1.0]]),
                             back=True)
    nb = np.cross(vb[tb][:, 1] - vb[tb][:, 0], vb[tb][:, 2] - vb[tb][:, 0])
    assert nb[0, 0] < 0  # a back plate faces away
