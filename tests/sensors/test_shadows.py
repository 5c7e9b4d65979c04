"""Soft sun shadows (pipeline.sensors.shadows): the disc's directions, a penumbra whose width is the occluder's
distance times the sun's angular diameter, unchanged full light and full shadow, exact conservative tests for every
disc direction, and anti-aliasing samples borrowing their surface's smoothed share."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.sensors.shading import shade
from pipeline.sensors.shadows import (
    SUN_SAMPLES,
    borrowed_shares,
    pixel_shares,
    sun_blocked,
    sun_disc,
    sun_rays,
    sun_shares,
)
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import condition

SPACING_M = 0.01  # the grid of rays: one "pixel" per centimetre of ground
RAY_HEIGHT_M = 0.5  # straight down from this height: a pixel's angle is SPACING_M / RAY_HEIGHT_M


def _quad(x0, x1, y0, y1, z, material="concrete", semantic=SemanticClass.BUILDING) -> Mesh:
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], np.float64)
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index(material), semantic)


def _grid(x0: float, columns: int, rows: int) -> np.ndarray:
    """(rows * columns, 6) float32 rays straight down onto z = 0, row-major, x = x0 + column * SPACING_M."""
    gx, gy = np.meshgrid(x0 + SPACING_M * np.arange(columns), SPACING_M * (np.arange(rows) - rows // 2))
    n = gx.size
    return np.column_stack([gx.ravel(), gy.ravel(), np.full(n, RAY_HEIGHT_M), np.zeros((n, 2)),
                            -np.ones(n)]).astype(np.float32)


def test_disc_directions_cover_the_sun_evenly():
    sun = np.array([0.3, 0.4, np.sqrt(0.75)])
    radius = np.radians(3.0)  # wide enough for float32 directions to resolve
    disc = sun_disc(sun, radius).astype(np.float64)
    assert disc.shape == (SUN_SAMPLES, 3)
    np.testing.assert_allclose(np.linalg.norm(disc, axis=1), 1.0, atol=1e-6)
    angle = np.arctan2(np.linalg.norm(np.cross(disc, sun), axis=1), disc @ sun)
    assert angle.max() <= radius * 1.0001
    # Spread evenly over the disc: a uniform disc has E[angle^2] = radius^2 / 2, and each quarter holds four.
    assert np.mean((angle / radius) ** 2) == pytest.approx(0.5, abs=0.06)  # 0.45: sixteen points, stratified
    e1 = np.cross([0.0, 0.0, 1.0], sun)
    e2 = np.cross(sun, e1)
    quarter = (disc @ e1 > 0).astype(int) + 2 * (disc @ e2 > 0)
    assert np.bincount(quarter, minlength=4).tolist() == [4, 4, 4, 4]
    mean = disc.mean(axis=0)
    assert np.degrees(np.arccos(mean @ sun / np.linalg.norm(mean))) < 1e-4
    np.testing.assert_array_equal(sun_disc(sun, 0.0), sun[None].astype(np.float32))


def _plate_scene(height_m: float) -> FrameScene:
    """The ground, and a plate 1 m wide (x in [-0.5, 0.5]) at ``height_m`` above it, long in y."""
    return FrameScene(StaticScene([_quad(-50, 50, -50, 50, 0.0, "asphalt", SemanticClass.ROAD),
                                   _quad(-0.5, 0.5, -20, 20, height_m)]), _no_actors())


def _no_actors():
    from pipeline.world.actors import Actors

    return Actors.empty()


SUN_45 = {"elevation_deg": 45.0, "azimuth_deg": 0.0}  # towards +x: the plate's edge x = 0.5 shades x = 0.5 - H


def _profile(height_m: float, radius_deg: float = 2.0, columns: int = 121, rows: int = 9):
    lighting = condition(sun={**SUN_45, "angular_radius_deg": radius_deg})
    scene = _plate_scene(height_m)
    edge_x = 0.5 - height_m
    rays = _grid(edge_x - SPACING_M * (columns // 2), columns, rows)
    hits = scene.cast_rays(rays)
    _, lit, share = sun_shares(scene, rays, hits, lighting, lighting.sun_disc, (rows, columns),
                                     SPACING_M / RAY_HEIGHT_M)
    assert len(lit) == len(rays)
    return share.reshape(rows, columns), rays[:columns, 0] - edge_x


@pytest.mark.parametrize("height_m", [0.6, 1.5, 3.0])
def test_penumbra_width_is_the_occluders_distance_times_the_suns_angular_diameter(height_m):
    """On the ground, the edge of a plate H above it lies d = H / sin 45 deg up the sun's ray; the penumbra spans
    d * 2 tan(radius) / sin 45 deg across the edge (the ground is tilted to the sun), and for a disc its 25-75 %
    part is 0.404 of that. Measured on the rows whose smoothing window lies inside the grid, within 15 % and a
    pixel; centred on the point sun's hard edge within two pixels."""
    share, offset_m = _profile(height_m)
    mean = share[2:-2].mean(axis=0)
    full_m = height_m / np.sin(np.pi / 4) * 2 * np.tan(np.radians(2.0)) / np.sin(np.pi / 4)
    rising = np.maximum.accumulate(mean)  # the dither left after smoothing is a few per cent
    width_m = np.interp(0.75, rising, offset_m) - np.interp(0.25, rising, offset_m)
    assert width_m == pytest.approx(0.404 * full_m, rel=0.15, abs=SPACING_M)
    assert abs(np.interp(0.5, rising, offset_m)) <= 2 * SPACING_M
    # Full light and full shadow beyond the penumbra: exactly 1 and 0.
    beyond = np.abs(offset_m) > 0.5 * full_m + 3 * SPACING_M
    assert np.all(share[:, beyond & (offset_m > 0)] == 1.0) and np.all(share[:, beyond & (offset_m < 0)] == 0.0)


