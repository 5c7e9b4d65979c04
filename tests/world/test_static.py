"""Static world meshes from road tables of real SUMO networks (netconvert/netgenerate into tmp_path)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.traffic.roadgeometry import read_network_geometry, write_road_geometry
from pipeline.world.materials import MATERIAL_NAMES
from pipeline.world.static import build_static_world, load_static_world


def _sumo_tool(name: str) -> str:
    found = shutil.which(name, path=str(Path(sys.executable).parent)) or shutil.which(name)
    if found is None:
        pytest.skip(f"SUMO tool {name} not found")
    return found


def _roads(tmp_path: Path, nodes: str, edges: str) -> Path:
    (tmp_path / "n.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (tmp_path / "e.edg.xml").write_text(f"<edges>{edges}</edges>")
    net = tmp_path / "n.net.xml"
    subprocess.run([_sumo_tool("netconvert"), "-n", str(tmp_path / "n.nod.xml"), "-e", str(tmp_path / "e.edg.xml"),
                    "-o", str(net), "--no-warnings"], check=True, capture_output=True)
    write_road_geometry(net, tmp_path / "roads")
    return tmp_path / "roads"


@pytest.fixture(scope="module")
def grid_roads(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("grid")
    net = tmp / "grid.net.xml"
    subprocess.run([_sumo_tool("netgenerate"), "--grid", "--grid.number", "3", "--grid.length", "100",
                    "--default.lanenumber", "2", "--tls.guess", "true", "--sidewalks.guess", "true",
                    "--crossings.guess", "true", "-o", str(net), "--no-warnings"], check=True, capture_output=True)
    write_road_geometry(net, tmp / "roads")
    return tmp / "roads"


@pytest.fixture(scope="module")
def grid_world(grid_roads: Path):
    return build_static_world(grid_roads, seed=7)


def _areas(mesh) -> np.ndarray:
    v = mesh.vertices[mesh.triangles]
    a, b = v[:, 1, :2] - v[:, 0, :2], v[:, 2, :2] - v[:, 0, :2]
    return 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def _ring_area(x: np.ndarray, y: np.ndarray) -> float:
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


STRAIGHT = ('<node id="a" x="0" y="0"/><node id="b" x="100" y="0"/>',
            '<edge id="ab" from="a" to="b" numLanes="2" width="3.5" speed="13.9" spreadType="center"/>')


def test_straight_road_area_and_markings(tmp_path: Path) -> None:
    roads = _roads(tmp_path, *STRAIGHT)
    world = build_static_world(roads, seed=0)
    geo = read_network_geometry(tmp_path / "n.net.xml")
    expected = (geo.lanes.length_m * geo.lanes.width_m).sum() + sum(
        _ring_area(j.shape_x, j.shape_y) for j in geo.junctions.itertuples() if len(j.shape_x) >= 3)
    assert _areas(world.parts["road"]).sum() == pytest.approx(expected, rel=0.02)

    marks = world.parts["lane_marking"]
    assert marks.semantic == SemanticClass.LANE_MARKING
    assert marks.vertices[:, 2].min() >= world.parts["road"].vertices[:, 2].max() + 0.015
    assert np.abs(marks.vertices[:, 1]).max() <= 3.5 + 1e-6  # inside the carriageway
    # Coverage along x of the centre line (dashed: 3 m of every 9 m) and the outer lines (solid).
    x = geo.lanes.shape_x.iloc[0]
    xs = np.linspace(x.min() + 1, x.max() - 1, 2000)
    tri = marks.vertices[marks.triangles]

    def covered(y: float) -> float:
        near = np.abs(tri[:, :, 1].mean(axis=1) - y) < 0.1
        lo, hi = tri[near, :, 0].min(axis=1), tri[near, :, 0].max(axis=1)
        return float(((xs[:, None] >= lo) & (xs[:, None] <= hi)).any(axis=1).mean())

    assert covered(0.0) == pytest.approx(3 / 9, abs=0.06)
    assert covered(3.5 - 0.06 - 0.05) > 0.99 and covered(-(3.5 - 0.06 - 0.05)) > 0.99


def test_meshes_valid_and_sized(grid_world) -> None:
    names = set(grid_world.parts)
    assert {"ground", "road", "sidewalk", "kerb", "crossing", "lane_marking", "building", "vegetation",
            "pole", "traffic_light", "traffic_light_pole"} <= names
    for name, mesh in grid_world.parts.items():
        assert np.isfinite(mesh.vertices).all(), name
        assert mesh.triangles.min() >= 0 and mesh.triangles.max() < len(mesh.vertices), name
        assert mesh.material.min() >= 0 and mesh.material.max() < len(MATERIAL_NAMES), name
    assert 5_000 < grid_world.num_triangles < 300_000
    sidewalk = grid_world.parts["sidewalk"]
    assert sidewalk.vertices[:, 2].min() == pytest.approx(0.15)


def test_ground_covers_bounds_below_roads(grid_world, grid_roads: Path) -> None:
    ground = grid_world.parts["ground"]
    import json

    xmin, ymin, xmax, ymax = json.loads((grid_roads / "network.json").read_text())["bounds"]
    v = ground.vertices
    assert v[:, 0].min() < xmin - 50 and v[:, 0].max() > xmax + 50
    assert v[:, 1].min() < ymin - 50 and v[:, 1].max() > ymax + 50
    assert _areas(ground).sum() == pytest.approx(np.ptp(v[:, 0]) * np.ptp(v[:, 1]))
    assert v[:, 2].max() < grid_world.parts["road"].vertices[:, 2].min()


def _distance_to_lane(points: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    a = np.stack([x[:-1], y[:-1]], 1)
    d = np.stack([x[1:], y[1:]], 1) - a
    t = np.clip(np.einsum("psk,sk->ps", points[:, None, :] - a[None], d) / np.einsum("sk,sk->s", d, d), 0, 1)
    return np.linalg.norm(points[:, None, :] - (a[None] + t[..., None] * d[None]), axis=2).min(axis=1)


def test_buildings_and_trees_off_the_roads(grid_world, grid_roads: Path) -> None:
    """Buildings stay off lanes and sidewalks; trees off driving lanes, trunks (below 1.5 m) off sidewalks
    (crowns may overhang a sidewalk)."""
    from pipeline.traffic.roadgeometry import load_road_geometry

    lanes = load_road_geometry(grid_roads).lanes
    rng = np.random.default_rng(0)
    for part, low_kinds, all_kinds in (("building", ["driving", "sidewalk"], ["driving", "sidewalk"]),
                                       ("vegetation", ["sidewalk"], ["driving"])):
        mesh = grid_world.parts[part]
        tri = mesh.vertices[mesh.triangles]
        w = rng.dirichlet(np.ones(3), len(tri))
        points = np.concatenate([np.einsum("tk,tkd->td", w, tri), mesh.vertices])
        low = points[points[:, 2] < 1.5, :2]
        for lane in lanes[lanes.kind.isin(low_kinds + all_kinds)].itertuples():
            check = points[:, :2] if lane.kind in all_kinds else low
            assert (_distance_to_lane(check, lane.shape_x, lane.shape_y) > lane.width_m / 2).all(), (part, lane)


def test_signal_lamps(grid_world, grid_roads: Path) -> None:
    from pipeline.traffic.roadgeometry import load_road_geometry

    tls = load_road_geometry(grid_roads).traffic_lights
    vehicle = tls[~tls.pedestrian]
    lamps = grid_world.signal_lamps
    assert len(lamps) == 3 * len(vehicle)
    assert list(zip(lamps.tls_id[::3], lamps.link_index[::3], strict=True)) == list(
        zip(vehicle.tls_id, vehicle.link_index, strict=True))
    # Each link's lamps hang 4-6 m up within a few metres of its stop line, facing the incoming traffic.
    stop = np.repeat(vehicle[["stop_x", "stop_y"]].to_numpy(), 3, axis=0)
    assert (np.linalg.norm(lamps.position[:, :2] - stop, axis=1) < 3.0).all()
    assert ((lamps.position[:, 2] > 3.5) & (lamps.position[:, 2] < 6.0)).all()
    facing = np.repeat(vehicle.heading_rad.to_numpy(), 3) + np.pi
    assert np.allclose(np.cos(lamps.facing_rad - facing), 1.0)
    tl = grid_world.parts["traffic_light"]
    assert lamps.triangles.max() <= len(tl) and set(np.asarray(MATERIAL_NAMES)[tl.material[:2 * len(lamps)]]) == {
        "signal_off"}
    merged = grid_world.meshes
    offset = grid_world.signal_lamp_triangles[0, 0]
    all_material = np.concatenate([m.material for m in merged])
    assert MATERIAL_NAMES[all_material[offset]] == "signal_off" and offset == grid_world.part_offset("traffic_light")
    # State strings light exactly one lamp per link for r / y / G.
    states = {t: "".join("rGy"[i % 3] for i in range(n)) for t, n in vehicle.groupby("tls_id").size().items()}
    states = {t: s + "r" * 10 for t, s in states.items()}  # pedestrian links follow
    lit = lamps.lit(states).reshape(-1, 3)
    assert (lit.sum(axis=1) == 1).all()
    # Lamps per link are (red, yellow, green): "r" lights column 0, "G" column 2, "y" column 1.
    assert (lit.argmax(axis=1) == np.array([0, 2, 1])[lamps.link_index[::3] % 3]).all()


def test_deterministic_and_seeded(grid_roads: Path, grid_world) -> None:
    again = build_static_world(grid_roads, seed=7)
    for name, mesh in grid_world.parts.items():
        np.testing.assert_array_equal(mesh.vertices, again.parts[name].vertices)
        np.testing.assert_array_equal(mesh.triangles, again.parts[name].triangles)
        np.testing.assert_array_equal(mesh.material, again.parts[name].material)
    np.testing.assert_array_equal(grid_world.street_lights, again.street_lights)
    other = build_static_world(grid_roads, seed=8)
    assert not np.array_equal(other.parts["building"].vertices, grid_world.parts["building"].vertices)


def test_highway_barriers_and_no_buildings(tmp_path: Path) -> None:
    nodes = '<node id="a" x="0" y="0"/><node id="b" x="500" y="0"/>'
    edges = ('<edge id="ab" from="a" to="b" numLanes="3" speed="33" type="highway.motorway"/>'
             '<edge id="ba" from="b" to="a" numLanes="3" speed="33" type="highway.motorway"/>')
    roads = _roads(tmp_path, nodes, edges)
    world = build_static_world(roads, seed=1)
    assert "building" not in world.parts and "barrier" in world.parts
    barrier = world.parts["barrier"].vertices
    # Carriageways span |y| <= 9.6 (3 x 3.2 m each way): barriers 0.6 m outside and one on the median.
    outer = np.abs(barrier[:, 1]) > 1.0
    assert (np.abs(barrier[outer, 1]) >= 9.6 + 0.3 - 1e-6).all()
    assert (np.abs(barrier[~outer, 1]) <= 0.2 + 1e-6).all() and (~outer).any()
    assert barrier[:, 2].max() == pytest.approx(0.8)
    assert len(world.street_lights) >= 10


def test_raster_marks_polygon_area() -> None:
    from pipeline.world.occupancy import Grid

    grid = Grid.covering((0.0, 0.0, 100.0, 100.0), cell_m=0.5)
    square = np.array([[10.0, 10.0], [60.0, 20.0], [50.0, 70.0], [0.0, 60.0]])  # 50.99^2 = 2600 m^2
    by_tris = grid.rasterise(np.stack([square[[0, 1, 2]], square[[0, 2, 3]]]))
    by_poly = np.zeros(grid.shape, bool)
    grid.mark_convex(square[::-1], by_poly)
    assert by_tris.sum() * 0.25 == pytest.approx(2600.0, rel=0.01)
    assert (by_tris != by_poly).sum() <= 0.005 * by_tris.sum()


def test_triangulate_ring_covers_polygons() -> None:
    from pipeline.world.polygons import signed_area, triangulate_ring

    rng = np.random.default_rng(3)
    for n in (3, 5, 12, 40):
        angle = np.sort(rng.uniform(0, 2 * np.pi, n))
        ring = np.stack([np.cos(angle), np.sin(angle)], 1) * rng.uniform(0.3, 1.0, (n, 1))  # star-shaped
        for r in (ring, ring[::-1]):
            tris = triangulate_ring(r)
            areas = np.array([signed_area(r[t]) for t in tris])
            assert len(tris) == n - 2 and (areas >= -1e-12).all()
            assert areas.sum() == pytest.approx(abs(signed_area(r)))


def test_chunk_boxes_contain_every_triangle(grid_world) -> None:
    from pipeline.world.scene import StaticScene

    scene = StaticScene(grid_world.meshes)
    lo, hi = scene.chunk_boxes
    verts = np.concatenate([m.vertices[m.triangles] for m in grid_world.meshes if len(m)])  # (T, 3, 3)
    assert len(lo) < len(verts) / 10  # boxes of many triangles each
    inside = np.zeros(len(verts), bool)
    for start in range(0, len(lo), 256):  # every triangle: some box holds all three of its vertices
        a, b = lo[start:start + 256], hi[start:start + 256]
        inside |= ((verts[:, None] >= a[None, :, None]) & (verts[:, None] <= b[None, :, None])).all(axis=(2, 3)).any(1)
    assert inside.all(), f"{np.count_nonzero(~inside)} triangles outside every chunk box"


@pytest.mark.parametrize("pose", [((50.0, 1.6, 1.4), (0.0, 0.0, 0.0)), ((100.0, 100.0, 1.4), (0.0, -1.2, 0.0)),
                                  ((-20.0, 20.0, 3.0), (0.1, 0.05, -0.7)), ((150.0, 98.0, 0.3), (0.0, 0.1, 3.0))])
def test_camera_skips_only_rays_that_cannot_hit_the_static_world(grid_world, pose) -> None:
    """The camera's static mask (chunk boxes projected) leaves out rays, and every hit is the same as without it."""
    from pipeline.sensors.camera import Camera
    from pipeline.world.scene import StaticScene, make_rays
    from tests.sensors.conftest import camera_config

    scene = StaticScene(grid_world.meshes)
    cam = Camera(camera_config(width_px=400, height_px=300))
    cam_to_world = cam.camera_to_world(Transform.from_xyz_rpy(*pose))
    rays = make_rays(cam_to_world.translation, cam.pixel_directions, cam_to_world.rotation)
    where = cam.boxes_pixel_mask(cam_to_world, *scene.chunk_boxes)
    full, masked = scene.cast(rays, where=None), scene.cast(rays, where=where)
    for a, b in zip(full, masked, strict=True):
        np.testing.assert_array_equal(a, b)
    sky = ~np.isfinite(full[0])
    assert where[~sky].all()
    if pose[1][1] < 0:  # looking up: most rays are sky and skipped, so the subset path ran
        assert where.mean() < 0.8 and sky.mean() > 0.3


