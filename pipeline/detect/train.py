"""Training loop: seeded sampling and augmentation, AdamW with warm-up and cosine decay, loss history.

Reproducibility: :func:`seed_everything` seeds torch, fixes the CPU thread count (``train.threads``:
float reductions are split by thread, so another count gives other bits) and turns on
``torch.use_deterministic_algorithms``. Sampling and augmentation draw from numpy generators keyed by
(seed, epoch) and (seed, step, sample); data is prepared in the main process (no loader workers). The
same config, data and seed therefore give bit-identical weights on the CPU. CUDA runs are seeded too
but not bit-reproducible (cuDNN convolution backward is not).
"""

from __future__ import annotations

import logging
import math
import os
import random
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from tqdm import tqdm

from pipeline.core.config import DetectorConfig
from pipeline.detect.data import CocoData, Letterbox, augment, read_rgb
from pipeline.detect.infer import CHECKPOINT_FORMAT
from pipeline.detect.losses import build_targets, collate_targets, detection_loss
from pipeline.detect.model import STRIDE, CenterNet

log = logging.getLogger(__name__)
LOSS_COLUMNS = ("step", "loss", "heatmap", "size", "offset", "lr")


def seed_everything(seed: int, threads: int, device: torch.device) -> None:
    random.seed(seed)
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    if device.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    # CUDA lacks deterministic kernels for some backward passes: warn there instead of failing.
    torch.use_deterministic_algorithms(True, warn_only=device.type == "cuda")


class TrainImages:
    """Training samples: seeded augmentation of (optionally cached, pre-shrunk) images plus targets."""

    def __init__(self, data: CocoData, config: DetectorConfig, seed: int):
        if not data.images:
            raise ValueError(f"{data.path}: no training images (condition filter: {config.train.conditions})")
        self.data, self.config, self.seed = data, config, seed
        self.cache: dict[int, tuple[np.ndarray, float]] = {}
        self._perms: dict[int, np.ndarray] = {}

    def _image(self, index: int) -> tuple[np.ndarray, float]:
        if index in self.cache:
            return self.cache[index]
        im = self.data.images[index]
        rgb = read_rgb(im.path)
        if (rgb.shape[1], rgb.shape[0]) != (im.width, im.height):
            raise ValueError(f"{im.path}: image is {rgb.shape[1]}x{rgb.shape[0]}, "
                             f"annotations say {im.width}x{im.height}")
        pre = 1.0
        if self.config.train.cache_images:
            # Keep only the resolution the largest zoom can use.
            lb = Letterbox.fit(im.width, im.height, self.config.input_size)
            pre = min(1.0, lb.scale * self.config.augment.scale[1])
            if pre < 1.0:
                rgb = cv2.resize(rgb, (round(im.width * pre), round(im.height * pre)), interpolation=cv2.INTER_AREA)
            self.cache[index] = (rgb, pre)
        return rgb, pre

    def index(self, position: int) -> int:
        n = len(self.data.images)
        epoch = position // n
        if epoch not in self._perms:
            self._perms = {epoch: np.random.default_rng([self.seed, epoch]).permutation(n)}
        return int(self._perms[epoch][position % n])

    def batch(self, step: int, batch_size: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        w, h = self.config.input_size
        images, targets = [], []
        for i in range(batch_size):
            index = self.index(step * batch_size + i)
            rgb, pre = self._image(index)
            rng = np.random.default_rng([self.seed, step, i])
            img, boxes, labels, ignore = augment(rgb, self.data.images[index], (w, h), self.config.augment, rng, pre)
            images.append(torch.from_numpy(img).permute(2, 0, 1))
            targets.append(build_targets(boxes, labels, ignore, len(self.config.classes), (h // STRIDE, w // STRIDE),
                                         self.config.train.gaussian_alpha, self.config.train.min_sigma_cells))
        return torch.stack(images), collate_targets(targets)


def lr_factor(step: int, steps: int, warmup: int) -> float:
    """Linear warm-up to 1, then cosine decay to 0.05."""
    if step < warmup:
        return (step + 1) / warmup
    t = (step - warmup) / max(1, steps - warmup)
    return 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t))


@dataclass
class TrainResult:
    model: CenterNet
    history: list[dict[str, float]]  # one row per step, keys LOSS_COLUMNS
    seconds: float
    images: int


def train(config: DetectorConfig, data: CocoData, *, seed: int, device: torch.device, steps: int | None = None,
          progress: bool = True) -> TrainResult:
    """Train a fresh :class:`CenterNet` on ``data`` (already filtered by condition)."""
    steps = config.train.steps if steps is None else steps
    seed_everything(seed, config.train.threads, device)
    model = CenterNet(len(config.classes), config.backbone).to(device).train()
    samples = TrainImages(data, config, seed)
    decay = [p for n, p in model.named_parameters() if p.ndim > 1]
    no_decay = [p for n, p in model.named_parameters() if p.ndim <= 1]
    optimizer = torch.optim.AdamW([{"params": decay, "weight_decay": config.train.weight_decay},
                                   {"params": no_decay, "weight_decay": 0.0}], lr=config.train.lr)
    warmup = min(config.train.warmup_steps, max(0, steps - 1))
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: lr_factor(s, steps, warmup))
    history: list[dict[str, float]] = []
    start = time.perf_counter()
    bar = tqdm(range(steps), desc="train", unit="step", disable=not progress)
    for step in bar:
        images, targets = samples.batch(step, config.train.batch_size)
        targets = {k: v.to(device) for k, v in targets.items()}
        losses = detection_loss(model(images.to(device)), targets)
        optimizer.zero_grad(set_to_none=True)
        losses["loss"].backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
        optimizer.step()
        row = {"step": step, **{k: float(v.detach()) for k, v in losses.items()}, "lr": scheduler.get_last_lr()[0]}
        scheduler.step()
        if not math.isfinite(row["loss"]):
            raise RuntimeError(f"training diverged at step {step}: loss {row['loss']} (lower train.lr)")
        history.append(row)
        bar.set_postfix(loss=f"{row['loss']:.3f}")
    seconds = time.perf_counter() - start
    log.info("trained %d steps in %.1f s (%.2f steps/s) on %s", steps, seconds, steps / max(seconds, 1e-9), device)
    return TrainResult(model.eval(), history, seconds, len(data.images))


def save_checkpoint(path: Path, result: TrainResult, config: DetectorConfig, data: CocoData, *,
                    seed: int, annotations_sha256: str) -> dict[str, Any]:
    """``model.pt``: weights (on the CPU), the resolved config, the class map and the data's hash."""
    ckpt = {
        "format": CHECKPOINT_FORMAT,
        "config": config.model_dump(mode="json"),
        "state_dict": {k: v.detach().cpu() for k, v in result.model.state_dict().items()},
        "class_names": list(config.classes),
        "category_ids": list(data.category_ids),
        "annotations_file": data.path.name,
        "annotations_sha256": annotations_sha256,
        "train_images": result.images,
        "seed": seed,
        "steps": len(result.history),
    }
    torch.save(ckpt, path)
    return ckpt