def test_penumbra_narrows_towards_the_contact():
    widths = []
    for height_m in (0.6, 3.0):
        share, _ = _profile(height_m)
        inside = (share.mean(axis=0) > 0.02) & (share.mean(axis=0) < 0.98)
        widths.append(inside.sum() * SPACING_M)
    assert widths[1] > 3.0 * widths[0]


def test_full_light_and_full_shadow_shade_as_under_a_point_sun():
    """Shaded with the realistic camera's passes, pixels far from the penumbra have the radiance they have under a
    point sun, to the bit; inside it each pixel lies between its radiance without the sun and without shadows."""
    scene = _plate_scene(1.5)
    columns, rows = 121, 9
    rays = _grid(-1.0 - SPACING_M * (columns // 2), columns, rows)
    hits = scene.cast_rays(rays)

    def shaded(**sun):
        lighting = condition(sun={**SUN_45, "angular_radius_deg": 2.0, **sun})
        return shade(scene, rays, hits, lighting, indirect=True, pixel_angle_rad=SPACING_M / RAY_HEIGHT_M,
                     image_shape=(rows, columns)).reshape(rows, columns, 3)

    soft, hard = shaded(), shaded(angular_radius_deg=0.0)
    unshadowed, sunless = shaded(shadows=False), shaded(intensity=0.0)
    offset = rays[:columns, 0] + 1.0
    far = np.abs(offset) > 0.25
    np.testing.assert_array_equal(soft[:, far], hard[:, far])
    assert np.all((soft >= sunless - 1e-6) & (soft <= unshadowed + 1e-6))
    between = (soft > sunless + 1e-3) & (soft < unshadowed - 1e-3)
    assert between[:, ~far].any() and not between[:, far].any()


def test_every_disc_direction_keeps_its_conservative_tests_exact(box_meshes, actors_factory):
    """Shadow rays along all sixteen directions, from ground points around an actor and a wall at a low sun: the
    per-direction actor and sun-map tests block exactly the rays that the unmasked cast blocks."""
    actors = actors_factory([[3.0, 0.0, 0.75], [6.0, 4.0, 1.0]], [[4.5, 1.8, 1.5], [2.0, 2.0, 2.0]])
    scene = FrameScene(StaticScene([_quad(-50, 50, -50, 50, 0.0, "asphalt", SemanticClass.ROAD),
                                    _quad(-2, -1.9, -10, 10, 3.0)]), actors, box_meshes)
    lighting = condition(sun={"elevation_deg": 14.0, "azimuth_deg": 10.0, "angular_radius_deg": 3.0})
    gx, gy = np.meshgrid(np.linspace(-8.0, 2.0, 60), np.linspace(-3.0, 3.0, 40))
    n = gx.size
    rays = np.column_stack([gx.ravel(), gy.ravel(), np.full(n, 0.2), np.zeros((n, 2)),
                            -np.ones(n)]).astype(np.float32)
    hits = scene.cast_rays(rays)
    disc = lighting.sun_disc
    _, lit, shadow, which = sun_rays(rays, hits.normal, hits.t_m, lighting.sun_direction, disc, 60, n)
    assert set(which.tolist()) == set(range(SUN_SAMPLES))
    blocked, _, _ = sun_blocked(scene, shadow, which, disc, hits.t_m[lit])
    np.testing.assert_array_equal(blocked, scene.occluded_rays(shadow))
    assert 0 < blocked.sum() < len(blocked)


def test_samples_borrow_the_share_of_their_surface():
    """A 3 x 3 grid: the centre pixel's samples take its own share if they hit its surface, else the first
    neighbour's on their surface, else NaN (traced); unlit centres (NaN) lend nothing."""
    centre = pixel_shares(9, np.array([0, 1, 2, 3, 4, 5, 7, 8]), np.linspace(0.1, 0.8, 8).astype(np.float32))
    instance = np.zeros(9, np.int32)
    instance[[2, 5, 8]] = 7  # the right column is an actor
    normal = np.tile(np.float32([0, 0, 1]), (9, 1))
    t = np.full(9, 10.0, np.float32)
    where = np.array([4, 4, 4, 4, 6])
    sample_instance = np.array([0, 7, 3, 0, 0], np.int32)
    sample_normal = np.float32([[0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0], [0, 0, 1]])
    sample_t = np.float32([10.1, 10.0, 10.0, 10.0, 10.0])
    got = borrowed_shares(centre, instance, normal, t, where, sample_instance, sample_normal, sample_t, 3, 3,
                          np.float32(0.95), np.float32(0.03))
    assert got[0] == centre[4]  # its own pixel's surface
    assert got[1] == centre[2]  # the actor: the first neighbour on it (top right)
    assert np.isnan(got[2]) and np.isnan(got[3])  # no pixel of that instance; a normal turned by 90 degrees
    assert got[4] == centre[3]  # pixel 6 is not lit (NaN): its neighbour above
