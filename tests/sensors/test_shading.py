"""Day shading: tone mapping values, sun versus shadow, sky for misses, lit brake lights."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.sensors.shading import shade, sky, to_srgb8
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import condition


def test_tone_map_is_srgb_per_channel():
    rgb = to_srgb8(np.array([[[0.0, 0.5, 0.2158]], [[0.5, 0.5, 0.5]]], np.float32))
    assert rgb.shape == (2, 1, 3) and rgb.dtype == np.uint8
    assert rgb[0, 0].tolist() == [0, 188, 128]  # sRGB(0.5) = 0.7354, sRGB(0.2158) = 0.5020
    assert rgb[1, 0].tolist() == [188, 188, 188]
    assert to_srgb8(np.array([[-1.0, 10.0, 0.0031308]], np.float32)).tolist() == [[0, 255, 10]]


def test_tone_map_follows_the_srgb_curve_with_its_shoulder_everywhere():
    x = np.concatenate([np.linspace(0.0, 4.5, 20001), [np.nan, np.inf, -np.inf]]).astype(np.float32)
    soft = np.where(x > 0.8, 0.8 + 0.2 * np.tanh((np.minimum(x, 4.0) - 0.8) / 0.2), x)
    srgb = np.where(soft <= 0.0031308, 12.92 * soft, 1.055 * np.power(np.maximum(soft, 0.0031308), 1 / 2.4) - 0.055)
    expected = np.nan_to_num(np.clip(255.0 * srgb, 0.0, 255.0), nan=0.0, neginf=0.0)
    got = to_srgb8(np.repeat(x[:, None], 3, axis=1))
    assert np.all(got == got[:, :1])  # channel by channel, the same curve
    # The table's steps are 4 / 65535 wide: at most one 8-bit level from the exact curve, and monotone.
    assert np.max(np.abs(got[:, 0].astype(float) - expected)) <= 1.0
    assert np.all(np.diff(got[:20001, 0].astype(int)) >= 0)
    assert got[-3:, 0].tolist() == [0, 255, 0]  # NaN, +inf, -inf


def test_sun_shadow_and_sky(box_meshes, actors_factory, wall):
    # Wall x = 10 facing the origin; the sun 10 deg high behind the camera (towards -x) lights it with
    # n.l = cos 10 deg. A thin box at x = 7, y in [2, 4], z in [-1, 1] shades the wall around (10, 3, 0).
    lighting = condition(sun={"elevation_deg": 10.0, "azimuth_deg": 180.0})
    scene = FrameScene(StaticScene([wall(10.0, half_size_m=5.0)]), actors_factory([[7.0, 3.0, 0.0]], [[0.5, 2.0, 2.0]]),
                       box_meshes)
    origins = np.array([[0.0, 0.0, 0.0], [8.0, 1.0, 0.0], [0.0, 0.0, 0.0]])  # (8, 1, 0) sees past the box
    targets = np.array([[10.0, -3.0, 0.0], [10.0, 3.0, 0.0], [10.0, 0.0, 50.0]])
    d = (targets - origins) / np.linalg.norm(targets - origins, axis=1, keepdims=True)
    rays = np.concatenate([origins, d], axis=1).astype(np.float32)
    hits = scene.cast_rays(rays)
    assert hits.hit.tolist() == [True, True, False] and hits.instance_id[1] == 0
    out = shade(scene, rays, hits, lighting)
    albedo = material_arrays()["albedo"][material_index("concrete")]
    ambient, sun = np.asarray(lighting.ambient_rgb), np.asarray(lighting.sun_rgb)
    np.testing.assert_allclose(out[0], albedo * (ambient + np.cos(np.radians(10.0)) * sun), rtol=1e-5)
    np.testing.assert_allclose(out[1], albedo * ambient, rtol=1e-5)  # in the box's shadow
    np.testing.assert_allclose(out[2], sky(rays[2:, 3:], lighting)[0])
    lit_no_shadows = shade(scene, rays, hits,
                           condition(sun={"elevation_deg": 10.0, "azimuth_deg": 180.0, "shadows": False}))
    np.testing.assert_allclose(lit_no_shadows[1], out[0], rtol=1e-5)


def test_brake_lights_glow(actors_factory):
    actors = actors_factory([[10.0, 0.0, 0.0], [10.0, 5.0, 0.0]], [[4.5, 1.8, 1.5]] * 2, classes=[ObjectClass.CAR] * 2,
                            brake=[True, False])
    scene = FrameScene(StaticScene([]), actors)
    tail = material_index("taillight")
    # Aim at each car's tail lights from behind: find a taillight triangle and shoot at its centroid.
    geo = scene.geometry
    rays = []
    for k in range(2):
        tri = np.flatnonzero((geo.triangle_actor == k) & (geo.triangle_material == tail))
        centroid = geo.vertices[geo.triangles[tri]].mean(axis=1)
        target = centroid[np.argmin(centroid[:, 0])]
        rays.append(np.concatenate([target - [5.0, 0, 0], [1.0, 0.0, 0.0]]))
    rays = np.asarray(rays, np.float32)
    hits = scene.cast_rays(rays)
    assert (hits.material == tail).all()
    out = shade(scene, rays, hits, condition(sun={"shadows": False}))
    assert out[0, 0] > out[1, 0] + 1.0


def test_condition_validation():
    with pytest.raises(ValueError):
        condition(sun={"elevation_deg": 120.0})
    with pytest.raises(ValueError):
        condition(lens={"exposure": 0.0})


def test_a_bicycles_lamps_glow_at_night(actors_factory):
    """A bicycle's front and rear lamps glow at night with its lights on (a ridden bicycle's are), not with them
    off: seen from ahead and from behind, their lenses are brighter lit than unlit."""
    from pipeline.sensors.conditions import get_condition

    night = get_condition("night")
    assert night.lights_on
    for material, side in (("headlight", 1.0), ("taillight", -1.0)):
        rays, out = [], []
        for lit in (True, False):
            actors = actors_factory([[10.0, 0.0, 0.85]], [[1.75, 0.65, 1.7]], classes=[ObjectClass.BICYCLE],
                                    lights_on=[lit])
            scene = FrameScene(StaticScene([]), actors)
            geo = scene.geometry
            tri = np.flatnonzero(geo.triangle_material == material_index(material))
            centroid = geo.vertices[geo.triangles[tri]].mean(axis=1)
            target = centroid[np.argmax(side * centroid[:, 0])]
            rays = np.asarray([np.concatenate([target + [side * 5.0, 0.0, 0.0], [-side, 0.0, 0.0]])], np.float32)
            hits = scene.cast_rays(rays)
            assert hits.material[0] == material_index(material)
            out.append(shade(scene, rays, hits, night)[0])
        assert out[0].sum() > 0.5 and out[0].sum() > 100.0 * out[1].sum(), (material, out)
