"""Per-vehicle parameters follow their configured distributions (statistical tests, fixed seed)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy import stats

from pipeline.core.config import ScenarioConfig, load_config
from pipeline.core.config.distributions import LogNormal, TruncNormal, Uniform
from pipeline.traffic.demand import DRIVER_FIELDS, sample_vehicles

N = 4000


@pytest.fixture(scope="module")
def highway() -> ScenarioConfig:
    return load_config(ScenarioConfig, "highway", "scenarios")[0]


@pytest.fixture(scope="module")
def sampled(highway):
    demand = highway.demand.model_copy(update={"vehicles": N})
    return demand, sample_vehicles(demand, np.random.default_rng(12345))


def test_class_shares_match_configuration(sampled):
    demand, table = sampled
    counts = table["cls"].value_counts()
    classes = sorted(demand.classes, key=lambda c: c.value)
    observed = np.array([counts.get(c.value, 0) for c in classes])
    expected = np.array([demand.classes[c].share for c in classes])
    expected = expected / expected.sum() * N
    assert stats.chisquare(observed, expected).pvalue > 1e-3


@pytest.mark.parametrize("field", [f for f in DRIVER_FIELDS])
def test_car_driver_parameters_follow_their_distributions(sampled, field):
    demand, table = sampled
    dist = getattr(demand.driver, field)
    values = table.loc[table["cls"] == "car", field].to_numpy()
    if not isinstance(dist, (TruncNormal, LogNormal, Uniform)):
        assert np.all(values == dist.value)
        return
    assert stats.kstest(values, dist.cdf).pvalue > 1e-3
    lo, hi = getattr(dist, "low", -np.inf), getattr(dist, "high", np.inf)
    assert values.min() >= lo and values.max() <= hi


def test_class_override_and_sizes(sampled):
    demand, table = sampled
    trucks = table[table["cls"] == "truck"]
    override = demand.classes["truck"].driver
    assert stats.kstest(trucks["tau_s"], override.tau_s.cdf).pvalue > 1e-3
    assert stats.kstest(trucks["length_m"], demand.classes["truck"].length_m.cdf).pvalue > 1e-3
    colors = {tuple(c) for c in demand.classes["truck"].colors}
    assert set(map(tuple, trucks[["color_r", "color_g", "color_b"]].to_numpy().tolist())) <= colors


def test_a_wrong_distribution_is_rejected(sampled):
    # The KS test above has power: shifting the mean by a fifth of a std is detected at this sample size.
    demand, table = sampled
    dist = demand.driver.tau_s
    shifted = dist.model_copy(update={"mean": dist.mean + 0.2 * dist.std})
    values = table.loc[table["cls"] == "car", "tau_s"].to_numpy()
    assert stats.kstest(values, shifted.cdf).pvalue < 1e-3


def test_written_vtypes_carry_each_vehicles_parameters(small_highway_run):
    import pandas as pd

    vehicles = pd.read_parquet(small_highway_run / "vehicles.parquet").set_index("vehicle_id")
    root = ET.parse(small_highway_run / "demand.rou.xml").getroot()
    vtypes = {v.get("id"): v for v in root.iter("vType")}
    assert len(vtypes) == len(vehicles) == 40
    for vid, row in vehicles.iterrows():
        vt = vtypes[f"t_{vid}"]
        assert vt.get("carFollowModel") == "IDM"
        assert float(vt.get("tau")) == pytest.approx(row["tau_s"], abs=1e-12)
        assert float(vt.get("accel")) == pytest.approx(row["accel_mps2"], abs=1e-12)
        assert float(vt.get("speedFactor")) == pytest.approx(row["speed_factor"], abs=1e-12)
        assert float(vt.get("length")) == pytest.approx(row["length_m"], abs=1e-12)


def test_color_shares_set_the_colour_frequencies():
    """With color_shares, colours are drawn by those shares (a large sample, within 3 standard errors); without,
    uniformly as before; shares of the wrong length or all zero fail naming the field."""
    import numpy as np
    import pytest
    from pydantic import ValidationError

    from pipeline.core.config.scenario import ClassSpec

    base = dict(share=1.0, length_m={"dist": "constant", "value": 4.5}, width_m={"dist": "constant", "value": 1.8},
                height_m={"dist": "constant", "value": 1.5}, colors=[[255, 255, 255], [0, 0, 0], [255, 0, 0]],
                max_speed_mps=40.0)
    spec = ClassSpec(**base, color_shares=[0.6, 0.3, 0.1])
    n = 20000
    counts = np.bincount(spec.color_index(np.random.default_rng(0), n), minlength=3) / n
    np.testing.assert_allclose(counts, [0.6, 0.3, 0.1], atol=3 * np.sqrt(0.25 / n))
    uniform = ClassSpec(**base)
    np.testing.assert_array_equal(uniform.color_index(np.random.default_rng(1), 50),
                                  np.random.default_rng(1).integers(0, 3, size=50))
    for bad in ([0.5, 0.5], [0.0, 0.0, 0.0], [1.0, -0.5, 0.5]):
        with pytest.raises(ValidationError, match="color_shares"):
            ClassSpec(**base, color_shares=bad)


def test_a_share_of_the_walkers_run_from_a_stream_of_their_own():
    """``runners`` of the walkers (binomial) get a runner's speed (``runner_speed_mps``), the others keep theirs; no
    runners leaves every speed; the same seed draws the same runners, another seed others."""
    from pipeline.traffic.demand import _with_runners

    config = load_config(ScenarioConfig, "urban", "scenarios")[0].demand
    assert config.runners == pytest.approx(0.04)
    walk = config.pedestrian_speed_mps.sample(np.random.default_rng(2), N)
    speed = _with_runners(config, walk, seed=9)
    runs = speed != walk
    k = int(runs.sum())
    assert stats.binomtest(k, N, config.runners).pvalue > 1e-3
    assert (speed[runs] >= 2.3).all() and (speed[runs] <= 4.0).all() and 2.7 < speed[runs].mean() < 3.1
    assert (walk <= 2.2).all()
    np.testing.assert_array_equal(_with_runners(config, walk, seed=9), speed)
    assert not np.array_equal(_with_runners(config, walk, seed=10) != walk, runs)
    none = config.model_copy(update={"runners": 0.0})
    np.testing.assert_array_equal(_with_runners(none, walk, seed=9), walk)


def test_standing_pedestrians_stand_in_groups_on_their_first_sidewalk():
    """Standing pedestrians come in groups of 1-3 (shares STANDING_GROUP_SHARES), side by side STANDING_SPACING_M
    apart on the sidewalk of their walk's first edge, inside it, departing, standing and walking on together; a walk
    whose first edge is too short for the group gets no stop."""
    import pandas as pd

    from pipeline.traffic.demand import STANDING_LATERAL_M, STANDING_SPACING_M, _standing

    config = load_config(ScenarioConfig, "urban", "scenarios")[0].demand.model_copy(
        update={"pedestrians": 0, "standing_pedestrians": 300})
    sidewalks = {"long": ("long_0", 90.0, 2.5), "short": ("short_0", 5.0, 2.5)}
    walks = [("w", ["short" if i % 50 == 7 else "long", "next"]) for i in range(300)]
    rows = _standing(config, sidewalks, walks, np.random.default_rng(4))
    assert len(rows) == 300 and rows["person_id"].is_unique
    stops = rows[rows["stop_lane"] != ""]
    assert set(stops["stop_lane"]) == {"long_0"} and len(stops) < len(rows)
    assert ((stops["stop_pos_m"] >= 3.0) & (stops["stop_pos_m"] <= 87.0)).all()
    assert ((stops["stop_s"] >= 60.0) & (stops["stop_s"] <= 300.0)).all()
    groups = stops.groupby(["depart_s", "stop_s"])
    sizes = groups.size()
    assert set(sizes) <= {1, 2, 3} and {1, 2, 3} <= set(sizes)
    for _, group in groups:
        np.testing.assert_allclose(np.diff(group["stop_pos_m"]), STANDING_SPACING_M, atol=0.011)
        assert group["speed_mps"].nunique() == 1 and group["route"].nunique() == 1
    assert pd.isna(rows.loc[rows["stop_lane"] == "", "stop_pos_m"]).all()
    alone = stops.set_index(["depart_s", "stop_s"]).loc[sizes[sizes == 1].index]
    assert (alone["stand_dx_m"] == 0.0).all() and (alone["stand_dy_m"] == STANDING_LATERAL_M).all()
    assert alone["stand_face_rad"].notna().all()


def test_a_person_standing_alone_faces_the_street_the_shops_or_along_the_sidewalk():
    """LONE_FACING_RAD with their shares (binomial bounds over 4000 draws), each within LONE_TURN_RAD of its way."""
    from pipeline.traffic.demand import LONE_FACING_RAD, LONE_FACING_SHARES, LONE_TURN_RAD, _lone_facing

    rng = np.random.default_rng(7)
    face = np.array([_lone_facing(rng) for _ in range(N)])
    off = np.angle(np.exp(1j * (face[:, None] - np.array(LONE_FACING_RAD)[None, :])))
    nearest = np.argmin(np.abs(off), axis=1)
    assert (np.abs(off[np.arange(N), nearest]) <= LONE_TURN_RAD + 1e-12).all()
    for k, share in enumerate(LONE_FACING_SHARES):
        assert abs(np.mean(nearest == k) - share) < 4 * np.sqrt(share * (1 - share) / N)


def test_a_standing_group_stands_in_a_formation_facing_each_other():
    """Two face each other FORMATION_PAIR_M apart, three stand on a circle of FORMATION_RADIUS_M facing its centre
    (the members' places: their stops plus dx along the sidewalk, dy across it); all within the sidewalk less the
    margin, the group's centre along the sidewalk at its stops' mean."""
    from pipeline.traffic.demand import (
        FORMATION_MARGIN_M,
        FORMATION_PAIR_M,
        FORMATION_RADIUS_M,
        STANDING_LATERAL_M,
        _formation,
    )

    rng = np.random.default_rng(1)
    for size in (2, 3):
        for _ in range(200):
            stops = 10.0 + 0.75 * np.arange(size)
            f = _formation(size, stops, 2.5, rng)
            a, across = stops + f[:, 0], f[:, 1]
            centre = np.array([a.mean(), across.mean()])
            assert abs(centre[0] - stops.mean()) < 1e-9
            assert np.all(np.abs(across) <= 1.25 - FORMATION_MARGIN_M + 1e-9)
            radius = np.hypot(a - centre[0], across - centre[1])
            np.testing.assert_allclose(radius, FORMATION_PAIR_M / 2 if size == 2 else FORMATION_RADIUS_M)
            facing = np.column_stack([np.cos(f[:, 2]), np.sin(f[:, 2])])
            towards = (centre - np.column_stack([a, across])) / radius[:, None]
            np.testing.assert_allclose(facing, towards, atol=1e-9)  # each faces the group's centre
            # Across the sidewalk as near STANDING_LATERAL_M as the margin allows.
            if np.all(np.abs(across - across.mean() + STANDING_LATERAL_M) <= 1.25 - FORMATION_MARGIN_M):
                assert abs(across.mean() - STANDING_LATERAL_M) < 1e-9
