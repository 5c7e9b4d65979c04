"""Validated configuration models. YAML under ``configs/`` only deserialises into these."""

from pipeline.core.config.actor_meshes import ActorMeshConfig
from pipeline.core.config.detector import (
    AugmentConfig,
    BackboneConfig,
    DetectorConfig,
    InferConfig,
    TrainConfig,
)
from pipeline.core.config.distributions import Constant, Distribution, LogNormal, TruncNormal, Uniform
from pipeline.core.config.experiment import ExperimentConfig
from pipeline.core.config.loading import ConfigError, config_dir, load_config, resolve_config_path
from pipeline.core.config.scenario import (
    ClassSpec,
    DemandConfig,
    DriverModel,
    EgoConfig,
    NetworkConfig,
    NetworkKind,
    ScenarioConfig,
    SimulationConfig,
)
from pipeline.core.config.sensors import CameraConfig, ConditionConfig, LidarConfig, RadarConfig, RigConfig

__all__ = [
    "ActorMeshConfig",
    "AugmentConfig",
    "BackboneConfig",
    "CameraConfig",
    "ClassSpec",
    "ConditionConfig",
    "ConfigError",
    "Constant",
    "DemandConfig",
    "DetectorConfig",
    "Distribution",
    "DriverModel",
    "EgoConfig",
    "ExperimentConfig",
    "InferConfig",
    "LidarConfig",
    "LogNormal",
    "NetworkConfig",
    "NetworkKind",
    "RadarConfig",
    "RigConfig",
    "ScenarioConfig",
    "SimulationConfig",
    "TrainConfig",
    "TruncNormal",
    "Uniform",
    "config_dir",
    "load_config",
    "resolve_config_path",
]
