"""The static world of one simulated run: road-geometry tables (``<sim>/roads/``) to triangle meshes.

:func:`build_static_world` builds, in world coordinates (SUMO network frame, metres, x east, y north, z up):
road surfaces and junctions, sidewalks with kerbs, crossings with zebra stripes, lane markings and stop
lines (:mod:`pipeline.world.roadmesh`); a grass ground plane below road level; buildings, trees, street
lamps and highway barriers (:mod:`pipeline.world.props`); traffic-light poles and signal heads
(:mod:`pipeline.world.signals`). It also returns what the renderer animates or lights per frame: the
signal lamps per (tls_id, link_index) and the street-light positions. All random choices come from
``numpy.random.default_rng(seed)``, so the same tables and seed give the same world.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.core.build_cache import cached, source_key
from pipeline.core.classes import SemanticClass
from pipeline.traffic.roadgeometry import RoadGeometry, load_road_geometry
from pipeline.world.mesh import Mesh
from pipeline.world.occupancy import Grid
from pipeline.world.primitives import PartBuilder, quads
from pipeline.world.props import PropPlacer
from pipeline.world.roadmesh import RoadSurfaces
from pipeline.world.signals import SignalLamps, build_signals

if TYPE_CHECKING:
    from pipeline.world.scene import StaticGeometry

log = logging.getLogger(__name__)

GROUND_DZ_M = -0.05  # grass sits this far below the lowest road point, so roads always win


@dataclass(frozen=True)
class StaticWorld:
    """Static meshes and the positions of dynamic lights.

    Attributes:
        parts: name -> Mesh (world frame), one semantic class each: ground, road, sidewalk, kerb, crossing,
            lane_marking, building, vegetation, pole, barrier, traffic_light_pole, traffic_light.
        signal_lamps: one row per lamp of each controlled link (see :class:`SignalLamps`); its
            ``triangles`` index ranges of ``parts["traffic_light"]`` to re-material per frame.
        street_lights: (S, 3) float64 positions of street-lamp heads (light sources, pointing down).
        ground_bounds: (xmin, ymin, xmax, ymax) of the ground plane, metres.
        ground_z: height of the ground plane, metres.
    """

    parts: dict[str, Mesh]
    signal_lamps: SignalLamps
    street_lights: np.ndarray
    ground_bounds: tuple[float, float, float, float]
    ground_z: float

    @property
    def meshes(self) -> list[Mesh]:
        """All meshes, in a fixed order (sorted part names)."""
        return [self.parts[k] for k in sorted(self.parts)]

    @property
    def num_triangles(self) -> int:
        return sum(len(m) for m in self.parts.values())

    def part_offset(self, name: str) -> int:
        """Index of a part's first triangle when :attr:`meshes` are concatenated in order."""
        names = sorted(self.parts)
        if name not in names:
            raise KeyError(f"no part {name!r}; parts: {', '.join(names)}")
        return sum(len(self.parts[n]) for n in names[: names.index(name)])

    @property
    def signal_lamp_triangles(self) -> np.ndarray:
        """(L, 2) int64 [start, stop) of each signal lamp's triangles in the concatenation of :attr:`meshes`."""
        if not len(self.signal_lamps):
            return np.zeros((0, 2), np.int64)
        return self.signal_lamps.triangles.astype(np.int64) + self.part_offset("traffic_light")


