"""Model class index -> COCO category id: the standard 80-class table, names files, explicit maps.

COCO-trained detectors (YOLOX, YOLOv5, YOLOv8 ...) predict 80 contiguous class indices 0..79; COCO's
category ids are 1..90 with gaps (index 0 person -> id 1, 2 car -> 3, 5 bus -> 6, 7 truck -> 8, 79
toothbrush -> 90). Results keep every one of the 80 ids: ``roadsynth evaluate`` scores the ground
truth's categories and counts the others, so nothing a detector found disappears unreported.

A **names file** gives the model's class names in index order: a text file with one name per line,
or a JSON/YAML file with ``names`` as a list or an ``{index: name}`` mapping (the ``names`` of an
Ultralytics dataset YAML). Names map to ids through COCO's 80 names (``motorbike`` and
``aeroplane``-style VOC spellings are not guessed); a name COCO lacks has no id, and its detections
are dropped and counted by :class:`pipeline.detect.onnx.OnnxDetector`.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import yaml

# (category id, name) of COCO 2017's 80 classes, in the detectors' index order.
COCO80: tuple[tuple[int, str], ...] = (
    (1, "person"), (2, "bicycle"), (3, "car"), (4, "motorcycle"), (5, "airplane"), (6, "bus"), (7, "train"),
    (8, "truck"), (9, "boat"), (10, "traffic light"), (11, "fire hydrant"), (13, "stop sign"),
    (14, "parking meter"), (15, "bench"), (16, "bird"), (17, "cat"), (18, "dog"), (19, "horse"), (20, "sheep"),
    (21, "cow"), (22, "elephant"), (23, "bear"), (24, "zebra"), (25, "giraffe"), (27, "backpack"),
    (28, "umbrella"), (31, "handbag"), (32, "tie"), (33, "suitcase"), (34, "frisbee"), (35, "skis"),
    (36, "snowboard"), (37, "sports ball"), (38, "kite"), (39, "baseball bat"), (40, "baseball glove"),
    (41, "skateboard"), (42, "surfboard"), (43, "tennis racket"), (44, "bottle"), (46, "wine glass"),
    (47, "cup"), (48, "fork"), (49, "knife"), (50, "spoon"), (51, "bowl"), (52, "banana"), (53, "apple"),
    (54, "sandwich"), (55, "orange"), (56, "broccoli"), (57, "carrot"), (58, "hot dog"), (59, "pizza"),
    (60, "donut"), (61, "cake"), (62, "chair"), (63, "couch"), (64, "potted plant"), (65, "bed"),
    (67, "dining table"), (70, "toilet"), (72, "tv"), (73, "laptop"), (74, "mouse"), (75, "remote"),
    (76, "keyboard"), (77, "cell phone"), (78, "microwave"), (79, "oven"), (80, "toaster"), (81, "sink"),
    (82, "refrigerator"), (84, "book"), (85, "clock"), (86, "vase"), (87, "scissors"), (88, "teddy bear"),
    (89, "hair drier"), (90, "toothbrush"),
)
COCO80_IDS: tuple[int, ...] = tuple(cid for cid, _ in COCO80)
COCO_ID_BY_NAME: dict[str, int] = {name: cid for cid, name in COCO80}


def coco80_map() -> dict[int, int]:
    """{model index 0..79: COCO category id}."""
    return dict(enumerate(COCO80_IDS))


def _names_list(data, path: Path) -> list[str]:
    names = data.get("names") if isinstance(data, dict) else data
    if isinstance(names, dict):
        try:
            index = {int(k): str(v) for k, v in names.items()}
        except (TypeError, ValueError):
            raise ValueError(f"{path}: field 'names' has a non-integer key (expected {{index: name}})") from None
        if sorted(index) != list(range(len(index))):
            raise ValueError(f"{path}: field 'names' keys are {sorted(index)} (expected 0..{len(index) - 1})")
        return [index[i] for i in range(len(index))]
    if isinstance(names, list) and all(isinstance(n, str) for n in names):
        return names
    raise ValueError(f"{path}: expected 'names' as a list of strings or an {{index: name}} mapping")


def read_names(path: str | Path) -> list[str]:
    """Class names in model index order from a names file (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: names file not found")
    text = path.read_text()
    if path.suffix.lower() in (".json", ".yaml", ".yml"):
        try:
            data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
        except (json.JSONDecodeError, yaml.YAMLError) as exc:
            raise ValueError(f"{path}: cannot parse names file: {exc}") from None
        names = _names_list(data, path)
    else:
        names = [line.strip() for line in text.splitlines() if line.strip()]
    if not names:
        raise ValueError(f"{path}: no class names (expected one name per line, or 'names' in JSON/YAML)")
    return names


def names_map(names: list[str]) -> tuple[dict[int, int], list[str]]:
    """{model index: COCO id} for the names COCO has, and the names it lacks."""
    keys = [n.strip().lower() for n in names]
    mapping = {i: COCO_ID_BY_NAME[k] for i, k in enumerate(keys) if k in COCO_ID_BY_NAME}
    return mapping, [n for n, k in zip(names, keys, strict=True) if k not in COCO_ID_BY_NAME]


def metadata_names(value: str) -> list[str] | None:
    """Class names from a model's ``names`` metadata (Ultralytics writes ``{0: 'person', ...}``)."""
    try:
        data = ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return None
    try:
        return _names_list({"names": data}, Path("<model metadata>"))
    except ValueError:
        return None
