"""The rendered record the benchmarks that take ``--record``/``--dataset`` make when given none (not a benchmark)."""

from __future__ import annotations

from pathlib import Path

from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.stages.render import render
from pipeline.stages.simulate import resolve_scenario, simulate


def rendered_record(tmp: Path, frames: int, condition: str = "noon", workers: int = 1, progress: bool = False
                    ) -> Path:
    """``frames`` frames of the default rig under ``condition``, rendered into TMP/record from a highway run
    simulated into TMP/sim (seed 1, 90 s of warm-up, a frame per 0.1 s)."""
    config, _ = resolve_scenario("highway", duration_s=frames / 10.0, warmup_s=90.0)
    simulate(config, 1, tmp / "sim", progress=progress)
    rig, _ = load_config(RigConfig, "default", "rigs")
    condition_cfg, _ = load_config(ConditionConfig, condition, "conditions")
    render(tmp / "sim", condition_cfg, rig, tmp / "record", frames=frames, workers=workers, progress=progress)
    return tmp / "record"
