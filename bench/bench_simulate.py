"""Benchmark: recording cost of the simulate stage against bare libsumo stepping.

Builds the highway scenario (200 vehicles by default) once, then times, alternating and in one run:
  bare      libsumo stepping of the same .sumocfg for warm-up + recording, no subscriptions
  recorded  the stage's loop (subscriptions, ego choice, TLS states) + trajectory table + Parquet write
and prints recorded actor-states per second and the ratio recorded / bare (target: <= 1.30).

    python bench/bench_simulate.py [--vehicles 200] [--duration 60] [--warmup 90] [--repeats 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from pipeline.core.tables import write_parquet
from pipeline.stages.simulate import resolve_scenario
from pipeline.traffic import networks
from pipeline.traffic.demand import build_demand
from pipeline.traffic.simulation import VEHICLE_VARS, run, to_trajectories, write_sumocfg
from pipeline.traffic.sumo_tools import binary


def bare(sumocfg: Path, steps: int) -> float:
    import libsumo

    start = time.perf_counter()
    libsumo.start([binary("sumo"), "-c", str(sumocfg), "--no-warnings", "true"])
    for _ in range(steps):
        libsumo.simulationStep()
    libsumo.close()
    return time.perf_counter() - start


def subscribed(sumocfg: Path, steps: int, warm_steps: int, retrieve: bool) -> float:
    """Bare stepping plus the stage's vehicle subscriptions (and, optionally, reading them each step)."""
    import libsumo

    start = time.perf_counter()
    libsumo.start([binary("sumo"), "-c", str(sumocfg), "--no-warnings", "true"])
    for step in range(steps):
        libsumo.simulationStep()
        if step >= warm_steps:
            new = libsumo.vehicle.getIDList() if step == warm_steps else libsumo.simulation.getDepartedIDList()
            for vid in new:
                libsumo.vehicle.subscribe(vid, VEHICLE_VARS)
            if retrieve:
                libsumo.vehicle.getAllSubscriptionResults()
    libsumo.close()
    return time.perf_counter() - start


def recorded(sumocfg: Path, config, demand, out: Path) -> tuple[float, int]:
    start = time.perf_counter()
    candidates = demand.vehicles.loc[demand.vehicles["cls"] == "car", "vehicle_id"].tolist()
    veh, ped, _, _, ego = run(sumocfg, config.simulation, config.ego, candidates, 1, progress=False)
    traj = to_trajectories(veh, ped, demand.actor_table(), ego)
    write_parquet(traj, out / "trajectories.parquet")
    return time.perf_counter() - start, len(traj)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vehicles", type=int, default=200)
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--warmup", type=float, default=90.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config, _ = resolve_scenario("highway", vehicles=args.vehicles, duration_s=args.duration, warmup_s=args.warmup)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        net = networks.build_network(config.network, tmp)
        demand = build_demand(config.demand, net, tmp, tmp / "work", seed=1)
        sumocfg = write_sumocfg(tmp, net.name, demand.routes_file.name, config.simulation, 1)
        sim = config.simulation
        steps = round(sim.warmup_s / sim.step_length_s) + (sim.num_frames - 1) * sim.record_every_steps + 1
        warm = round(sim.warmup_s / sim.step_length_s)
        bare_times, sub_times, get_times, rec_times, states = [], [], [], [], 0
        for _ in range(args.repeats):
            bare_times.append(bare(sumocfg, steps))
            sub_times.append(subscribed(sumocfg, steps, warm, retrieve=False))
            get_times.append(subscribed(sumocfg, steps, warm, retrieve=True))
            elapsed, states = recorded(sumocfg, config, demand, tmp)
            rec_times.append(elapsed)
    b, r = min(bare_times), min(rec_times)
    sub, get = min(sub_times), min(get_times)
    rows = [
        ("scenario", f"highway, {args.vehicles} vehicles, {args.warmup:g} s warm-up + {args.duration:g} s at "
                     f"{sim.record_hz:g} Hz"),
        (f"bare libsumo stepping (best of {args.repeats})", f"{b:.2f} s"),
        ("  + vehicle subscriptions (SUMO computes them each step)", f"{sub:.2f} s ({sub / b:.2f}x)"),
        ("  + getAllSubscriptionResults each step", f"{get:.2f} s ({get / b:.2f}x)"),
        ("simulate stage loop + table + parquet", f"{r:.2f} s"),
        ("recorded actor-states", f"{states}"),
        ("recorded actor-states per second", f"{states / r:,.0f}"),
        ("ratio stage / bare (target <= 1.30)", f"{r / b:.3f}"),
    ]
    width = max(len(k) for k, _ in rows)
    print(f"{'measure':<{width}} | value")
    print(f"{'-' * width}-|------")
    for key, value in rows:
        print(f"{key:<{width}} | {value}")


if __name__ == "__main__":
    main()
