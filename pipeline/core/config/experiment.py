"""An experiment: which scenarios, seeds and conditions to run, and at what size."""

from __future__ import annotations

from pydantic import Field, field_validator

from pipeline.core.config.base import ConfigModel, run_seed_problem


class ExperimentConfig(ConfigModel):
    """The cross product scenarios x seeds is simulated; each run is rendered under every condition."""

    name: str
    description: str = ""
    scenarios: list[str] = Field(min_length=1)
    seeds: list[int] = Field(min_length=1)
    conditions: list[str] = Field(min_length=1)
    rig: str = "default"
    vehicles: int = Field(200, ge=1)
    warmup_s: float = Field(60.0, ge=0.0)
    duration_s: float = Field(20.0, gt=0.0)
    frames: int | None = Field(None, ge=1, description="frames rendered per run (None: all recorded)")
    iou_thresholds: list[float] = Field([0.5, 0.6, 0.7, 0.8], min_length=1)
    score_threshold: float | None = Field(None, ge=0.0, le=1.0, description="the detector's operating threshold "
                                          "of the evaluation (None: `roadsynth evaluate`'s default)")

    @field_validator("seeds")
    @classmethod
    def _unique_seeds(cls, seeds: list[int]) -> list[int]:
        if len(set(seeds)) != len(seeds):
            raise ValueError("seeds must be unique")
        for seed in seeds:
            if run_seed_problem(seed):
                raise ValueError(f"seed {seed}: {run_seed_problem(seed)}")
        return seeds

    @field_validator("iou_thresholds")
    @classmethod
    def _check_iou(cls, values: list[float]) -> list[float]:
        if any(not 0.0 < v <= 1.0 for v in values):
            raise ValueError("IoU thresholds must lie in (0, 1]")
        return values
