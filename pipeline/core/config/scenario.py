"""Scenario configuration: network, demand (naturalistic background vehicles), simulation and ego.

Units are in the field names (``_m``, ``_s``, ``_hz``, ``_mps``). Distributions are tagged mappings
(see :mod:`pipeline.core.config.distributions`).
"""

from __future__ import annotations

import enum
from pathlib import Path

import numpy as np
from pydantic import ConfigDict, Field, field_validator, model_validator

from pipeline.core.classes import ObjectClass
from pipeline.core.config.base import ConfigModel
from pipeline.core.config.distributions import Constant, Distribution, TruncNormal, Uniform


class _Model(ConfigModel):
    model_config = ConfigDict(use_enum_values=False)


class NetworkKind(str, enum.Enum):
    HIGHWAY = "highway"
    URBAN = "urban"
    OSM = "osm"


class HighwayNetwork(_Model):
    lanes_per_direction: int = Field(3, ge=3, le=6)
    lane_width_m: float = Field(3.5, gt=2.5, le=5.0)
    straight_length_m: float = Field(1500.0, ge=300.0, description="each straight before/after the curve")
    curve_radius_m: float = Field(800.0, ge=150.0)
    curve_angle_deg: float = Field(40.0, gt=0.0, le=120.0)
    median_width_m: float = Field(4.0, ge=1.0)
    speed_limit_mps: float = Field(33.33, gt=5.0, le=70.0)
    ramp_speed_mps: float = Field(22.22, gt=5.0, le=40.0)


class UrbanNetwork(_Model):
    blocks_x: int = Field(4, ge=4, le=20)
    blocks_y: int = Field(4, ge=4, le=20)
    block_length_m: float = Field(120.0, ge=50.0, le=500.0)
    lanes_per_direction: int = Field(2, ge=1, le=4)
    lane_width_m: float = Field(3.2, gt=2.5, le=5.0)
    sidewalk_width_m: float = Field(2.5, ge=1.0, le=6.0)
    speed_limit_mps: float = Field(13.89, gt=3.0, le=30.0)
    parking_lane_width_m: float | None = Field(
        None, ge=1.8, le=3.0,
        description="a kerbside parking lane of this width on every street (between sidewalk and traffic); "
                    "None: no parking lane")


class NetworkConfig(_Model):
    """Which road network to build. ``osm_file`` is required (and only allowed) for ``kind: osm``."""

    kind: NetworkKind
    highway: HighwayNetwork = HighwayNetwork()
    urban: UrbanNetwork = UrbanNetwork()
    osm_file: Path | None = None

    @model_validator(mode="after")
    def _check_osm(self) -> NetworkConfig:
        if self.kind is NetworkKind.OSM and self.osm_file is None:
            raise ValueError("kind 'osm' needs osm_file: the path of an OpenStreetMap .osm extract")
        if self.kind is not NetworkKind.OSM and self.osm_file is not None:
            raise ValueError(f"osm_file is only used with kind 'osm', not {self.kind.value!r}")
        return self


class DriverModel(_Model):
    """Per-vehicle car-following (SUMO IDM) and lane-change parameters, each sampled per vehicle.

    speed_factor: desired speed / lane speed limit (SUMO speedFactor).
    tau_s: desired time headway T. min_gap_m: standstill gap s0. accel_mps2: maximum acceleration a.
    decel_mps2: comfortable deceleration b. delta: IDM acceleration exponent.
    imperfection: driver imperfection in [0, 1): SUMO's driver-state device with
        initialAwareness = 1 - imperfection (perception errors on gap and speed difference; SUMO's IDM
        ignores Krauss' ``sigma``). 0 disables the device.
    lc_cooperative: willingness to make room for others, [0, 1]. lc_assertive: acceptance of small
        gaps when changing lanes (>= 1 means accepting smaller gaps).
    """

    speed_factor: Distribution
    tau_s: Distribution
    min_gap_m: Distribution
    accel_mps2: Distribution
    decel_mps2: Distribution
    delta: Distribution = Constant(value=4.0)
    imperfection: Distribution = Constant(value=0.0)
    lc_cooperative: Distribution = Constant(value=1.0)
    lc_assertive: Distribution = Constant(value=1.0)