def test_the_cached_world_is_the_built_one_and_follows_the_tables_and_seed(grid_roads: Path, grid_world, tmp_path,
                                                                         monkeypatch) -> None:
    """load_static_world builds once per (tables, seed, code) and then loads the same world from the build cache."""
    import pipeline.world.static as static

    monkeypatch.setenv("ROADSYNTH_CACHE_DIR", str(tmp_path / "cache"))
    builds = []
    monkeypatch.setattr(static, "build_static_world", lambda *a, **k: builds.append(1) or build_static_world(*a, **k))
    first = load_static_world(grid_roads, seed=7)
    again = load_static_world(grid_roads, seed=7)
    assert len(builds) == 1 and len(list((tmp_path / "cache").glob("static-world-*.pickle"))) == 1
    for world in (first, again):
        assert list(world.parts) == list(grid_world.parts)
        for name, mesh in grid_world.parts.items():
            for field in ("vertices", "triangles", "material"):
                np.testing.assert_array_equal(getattr(world.parts[name], field), getattr(mesh, field))
        np.testing.assert_array_equal(world.street_lights, grid_world.street_lights)
    other_seed = load_static_world(grid_roads, seed=8)
    assert not np.array_equal(other_seed.parts["building"].vertices, grid_world.parts["building"].vertices)
    changed = tmp_path / "roads"
    shutil.copytree(grid_roads, changed)
    (changed / "network.json").write_text((changed / "network.json").read_text() + "\n")  # another byte: rebuilt
    load_static_world(changed, seed=7)
    assert len(builds) == 3 and len(list((tmp_path / "cache").glob("static-world-*.pickle"))) == 3
    with pytest.raises(FileNotFoundError, match="no road geometry folder"):
        load_static_world(tmp_path / "nowhere", seed=7)


