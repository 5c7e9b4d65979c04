"""A tiny generated COCO dataset (coloured boxes on a noisy grey road) and a tiny detector config."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

WIDTH, HEIGHT = 200, 150
CAR, TRUCK = 3, 8
# Small enough to train in about a second: 128x96 input, narrow layers.
TINY_CONFIG = {
    "name": "tiny",
    "classes": ["car", "truck"],
    "input_size": [128, 96],
    "backbone": {"widths": [8, 8, 16, 16, 16], "neck_channels": 16, "head_channels": 16},
    "augment": {"scale": [0.9, 1.1], "dark": 0.0},
    "train": {"steps": 40, "batch_size": 4, "lr": 0.01, "warmup_steps": 5, "threads": 2,
              "conditions": ["morning"]},
    "infer": {"score_threshold": 0.01, "max_detections": 20, "candidates": 50, "nms_iou": 0.6},
}


def make_coco(root: Path, n_images: int = 8, seed: int = 0) -> Path:
    """``root/annotations.json`` + ``root/images/``: per image 1-3 filled rectangles (red car 3, blue
    truck 8) and a crowd region; even images are ``morning``, odd ``night`` (darker)."""
    rng = np.random.default_rng(seed)
    (root / "images").mkdir(parents=True)
    images, annotations = [], []
    for i in range(1, n_images + 1):
        night = i % 2 == 0
        img = (rng.normal(110, 10, (HEIGHT, WIDTH, 3))).clip(0, 255).astype(np.uint8)
        for _ in range(rng.integers(1, 4)):
            cat = int(rng.choice([CAR, TRUCK]))
            w, h = (int(rng.integers(20, 40)), int(rng.integers(14, 26))) if cat == CAR else (50, 40)
            x, y = int(rng.integers(0, WIDTH - w)), int(rng.integers(0, HEIGHT - h))
            colour = (40, 40, 220) if cat == CAR else (220, 60, 30)  # BGR
            cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), colour, thickness=-1)
            annotations.append({"id": len(annotations) + 1, "image_id": i, "category_id": cat, "iscrowd": 0,
                                "bbox": [float(x), float(y), float(w), float(h)], "area": float(w * h)})
        annotations.append({"id": len(annotations) + 1, "image_id": i, "category_id": CAR, "iscrowd": 1,
                            "bbox": [0.0, 0.0, 6.0, 5.0], "area": 30.0})
        if night:
            img = (img * 0.4).astype(np.uint8)
        name = f"img_{i:03d}.png"
        cv2.imwrite(str(root / "images" / name), img)
        images.append({"id": i, "file_name": name, "width": WIDTH, "height": HEIGHT,
                       "condition": "night" if night else "morning", "scenario": "toy", "seed": seed})
    categories = [{"id": CAR, "name": "car", "supercategory": "vehicle"},
                  {"id": TRUCK, "name": "truck", "supercategory": "vehicle"},
                  {"id": 1, "name": "person", "supercategory": "person"}]
    path = root / "annotations.json"
    path.write_text(json.dumps({"images": images, "annotations": annotations, "categories": categories}))
    return path


@pytest.fixture(scope="session")
def tiny_coco(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("coco")
    make_coco(root)
    return root


@pytest.fixture(scope="session")
def tiny_config_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cfg") / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY_CONFIG))
    return path