class ClassSpec(_Model):
    """One actor class in the mix: its share and its size and colour distributions."""

    share: float = Field(ge=0.0)
    length_m: Distribution
    width_m: Distribution
    height_m: Distribution
    colors: list[tuple[int, int, int]] = Field(min_length=1, description="RGB 0-255, drawn uniformly or by "
                                               "color_shares")
    color_shares: list[float] | None = Field(None, description="relative frequency of each colour (same order)")
    max_speed_mps: float = Field(gt=0.0)
    driver: DriverModel | None = Field(None, description="overrides the demand's driver model")

    @field_validator("colors")
    @classmethod
    def _check_colors(cls, colors: list[tuple[int, int, int]]) -> list[tuple[int, int, int]]:
        for rgb in colors:
            if not all(0 <= c <= 255 for c in rgb):
                raise ValueError(f"colour components must be in 0..255, got {rgb}")
        return colors

    @model_validator(mode="after")
    def _check_color_shares(self) -> ClassSpec:
        shares = self.color_shares
        if shares is not None and (len(shares) != len(self.colors) or min(shares) < 0 or sum(shares) <= 0):
            raise ValueError(f"color_shares must give one share >= 0 per colour ({len(self.colors)}), not all 0; "
                             f"got {shares}")
        return self

    def color_index(self, rng: np.random.Generator, size: int | None = None) -> np.ndarray | int:
        """Indices into ``colors`` (``size`` of them, or one): uniform, or weighted by ``color_shares``."""
        if self.color_shares is None:
            return rng.integers(0, len(self.colors), size=size)
        p = np.asarray(self.color_shares, np.float64)
        return rng.choice(len(self.colors), size=size, p=p / p.sum())


class DeparturePattern(str, enum.Enum):
    UNIFORM = "uniform"  # evenly spaced departures over the window
    RANDOM = "random"  # independent uniform departure times over the window


class ParkedConfig(_Model):
    """Vehicles parked along the kerb, in the network's parking lanes (``urban.parking_lane_width_m``).

    Each parking lane is filled from ``end_clearance_m`` after its start to ``end_clearance_m`` before its end
    (lanes end where the junction and its crossings begin) with a row of slots: a vehicle of a class drawn by
    ``classes`` share, sized and coloured like moving vehicles of that class (``demand.classes``), then a gap
    drawn from ``gap_m``. Each slot holds its vehicle with probability ``occupancy`` (else it stays empty).
    A parked vehicle keeps ``kerb_gap_m`` between its right side and the lane's kerb edge.
    """

    occupancy: float = Field(0.7, ge=0.0, le=1.0)
    classes: dict[ObjectClass, float] = Field(default_factory=lambda: {ObjectClass.CAR: 0.85, ObjectClass.VAN: 0.15},
                                              min_length=1, description="share per class")
    gap_m: Distribution = Uniform(low=0.8, high=2.5)
    kerb_gap_m: Distribution = Uniform(low=0.1, high=0.35)
    end_clearance_m: float = Field(5.0, ge=0.0, description="no parking this close to a lane end")

    @field_validator("classes")
    @classmethod
    def _check_shares(cls, classes: dict[ObjectClass, float]) -> dict[ObjectClass, float]:
        if any(v < 0 for v in classes.values()) or sum(classes.values()) <= 0:
            raise ValueError(f"shares must be >= 0 and not all zero, got {classes}")
        if ObjectClass.PEDESTRIAN in classes:
            raise ValueError("pedestrians do not park")
        return classes


class DepartPosition(str, enum.Enum):
    """Where on its first edge a vehicle is inserted (SUMO ``departPos``)."""

    BASE = "base"  # at the start of the edge: one entry lane inserts a vehicle per safe headway at most
    RANDOM_FREE = "random_free"  # at a random free position along the edge


class BusStopConfig(_Model):
    """Bus stops on the network's sidewalks, with a shelter behind each, and people waiting at them
    (:mod:`pipeline.traffic.busstops`). The stops are the network's: the same for every seed of a scenario."""

    share: float = Field(0.2, ge=0.0, le=1.0, description="the share of sidewalks (of at least min_sidewalk_m) "
                         "with a stop, near their middle")
    min_sidewalk_m: float = Field(60.0, ge=10.0, description="no stop on a sidewalk shorter than this")
    waiting_mean: float = Field(0.0, ge=0.0, le=7.0, description="people waiting at a stop when the run starts: "
                                "the mean of a Poisson distribution (at most 7, the places along a stop)")
    waiting_s: Distribution = Field(Uniform(low=180.0, high=900.0),
                                    description="how long a waiting person stands before walking on, seconds")
    dwell_s: Distribution | None = Field(Uniform(low=15.0, high=40.0),
                                         description="how long a bus stands at each stop on its route, seconds "
                                         "(None: buses drive past the stops)")


