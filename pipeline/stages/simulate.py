"""``roadsynth simulate``: build the network and demand, run SUMO, record trajectories.

Writes into OUT (atomically): the exact SUMO inputs (network.net.xml, demand.rou.xml, run.sumocfg and
the plain XML the network was built from), trajectories.parquet, tls_states.parquet, vehicles.parquet
(every vehicle's sampled parameters), roads/ (static road geometry for the renderer), stats.json and
meta.json. Layout and columns: docs/simulate.md.
"""

from __future__ import annotations

import argparse
import logging
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.core.classes import ObjectClass
from pipeline.core.config import ScenarioConfig
from pipeline.core.config.resolve import resolve_scenario
from pipeline.core.files import atomic_file
from pipeline.core.outputs import MARK, MARK_KEY, OutputSpec, json_file
from pipeline.core.tables import write_parquet
from pipeline.stages.common import atomic_output_dir, run_seed, write_json, write_meta
from pipeline.traffic import networks
from pipeline.traffic.demand import Demand, build_demand
from pipeline.traffic.parking import PARKED_FILE, place_parked, with_parked
from pipeline.traffic.roadgeometry import write_road_geometry
from pipeline.traffic.simulation import ActorColumns, run, to_trajectories, write_sumocfg

log = logging.getLogger(__name__)

INPUT_ARGS = ("scenario",)
HELP = "simulate traffic with SUMO and record every actor"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", required=True, help="scenario NAME (configs/scenarios/) or YAML PATH")
    parser.add_argument("--seed", type=run_seed, required=True,
                        help="run seed (every random draw derives from it)")
    parser.add_argument("--out", type=Path, required=True, help="output folder (replaced atomically)")
    parser.add_argument("--vehicles", type=int, help="override demand.vehicles")
    parser.add_argument("--duration", type=float, help="override simulation.duration_s (recorded seconds)")
    parser.add_argument("--warmup", type=float, help="override simulation.warmup_s")
    parser.add_argument("--metrics-out", type=Path, help="also write the run's summary stats here (for dvc metrics)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def outputs(args: argparse.Namespace) -> list[OutputSpec]:
    """The run folder, and the stats file of ``--metrics-out``."""
    specs = [OutputSpec(args.out)]
    if args.metrics_out is not None:
        specs.append(OutputSpec(args.metrics_out, flag="--metrics-out", folder=False,
                                recognise=json_file(dict, ("frames", "collisions", "teleports")),
                                expected="a JSON file of run stats"))
    return specs


def simulate(config: ScenarioConfig, seed: int, out: Path, *, progress: bool = True) -> dict[str, object]:
    """Run the simulate stage; returns the stats written to stats.json."""
    with atomic_output_dir(out) as tmp:
        net_file = networks.build_network(config.network, tmp)
        work = tmp / "_work"
        demand = build_demand(config.demand, net_file, tmp, work, seed)
        shutil.rmtree(work)
        sumocfg = write_sumocfg(tmp, net_file.name, demand.routes_file.name, config.simulation, seed)
        candidates = demand.vehicles.loc[demand.vehicles["cls"] == config.ego.cls.value, "vehicle_id"].tolist()
        vehicles, persons, tls_rows, counters, ego_id = run(sumocfg, config.simulation, config.ego, candidates, seed,
                                                             progress=progress)
        stats = write_run(tmp, config, seed, net_file, demand, vehicles, persons, tls_rows, counters, ego_id)
        write_meta(tmp, stage="simulate", config=config.model_dump(mode="json"), seed=seed)
    return stats


def write_run(out: Path, config: ScenarioConfig, seed: int, net_file: Path, demand: Demand, vehicles: ActorColumns,
              persons: ActorColumns, tls_rows: list[tuple], counters: dict[str, object],
              ego_id: str) -> dict[str, object]:
    """Write a recorded run's tables, road geometry and stats.json into ``out`` (a folder being built that already
    holds the network, the demand and run.sumocfg); returns the stats. The recording comes from
    :class:`pipeline.traffic.simulation.RunRecorder` (``run`` here, or the driving environment's ``record=``)."""
    actors = demand.actor_table()
    parked = place_parked(config.demand, net_file, seed, demand.bus_stops)
    trajectories = with_parked(to_trajectories(vehicles, persons, actors, ego_id), parked,
                               int(actors["track_id"].max()) + 1)
    write_parquet(trajectories, out / "trajectories.parquet")
    write_parquet(parked, out / PARKED_FILE)
    tls = pd.DataFrame(tls_rows, columns=["frame", "time_s", "tls_id", "state"]).astype({"frame": np.int32})
    write_parquet(tls, out / "tls_states.parquet")
    write_parquet(demand.vehicles, out / "vehicles.parquet")
    write_road_geometry(net_file, out / "roads", demand.bus_stops)
    stats = _stats(trajectories, counters, config, ego_id, networks.network_summary(net_file))
    write_json(out / "stats.json", stats)
    return stats


def _stats(traj: pd.DataFrame, counters: dict, config: ScenarioConfig, ego_id: str, net: dict) -> dict[str, object]:
    vehicles = traj[(traj["cls"] != ObjectClass.PEDESTRIAN.value) & ~traj["parked"]]
    parked = traj[traj["parked"] & (traj["frame"] == traj["frame"].min())]
    per_frame = traj.groupby("frame").size()
    return {
        "ego_id": ego_id,
        "frames": int(traj["frame"].nunique()),
        "recorded_actor_states": len(traj),
        "actors_recorded": int(traj["track_id"].nunique()),
        "actors_per_frame_mean": round(float(per_frame.mean()), 3),
        "vehicles_configured": config.demand.vehicles,
        "vehicles_inserted": int(counters.get("departed", 0)),
        "vehicles_arrived": int(counters.get("arrived", 0)),
        "persons_inserted": int(counters.get("persons_departed", 0)),
        "parked_vehicles": len(parked),
        "parked_by_class": {str(k): int(v) for k, v in sorted(parked["cls"].value_counts().items())},
        "collisions": int(counters.get("collisions", 0)),
        "collision_events": counters.get("collision_events", []),
        "teleports": int(counters.get("teleports", 0)),
        "ego_left_early": bool(counters.get("ego_left_early", 0)),
        "mean_speed_mps": round(float(vehicles["speed_mps"].mean()), 4) if len(vehicles) else 0.0,
        # Moving vehicles per km of driving lane at the first recorded frame (what the ego drives through).
        "density_veh_per_lane_km": round(float(((vehicles["frame"] == vehicles["frame"].min()).sum())
                                               / max(net["driving_lane_length_m"] / 1000.0, 1e-9)), 3),
        "network": net,
    }


def main(args: argparse.Namespace) -> int:
    config, path = resolve_scenario(args.scenario, vehicles=args.vehicles, duration_s=args.duration,
                                    warmup_s=args.warmup)
    log.info("scenario %s from %s, seed %d", config.name, path, args.seed)
    stats = simulate(config, args.seed, args.out, progress=not args.no_progress)
    if args.metrics_out is not None:
        summary = {k: v for k, v in stats.items() if k not in ("collision_events", "ego_id")}
        summary[MARK_KEY] = f"{MARK} simulate"  # ours: a rerun may replace it, another program's file it may not
        with atomic_file(args.metrics_out) as tmp:
            write_json(tmp, summary)
    log.info("recorded %d frames, %d actor states; %d collisions, %d teleports -> %s", stats["frames"],
             stats["recorded_actor_states"], stats["collisions"], stats["teleports"], args.out)
    return 0
