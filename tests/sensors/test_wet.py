"""Rain on roads and vehicles (pipeline.sensors.wet): a water film over car paint reflects more than dry paint,
most at grazing angles, in closed form and end to end; dry conditions are unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sensors.indirect import mirror_rays
from pipeline.sensors.shading import shade
from pipeline.sensors.wet import WATER_F0, WET_PAINT_DARKENING
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import condition


def _schlick(f0, cos):
    return f0 + (1.0 - f0) * (1.0 - cos) ** 5


@pytest.mark.parametrize("incidence_deg", [0.0, 45.0, 70.0, 80.0, 88.0])
def test_water_film_adds_its_fresnel_over_the_coat(incidence_deg):
    """F = F_coat + w F_water (1 - F_coat): above the dry F_coat at every angle, by more at grazing angles."""
    a = np.radians(incidence_deg)
    rays = np.array([[0.0, 0.0, 10.0, np.sin(a), 0.0, -np.cos(a)]], np.float32)
    t = np.array([10.0 / max(np.cos(a), 0.05)], np.float32)
    normal, rows, coat = np.float32([[0, 0, 1]]), np.array([0]), np.float32([0.05])
    _, dry = mirror_rays(rays, t, normal, rows, coat, np.zeros(1, np.float32), np.float32(WATER_F0))
    _, wet = mirror_rays(rays, t, normal, rows, coat, np.float32([0.85]), np.float32(WATER_F0))
    cos = np.cos(a)
    assert dry[0] == pytest.approx(_schlick(0.05, cos), rel=1e-4)
    expected = _schlick(0.05, cos) + 0.85 * _schlick(WATER_F0, cos) * (1.0 - _schlick(0.05, cos))
    assert wet[0] == pytest.approx(expected, rel=1e-4)
    assert wet[0] > dry[0]


def test_wet_paint_mirrors_more_of_the_sky_at_grazing_angles(box_meshes, actors_factory):
    """The roof of a painted box under a uniform bright sky, no sun: seen at 80 degrees from its normal, the wet
    roof's reflectance F = (L - base) / (sky - base) (base: its diffuse radiance, darker when wet) is the film's
    F_coat + w F_water (1 - F_coat), above the dry roof's F_coat; seen straight down, nearly the same."""
    sky = {"zenith_rgb": (1.0, 1.0, 1.0), "horizon_rgb": (1.0, 1.0, 1.0), "ambient_rgb": (0.3, 0.3, 0.3)}
    dry = condition(sun={"elevation_deg": -10.0}, sky=sky)
    wet = condition(sun={"elevation_deg": -10.0}, sky=sky, rain={"rate_mm_h": 5.0, "wetness": 0.8})
    scene = FrameScene(StaticScene([]), actors_factory([[0.0, 0.0, 0.75]], [[20.0, 20.0, 1.5]]), box_meshes)
    reflectance = {}
    for incidence_deg in (80.0, 0.0):
        a = np.radians(incidence_deg)
        target = np.array([0.0, 0.0, 1.5])
        d = np.array([np.sin(a), 0.0, -np.cos(a)])
        rays = np.concatenate([target - 5.0 * d, d])[None].astype(np.float32)
        hits = scene.cast_rays(rays)
        assert hits.instance_id[0] == 1
        for name, lighting in (("dry", dry), ("wet", wet)):
            base = shade(scene, rays, hits, lighting)[0]  # no mirror: the diffuse (darkened when wet) radiance
            full = shade(scene, rays, hits, lighting, indirect=True)[0]
            reflectance[name, incidence_deg] = float(np.mean((full - base) / (1.0 - base)))
    cos80 = np.cos(np.radians(80.0))
    coat80 = _schlick(0.05, cos80)
    assert reflectance["dry", 80.0] == pytest.approx(coat80, rel=1e-3)
    assert reflectance["wet", 80.0] == pytest.approx(coat80 + 0.8 * _schlick(WATER_F0, cos80) * (1 - coat80),
                                                     rel=1e-3)
    assert reflectance["wet", 80.0] > reflectance["dry", 80.0] + 0.15
    assert reflectance["wet", 0.0] - reflectance["dry", 0.0] == pytest.approx(0.8 * WATER_F0 * 0.95, abs=1e-3)


def test_wet_paint_is_a_little_darker_and_the_dry_image_is_unchanged(box_meshes, actors_factory):
    scene = FrameScene(StaticScene([]), actors_factory([[0.0, 0.0, 0.75]], [[20.0, 20.0, 1.5]]), box_meshes)
    rays = np.array([[0.0, 0.0, 5.0, 0.0, 0.0, -1.0]], np.float32)
    hits = scene.cast_rays(rays)
    dry = condition(sun={"elevation_deg": 60.0, "shadows": False})
    wet = condition(sun={"elevation_deg": 60.0, "shadows": False}, rain={"rate_mm_h": 5.0, "wetness": 0.5})
    no_rain = condition(sun={"elevation_deg": 60.0, "shadows": False}, rain={"rate_mm_h": 5.0, "wetness": 0.0})
    ratio = shade(scene, rays, hits, wet)[0] / shade(scene, rays, hits, dry)[0]
    # Diffuse and ambient scale with the albedo; the highlight (sun_rgb * specular) does not: a lower bound.
    assert np.all(ratio < 1.0) and np.all(ratio >= 1.0 - WET_PAINT_DARKENING * 0.5 - 1e-6)
    np.testing.assert_array_equal(shade(scene, rays, hits, no_rain, indirect=True),
                                  shade(scene, rays, hits, dry, indirect=True))


@pytest.mark.parametrize("grazing", [0.06, 0.5])
def test_a_rough_wet_roads_lobe_is_long_and_thin_at_grazing_angles(grazing):
    """One reflecting pixel on a road that fills the image, seen at a grazing angle of sine g: its lobe spreads
    sigma_v along the image's vertical and sigma_v sin g across (g the middle of its GRAZING_BANDS band), the
    weights normalised: the second moments of the spread give both widths."""
    from pipeline.sensors.wet import GRAZING_BANDS, _lobes

    h, w, sigma_v = 201, 181, 12.0
    layer = np.zeros((h, w, 4), np.float32)
    layer[100, 90] = (1.0, 1.0, 1.0, 1.0)
    mask = np.ones((h, w), np.float32)
    sel = np.arange(h * w)
    out = _lobes(layer, mask, sel, np.full(h * w, grazing), sigma_v)[:, 0].reshape(h, w)
    lo = max(b for b in GRAZING_BANDS if b <= grazing)
    hi = min(b for b in GRAZING_BANDS if b > grazing)
    sigma_h = sigma_v * np.sqrt(lo * hi)
    ys, xs = np.mgrid[0:h, 0:w]
    total = out.sum()
    assert total == pytest.approx(1.0, rel=1e-3)
    assert np.sqrt((out * (ys - 100) ** 2).sum() / total) == pytest.approx(sigma_v, rel=0.03)
    assert np.sqrt((out * (xs - 90) ** 2).sum() / total) == pytest.approx(sigma_h, rel=0.05)
