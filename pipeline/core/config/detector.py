"""The baseline detector's configuration: model size, input resolution, augmentation, training, inference.

``configs/detector/NAME.yaml`` deserialises into :class:`DetectorConfig`; the checkpoint stores the
resolved model so that inference rebuilds exactly the network that was trained. Sizes are in pixels
of the network input (``input_size`` = width, height) unless a name says otherwise.
"""

from __future__ import annotations

from pydantic import Field, field_validator, model_validator

from pipeline.core.config.base import ConfigModel

# COCO category names the detector can learn (pipeline.core.classes.COCO_CATEGORIES).
DETECTOR_CLASSES = ("person", "bicycle", "car", "motorcycle", "bus", "truck")


class _Frozen(ConfigModel):
    pass


class BackboneConfig(_Frozen):
    """Channels of the stride-2 stages (strides 2, 4, 8, 16, 32) and of the stride-4 head."""

    widths: tuple[int, ...] = Field((16, 32, 64, 96, 128), min_length=5, max_length=5)
    neck_channels: int = Field(48, ge=8, le=512, description="top-down (FPN) channels at strides 8-32")
    head_channels: int = Field(32, ge=8, le=512, description="channels of the stride-4 output features")

    @field_validator("widths")
    @classmethod
    def _positive(cls, widths: tuple[int, ...]) -> tuple[int, ...]:
        if any(w < 4 or w > 1024 for w in widths):
            raise ValueError("every width must lie in [4, 1024]")
        return widths


class AugmentConfig(_Frozen):
    """Training-time augmentation; every draw comes from the run seed."""

    hflip: float = Field(0.5, ge=0.0, le=1.0, description="probability of a horizontal flip")
    scale: tuple[float, float] = Field((0.8, 2.0), description="zoom range (random crop around the zoom)")
    brightness: float = Field(0.3, ge=0.0, le=1.0, description="gain drawn from 1 +- brightness")
    contrast: float = Field(0.3, ge=0.0, le=1.0)
    saturation: float = Field(0.3, ge=0.0, le=1.0)
    dark: float = Field(0.3, ge=0.0, le=1.0, description="probability of a night-like darkening (gamma + gain)")
    min_box_px: float = Field(2.0, ge=0.0, description="boxes smaller than this after the crop are dropped")

    @field_validator("scale")
    @classmethod
    def _scale(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not 0.1 <= value[0] <= value[1] <= 10.0:
            raise ValueError("scale must be (low, high) with 0.1 <= low <= high <= 10")
        return value


class TrainConfig(_Frozen):
    steps: int = Field(1000, ge=1)
    batch_size: int = Field(4, ge=1)
    lr: float = Field(6e-3, gt=0.0, le=1.0)
    weight_decay: float = Field(1e-4, ge=0.0)
    warmup_steps: int = Field(30, ge=0)
    threads: int = Field(2, ge=1, description="torch CPU threads; fixed so that CPU results are reproducible")
    conditions: tuple[str, ...] | None = Field(
        ("morning", "noon"), description="train only on images with these conditions (None: all)")
    cache_images: bool = Field(True, description="keep decoded, resized training images in memory")
    gaussian_alpha: float = Field(2.0, gt=0.0, le=10.0, description="heatmap sigma = alpha * box size / 6")
    min_sigma_cells: float = Field(1.0, gt=0.0, le=10.0, description="smallest heatmap sigma, in output cells")

    @model_validator(mode="after")
    def _warmup(self) -> TrainConfig:
        if self.warmup_steps >= self.steps and self.steps > 1:
            raise ValueError(f"warmup_steps ({self.warmup_steps}) must be below steps ({self.steps})")
        return self


class InferConfig(_Frozen):
    score_threshold: float = Field(0.05, ge=0.0, le=1.0, description="detections below are dropped")
    max_detections: int = Field(100, ge=1, le=10000, description="per image, after NMS")
    candidates: int = Field(100, ge=1, le=10000, description="heatmap peaks kept before NMS")
    nms_iou: float = Field(0.6, gt=0.0, le=1.0, description="class-wise NMS IoU (1.0: no NMS)")
    batch_size: int = Field(4, ge=1)


class DetectorConfig(_Frozen):
    """A CenterNet-style detector: class heatmaps, log box size and sub-cell offset at stride 4."""

    name: str = "default"
    description: str = ""
    classes: tuple[str, ...] = Field(DETECTOR_CLASSES, min_length=1, description="COCO names; one heatmap each")
    input_size: tuple[int, int] = Field((384, 288), description="network input width, height (multiples of 32)")
    backbone: BackboneConfig = BackboneConfig()
    augment: AugmentConfig = AugmentConfig()
    train: TrainConfig = TrainConfig()
    infer: InferConfig = InferConfig()

    @field_validator("classes")
    @classmethod
    def _classes(cls, classes: tuple[str, ...]) -> tuple[str, ...]:
        unknown = [c for c in classes if c not in DETECTOR_CLASSES]
        if unknown:
            raise ValueError(f"unknown classes {unknown}; available: {', '.join(DETECTOR_CLASSES)}")
        if len(set(classes)) != len(classes):
            raise ValueError("classes must be unique")
        return classes

    @field_validator("input_size")
    @classmethod
    def _input_size(cls, size: tuple[int, int]) -> tuple[int, int]:
        if any(s % 32 or not 64 <= s <= 4096 for s in size):
            raise ValueError("width and height must be multiples of 32 in [64, 4096]")
        return size