class DemandConfig(_Model):
    """Background traffic. ``vehicles`` vehicles depart in ``[0, depart_window_s]`` on random routes."""

    vehicles: int = Field(200, ge=1, le=20000)
    depart_window_s: float = Field(60.0, gt=0.0)
    departure: DeparturePattern = DeparturePattern.RANDOM
    depart_pos: DepartPosition = Field(DepartPosition.BASE,
                                       description="where on its first edge a vehicle is inserted (departPos)")
    min_route_length_m: float = Field(300.0, ge=0.0)
    classes: dict[ObjectClass, ClassSpec]
    driver: DriverModel
    pedestrians: int = Field(0, ge=0, description="pedestrians walking sidewalks and crossings (urban/osm)")
    pedestrian_speed_mps: Distribution = TruncNormal(mean=1.34, std=0.26, low=0.6, high=2.2)
    runners: float = Field(0.0, ge=0.0, le=1.0, description="the share of the walking pedestrians who run instead "
                           "(joggers, people hurrying), at runner_speed_mps")
    runner_speed_mps: Distribution = Field(TruncNormal(mean=2.9, std=0.35, low=2.3, high=4.0),
                                           description="a runner's speed, m/s (recreational paces of 4-7 min/km)")
    standing_pedestrians: int = Field(0, ge=0, description="more pedestrians who first stand on a sidewalk, alone or "
                                      "in a small group (waiting, talking, at a shop front), then walk on")
    standing_s: Distribution = Field(Uniform(low=60.0, high=300.0),
                                     description="how long a standing pedestrian stands after departing, seconds")
    parked: ParkedConfig | None = Field(None, description="vehicles parked in the network's parking lanes")
    bus_stops: BusStopConfig | None = Field(None, description="bus stops with shelters on the sidewalks, and the "
                                            "people waiting at them")

    @model_validator(mode="after")
    def _check_classes(self) -> DemandConfig:
        if ObjectClass.PEDESTRIAN in self.classes:
            raise ValueError("pedestrians are not a vehicle class: set 'pedestrians' (a count) instead")
        if self.parked is not None:
            missing = sorted(c.value for c in self.parked.classes if c not in self.classes)
            if missing:
                raise ValueError(f"parked.classes {missing} have no entry in classes (their sizes and colours)")
        if sum(spec.share for spec in self.classes.values()) <= 0:
            raise ValueError("class shares must not all be zero")
        return self


class SimulationConfig(_Model):
    step_length_s: float = Field(0.1, gt=0.0, le=1.0)
    record_hz: float = Field(10.0, gt=0.0)
    warmup_s: float = Field(60.0, ge=0.0)
    duration_s: float = Field(20.0, gt=0.0, description="recorded time after the warm-up")
    time_to_teleport_s: float = Field(120.0, description="SUMO --time-to-teleport; <= 0 disables teleports")
    collision_action: str = Field("warn", pattern="^(none|warn|teleport|remove)$")

    @model_validator(mode="after")
    def _check_rates(self) -> SimulationConfig:
        steps = 1.0 / (self.record_hz * self.step_length_s)
        if steps < 1 - 1e-9 or abs(steps - round(steps)) > 1e-6:
            raise ValueError(
                f"record_hz ({self.record_hz}) must divide the step rate 1/step_length_s "
                f"({1.0 / self.step_length_s:g} Hz) into a whole number of steps"
            )
        return self

    @property
    def record_every_steps(self) -> int:
        return round(1.0 / (self.record_hz * self.step_length_s))

    @property
    def num_frames(self) -> int:
        return round(self.duration_s * self.record_hz)


class EgoConfig(_Model):
    """The ego is a random vehicle (by seed) whose remaining route covers the recording, or ``vehicle_id``.

    ``min_neighbours`` > 0 narrows the random choice to candidates with at least that many other vehicles
    driving their way within ``neighbour_radius_m`` ahead of them (in the half-plane in front of their heading,
    headings less than 90 deg apart) at the end of the warm-up: the ego still is a random vehicle, drawn among
    those that have traffic to look at. When no candidate has that many, those with the most are used (logged).
    0 keeps the paper's plain random ego. ``min_speed_mps`` > 0 also leaves out candidates slower than that at
    the end of the warm-up (on the highway: cars just inserted at an entry, still queued, have neighbours too).
    """

    vehicle_id: str | None = None
    route_margin: float = Field(1.2, ge=1.0, description="remaining route >= margin x duration x max speed")
    cls: ObjectClass = ObjectClass.CAR
    min_neighbours: int = Field(0, ge=0)
    neighbour_radius_m: float = Field(40.0, gt=0.0)
    min_speed_mps: float = Field(0.0, ge=0.0)


class ScenarioConfig(_Model):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    network: NetworkConfig
    demand: DemandConfig
    simulation: SimulationConfig = SimulationConfig()
    ego: EgoConfig = EgoConfig()