def test_a_scene_over_the_shared_geometry_is_the_scene_of_its_meshes(grid_roads: Path, grid_world, tmp_path,
                                                                    monkeypatch) -> None:
    """The static geometry (merged meshes, smooth normals' corners, chunk boxes, the sun maps' index) is built once
    per world, kept in the build cache, and shared by every StaticScene over it: their casts are those of a scene
    built from the meshes, and one scene's material changes (signal lamps) reach neither the geometry nor another."""
    from pipeline.sensors.camera import Camera
    from pipeline.sensors.shadows import sun_disc
    from pipeline.world.scene import StaticGeometry, StaticScene, make_rays
    from pipeline.world.static import load_static_geometry
    from tests.sensors.conftest import camera_config

    monkeypatch.setenv("ROADSYNTH_CACHE_DIR", str(tmp_path / "cache"))
    world = load_static_world(grid_roads, seed=7)
    built = load_static_geometry(world, grid_roads, seed=7)
    loaded = load_static_geometry(world, grid_roads, seed=7)
    assert len(list((tmp_path / "cache").glob("static-geometry-*.pickle"))) == 1
    assert built is not loaded  # the second came from the cache file
    fresh = StaticGeometry(world.meshes)
    for name in ("mesh_offsets", "vertices", "triangles", "triangle_material", "triangle_semantic", "smooth_row",
                 "corner_normals"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(fresh, name))
    assert len(fresh.corner_normals) > 0  # the grid world's trees are smooth
    own, shared, other = StaticScene(world.meshes), StaticScene(world.meshes, loaded), StaticScene(world.meshes, loaded)
    cam = Camera(camera_config(width_px=200, height_px=150))
    cam_to_world = cam.camera_to_world(Transform.from_xyz_rpy((50.0, 1.6, 1.4), (0.0, 0.0, 0.3)))
    rays = make_rays(cam_to_world.translation, cam.pixel_directions, cam_to_world.rotation)
    for a, b in zip(own.cast(rays), shared.cast(rays), strict=True):
        assert a.tobytes() == b.tobytes()
    disc = sun_disc(np.array([0.3, 0.2, 0.9]) / np.linalg.norm([0.3, 0.2, 0.9]), 0.01)
    hit = np.flatnonzero(np.isfinite(own.cast(rays)[0]))
    points = [(rays[hit, k] + rays[hit, 3 + k] * own.cast(rays)[0][hit]).astype(np.float32) for k in range(3)]
    assert loaded.sun_tiles(disc) is loaded.sun_tiles(disc.copy())  # one index per disc
    np.testing.assert_array_equal(own.sun_candidates(*points, disc[0], disc=disc),
                                  shared.sun_candidates(*points, disc[0], disc=disc))
    before = loaded.triangle_material.copy()
    changed = (before[:3] + 1) % len(MATERIAL_NAMES)  # mesh 0's first triangles, each to another material
    shared.set_triangle_materials(0, np.arange(3), changed)
    np.testing.assert_array_equal(shared.triangle_material[:3], changed)
    np.testing.assert_array_equal(loaded.triangle_material, before)
    np.testing.assert_array_equal(other.triangle_material, before)
    with pytest.raises(ValueError, match="not these 2 meshes"):
        StaticScene(world.meshes[:2], loaded)
