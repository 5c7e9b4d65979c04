"""Label-row columns that every sensor kind shares: which frame, sensor and actor a row is about, and the actor's
world box (docs/dataset.md, labels.parquet).

A frame's actors come as columns (``cols``: the simulated run's trajectory columns of one frame's non-ego actors,
in table order, as numpy arrays); ``index`` picks the rows a sensor labels.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D

BOX_KEYS = ("x1", "y1", "x2", "y2")
_COCO_ID = {c.value: c.coco_id for c in ObjectClass}


def actor_boxes(cols: dict[str, np.ndarray]) -> Boxes3D:
    """The actors' world boxes (centre, size, yaw) from their trajectory columns."""
    return Boxes3D(np.column_stack([cols["x_m"], cols["y_m"], cols["z_m"]]),
                   np.column_stack([cols["length_m"], cols["width_m"], cols["height_m"]]), cols["yaw_rad"])


def identity_columns(frame: int, sensor: str, sensor_type: str, cols: dict[str, np.ndarray],
                     index: np.ndarray) -> dict[str, np.ndarray]:
    """Label columns naming the rows ``index`` of one frame's actors: frame, sensor, track, class, body (model and
    person), world box."""
    n = len(index)
    cls = cols["cls"][index]
    out = {"frame": np.full(n, frame), "sensor": np.full(n, sensor, object),
           "sensor_type": np.full(n, sensor_type, object), "track_id": cols["track_id"][index], "cls": cls,
           "category_id": np.array([_COCO_ID[c] for c in cls], np.int64), "model": cols["model"][index],
           "person": cols["person"][index]}
    out.update({k: cols[k][index] for k in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")})
    return out


def matrix_rows(matrix: np.ndarray) -> list[list[float]]:
    """A matrix as record.json writes it: rows of floats rounded to 12 decimals."""
    return [[round(float(v), 12) for v in row] for row in matrix]
