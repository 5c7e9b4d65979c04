"""Street furniture on a real netgenerate grid with sidewalks: signs at the kerb facing their traffic, bus
shelters with glass, bushes off the pavement."""

from __future__ import annotations

import itertools
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.core.config.scenario import BusStopConfig
from pipeline.traffic.busstops import SHELTER_LENGTH_M, choose_bus_stops
from pipeline.traffic.roadgeometry import load_road_geometry, read_network_geometry, write_road_geometry
from pipeline.world.furniture import vertical_plates
from pipeline.world.materials import material_index
from pipeline.world.static import build_static_world


@pytest.fixture(scope="module")
def town_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A netgenerate grid (g.net.xml) and its road geometry (roads/) with bus stops on 30 % of its sidewalks, the
    first one twice (stop_id "twin")."""
    tool = shutil.which("netgenerate", path=str(Path(sys.executable).parent)) or shutil.which("netgenerate")
    if tool is None:
        pytest.skip("SUMO's netgenerate not found")
    tmp = tmp_path_factory.mktemp("town")
    subprocess.run([tool, "--grid", "--grid.number", "4", "--grid.length", "120", "--default.lanenumber", "2",
                    "--sidewalks.guess", "true", "--crossings.guess", "true", "-o", str(tmp / "g.net.xml"),
                    "--no-warnings"], check=True, capture_output=True)
    stops = choose_bus_stops(read_network_geometry(tmp / "g.net.xml").lanes, BusStopConfig(share=0.3))
    stops = pd.concat([stops, stops.iloc[:1].assign(stop_id="twin")], ignore_index=True)
    write_road_geometry(tmp / "g.net.xml", tmp / "roads", stops)
    return tmp


@pytest.fixture(scope="module")
def town(town_dir: Path):
    return build_static_world(town_dir / "roads", seed=3), load_road_geometry(town_dir / "roads").lanes


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


def _sidewalk_point(lane, pos_m: float, right_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The point ``right_m`` right of a lane's centre line at ``pos_m`` along it (as a share of its length), and the
    lane's direction there."""
    xy = np.stack([lane.shape_x, lane.shape_y], 1)
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = pos_m / lane.length_m * seg.sum()
    i = min(int(np.searchsorted(np.cumsum(seg), s)), len(seg) - 1)
    direction = (xy[i + 1] - xy[i]) / seg[i]
    point = xy[i] + direction * (s - np.cumsum(seg)[i] + seg[i])
    return point + right_m * np.array([direction[1], -direction[0]]), direction


def test_a_shelter_stands_behind_each_bus_stop_or_its_flag_at_the_kerb(town, town_dir, tmp_path):
    """Each stop of the road geometry's bus_stops gets a shelter (glass back and sides) behind its sidewalk, centred
    on the stop, or, where that ground is taken (here the first stop's twin, behind which its shelter stands), a
    flag (a plate on a pole, 2.25-2.85 m up) at the kerb; stops of another network are an error naming the stop."""
    world, lanes = town
    stops = load_road_geometry(town_dir / "roads").bus_stops
    assert len(stops) >= 4 and stops.stop_id.iloc[-1] == "twin"
    building, pole = world.parts["building"], world.parts["pole"]
    glass = building.vertices[building.triangles[building.material == material_index("glass")]].mean(axis=1)
    plates = pole.vertices[pole.triangles[pole.material == material_index("plate")]].mean(axis=1)
    flags = plates[(plates[:, 2] > 2.2) & (plates[:, 2] < 2.9)]
    sidewalks = lanes[(lanes.kind == "sidewalk") & (lanes.function == "normal")].set_index("lane_id")
    sheltered = 0
    for stop in stops.itertuples():
        lane = sidewalks.loc[stop.lane_id]
        behind, direction = _sidewalk_point(lane, stop.pos_m, lane.width_m / 2 + 0.2 + 0.75)
        near = glass[np.linalg.norm(glass[:, :2] - behind, axis=1) < SHELTER_LENGTH_M / 2 + 0.1]
        kerb, _ = _sidewalk_point(lane, stop.pos_m, -(lane.width_m / 2 - 0.35))
        flag = len(flags) > 0 and np.linalg.norm(flags[:, :2] - kerb, axis=1).min() < 0.1
        if stop.stop_id == "twin":  # the first stop's shelter stands behind it: a flag
            assert flag and len(near) > 0
            continue
        if len(near):
            along = (near[:, :2] - behind) @ direction
            assert abs(along.min() + along.max()) < 0.1 and along.max() > SHELTER_LENGTH_M / 2 - 0.2  # centred
            assert not flag or stop.Index == 0  # (the first stop's twin has its flag there)
            sheltered += 1
        else:
            assert flag
    assert sheltered >= 3
    write_road_geometry(town_dir / "g.net.xml", tmp_path / "roads", stops.iloc[:1].assign(lane_id="nowhere_0"))
    with pytest.raises(ValueError, match="bus stop bus000: 'nowhere_0' is not a sidewalk lane of this network"):
        build_static_world(tmp_path / "roads", seed=3)


def test_bushes_exist(town):
    world, _ = town
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
