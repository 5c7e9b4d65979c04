"""``record=DIR``: an episode written as a simulated run, so that ``roadsynth render`` and ``export`` read it unchanged.

The folder holds exactly what ``roadsynth simulate`` writes (docs/simulate.md), through the simulate stage's own
writer (:func:`pipeline.stages.simulate.write_run`): the network and its plain XML, the demand, run.sumocfg,
trajectories.parquet (frame 0 at the end of the warm-up, one frame per env step), tls_states.parquet,
vehicles.parquet, parked.parquet, roads/, stats.json and meta.json. The ego's trajectory is the agent's; replaying
run.sumocfg in sumo-gui shows the background demand with SUMO driving the ego instead. meta.json's config is the
scenario as the env ran it plus an ``env`` entry (the options and the episode's end); stats.json adds
``episode_end``.
"""

from __future__ import annotations

import shutil
from dataclasses import asdict
from pathlib import Path

from pipeline.core.config import ScenarioConfig, SimulationConfig
from pipeline.stages.common import atomic_output_dir, write_json, write_meta
from pipeline.stages.simulate import write_run
from pipeline.traffic.demand import Demand
from pipeline.traffic.simulation import RunRecorder, write_sumocfg


def episode_dir(root: Path, episode: int) -> Path:
    """The folder of the env's ``episode``-th recorded episode (counted from 0 over the env's life)."""
    return Path(root) / f"episode-{episode:04d}"


def write_episode(out: Path, *, config: ScenarioConfig, sim: SimulationConfig, options, seed: int, net_file: Path,
                  demand: Demand, recorder: RunRecorder, ego_id: str, end: str | None) -> dict[str, object]:
    """Write the recorded episode into ``out`` (atomically: it appears only when complete); returns its stats.

    ``config`` is the scenario, ``sim`` the simulation settings the env ran (its step length, one recorded frame
    per step), ``net_file`` the env's network (its folder's files are copied), ``demand`` the run seed's demand,
    ``recorder`` the episode's recording, ``end`` the episode's end reason (None: stopped before it ended)."""
    frames = len(recorder.vehicles.frame)  # one block of rows per recorded frame (the ego is always in it)
    recorded = SimulationConfig.model_validate({**sim.model_dump(), "duration_s": max(frames, 1) * sim.step_length_s})
    run_config = config.model_copy(update={"simulation": recorded})
    with atomic_output_dir(out) as tmp:
        for path in sorted(net_file.parent.iterdir()):
            if path.is_file():
                shutil.copyfile(path, tmp / path.name)
        shutil.copyfile(demand.routes_file, tmp / demand.routes_file.name)
        write_sumocfg(tmp, net_file.name, demand.routes_file.name, recorded, seed)
        stats = write_run(tmp, run_config, seed, tmp / net_file.name, demand, recorder.vehicles, recorder.persons,
                          recorder.tls_rows, recorder.stats(), ego_id)
        stats["episode_end"] = end
        write_json(tmp / "stats.json", stats)
        meta_config = {**run_config.model_dump(mode="json"),
                       "env": {"options": asdict(options), "episode_end": end}}
        write_meta(tmp, stage="simulate", config=meta_config, seed=seed)
    return stats
