"""Resolving a scenario NAME or PATH with command-line style overrides (shared by ``simulate`` and the envs)."""

from __future__ import annotations

from pathlib import Path

from pipeline.core.config.loading import load_config, parse_config
from pipeline.core.config.scenario import ScenarioConfig


def resolve_scenario(name_or_path: str | Path, *, vehicles: int | None = None, duration_s: float | None = None,
                     warmup_s: float | None = None) -> tuple[ScenarioConfig, Path]:
    """Load a scenario and apply command-line overrides (validated like the file itself)."""
    config, path = load_config(ScenarioConfig, name_or_path, "scenarios")
    data = config.model_dump(mode="json")
    if vehicles is not None:
        data["demand"]["vehicles"] = vehicles
    if duration_s is not None:
        data["simulation"]["duration_s"] = duration_s
    if warmup_s is not None:
        data["simulation"]["warmup_s"] = warmup_s
    if config.network.osm_file is not None and not Path(config.network.osm_file).is_absolute():
        # A relative osm_file is relative to the scenario file.
        data["network"]["osm_file"] = str((path.parent / config.network.osm_file).resolve())
    return parse_config(ScenarioConfig, data, f"{path} (with command-line overrides)"), path
