"""The closed-loop evaluation's config (``roadsynth closedloop``; configs/closedloop/, docs/closedloop.md)."""

from __future__ import annotations

from pydantic import Field, field_validator

from pipeline.core.config.base import ConfigModel, run_seed_problem


class ClosedLoopConfig(ConfigModel):
    """Every (scenario, seed, condition) episode is driven twice by the same agent with the same traffic: on
    ground-truth features, and on the features a detector's boxes, ranged by the LiDAR and tracked, give."""

    name: str
    description: str = ""
    scenarios: list[str] = Field(min_length=1, description="scenario NAMEs or YAML paths")
    seeds: list[int] = Field(min_length=1)
    conditions: list[str] = Field(min_length=1, description="condition NAMEs or YAML paths")
    episode_s: float = Field(30.0, gt=0.0, le=3600.0, description="episode length after the warm-up, seconds")
    vehicles: int | None = Field(None, ge=1, description="background vehicles (None: the scenario's)")
    warmup_s: float | None = Field(None, ge=0.0, description="warm-up before the ego is handed over (None: the "
                                   "scenario's)")
    rig: str = Field("default", description="the rig whose first camera and LiDAR perceive (NAME or path)")
    detector: str = Field(description="onnx:PATH (any model `roadsynth detect --onnx` runs) or baseline:DIR "
                          "(a model folder `roadsynth train` wrote); a relative PATH is relative to the config file")
    agent: str = Field("reference", description="the agent: reference (IDM + MOBIL, pipeline.envs.driver)")
    max_detections: int = Field(32, ge=1, le=1000)
    birth_score: float = Field(0.0, ge=0.0, le=1.0, description="the tracker's birth_score: only detections scoring "
                               "at least this start a track; weaker ones only continue one (0: every detection "
                               "may start one; pipeline.envs.tracker)")

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, seeds: list[int]) -> list[int]:
        if len(set(seeds)) != len(seeds):
            raise ValueError("seeds must be unique")
        for seed in seeds:
            if run_seed_problem(seed):
                raise ValueError(f"seed {seed}: {run_seed_problem(seed)}")
        return seeds

    @field_validator("detector")
    @classmethod
    def _detector(cls, value: str) -> str:
        kind, _, path = value.partition(":")
        if kind not in ("onnx", "baseline") or not path:
            raise ValueError(f"expected onnx:PATH or baseline:DIR, got {value!r}")
        return value

    @field_validator("agent")
    @classmethod
    def _agent(cls, value: str) -> str:
        if value != "reference":
            raise ValueError(f"unknown agent {value!r}; known agents: reference")
        return value