def _ground(geo: RoadGeometry) -> tuple[Mesh, tuple[float, float, float, float], float]:
    xmin, ymin, xmax, ymax = geo.network["bounds"]
    margin = max(100.0, 0.2 * max(xmax - xmin, ymax - ymin))
    zs = [np.min(z) for z in geo.lanes.shape_z if len(z)]
    z = (min(zs) if zs else 0.0) + GROUND_DZ_M
    bounds = (xmin - margin, ymin - margin, xmax + margin, ymax + margin)
    x0, y0, x1, y1 = bounds
    corners = np.array([[[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]])
    part = PartBuilder(SemanticClass.TERRAIN)
    part.add(*quads(corners), "grass")
    return part.build(), bounds, z


def build_world_from_geometry(geo: RoadGeometry, *, seed: int) -> StaticWorld:
    """Build the static world from in-memory road geometry (see :func:`build_static_world`)."""
    rng = np.random.default_rng(seed)
    roads = RoadSurfaces(geo).build()
    ground, bounds, ground_z = _ground(geo)
    grid = Grid.covering(bounds)
    paved, driving, junctions = (grid.rasterise(np.concatenate(t)) if t else np.zeros(grid.shape, bool)
                                 for t in (roads.paved_tris, roads.driving_tris, roads.junction_tris))
    placer = PropPlacer(geo, grid, paved, driving, junctions, roads.highway, rng)
    placer.build()
    signal_parts, lamps = build_signals(geo, placer)

    builders = {**roads.parts, **placer.parts, **signal_parts}
    parts = {"ground": ground}
    for name in sorted(builders):
        mesh = builders[name].build()
        if mesh is not None:
            parts[name] = mesh
    world = StaticWorld(parts, lamps, placer.street_lights, bounds, ground_z)
    log.info("static world: %d triangles in %d parts, %d signal lamps, %d street lights",
             world.num_triangles, len(parts), len(lamps), len(world.street_lights))
    return world


def build_static_world(roads_dir: Path, *, seed: int) -> StaticWorld:
    """Build the static world from the road geometry tables in ``roads_dir`` (written by the simulate stage).

    Raises:
        FileNotFoundError: a table is missing (names the directory and the files).
    """
    return build_world_from_geometry(load_road_geometry(roads_dir), seed=seed)


# Static worlds kept in the build cache (urban ~18 MB each): the paper's matrix (6 simulations), its renders in any
# order, builds each world once.
CACHED_WORLDS = 8
WORLD_CACHE_NAME = "static-world"
GEOMETRY_CACHE_NAME = "static-geometry"  # its merged geometry (load_static_geometry)


def static_world_key(roads_dir: Path, seed: int) -> str:
    """The build cache's key of the static world of ``roads_dir``'s tables and ``seed`` (:func:`load_static_world`):
    a digest of the package's sources, the seed and every file's name and bytes in ``roads_dir``."""
    roads_dir = Path(roads_dir)
    if not roads_dir.is_dir():
        raise FileNotFoundError(f"{roads_dir}: no road geometry folder (written by `roadsynth simulate`)")
    digest = hashlib.sha256(f"{source_key()}|{int(seed)}".encode())
    for path in sorted(p for p in roads_dir.iterdir() if p.is_file()):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def load_static_world(roads_dir: Path, *, seed: int) -> StaticWorld:
    """:func:`build_static_world`'s world, from the build cache (:mod:`pipeline.core.build_cache`, name
    :data:`WORLD_CACHE_NAME`) when a process built it from the same road tables (every file's name and bytes), seed
    and code; else built, and kept there for the next render of the same simulation (another condition, a
    closed-loop episode on the same network)."""
    return cached(WORLD_CACHE_NAME, lambda: build_static_world(roads_dir, seed=seed),
                  key=static_world_key(roads_dir, seed), keep=CACHED_WORLDS)


def load_static_geometry(world: StaticWorld, roads_dir: Path, *, seed: int) -> StaticGeometry:
    """The :class:`pipeline.world.scene.StaticGeometry` of ``world``, :func:`load_static_world`'s world of
    ``roads_dir`` and ``seed``: from the build cache (name :data:`GEOMETRY_CACHE_NAME`, under the world's key) when a
    process built it for the same world, else built (the static world's smooth normals: ~0.25 s of CPU on the
    highway) and kept there beside the world."""
    from pipeline.world.scene import StaticGeometry

    return cached(GEOMETRY_CACHE_NAME, lambda: StaticGeometry(world.meshes), key=static_world_key(roads_dir, seed),
                  keep=CACHED_WORLDS)
