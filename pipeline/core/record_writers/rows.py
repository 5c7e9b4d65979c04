"""Label-row columns that every sensor kind shares: which frame, sensor and actor a row is about, and the actor's
world box (docs/dataset.md, labels.parquet).

A frame's actors come as columns (``cols``: the simulated run's trajectory columns of one frame's non-ego actors,
in table order, as numpy arrays); ``index`` picks the rows a sensor labels.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import RIDER, RIDER_TRACK_OFFSET, ObjectClass, Person, SemanticClass
from pipeline.core.geometry import Boxes3D

BOX_KEYS = ("x1", "y1", "x2", "y2")
_COCO_ID = {**{c.value: c.coco_id for c in ObjectClass}, RIDER: ObjectClass.PEDESTRIAN.coco_id}


def rider_counts(instance_id: np.ndarray, semantic: np.ndarray, track_ids: np.ndarray) -> np.ndarray:
    """(A,) int64 per actor of the frame (track ids ``track_ids``) its rider's points or detections: those with
    ``instance_id`` its track and ``semantic`` RIDER."""
    on = np.asarray(semantic) == SemanticClass.RIDER
    order = np.argsort(track_ids, kind="stable")
    which = order[np.searchsorted(track_ids, np.asarray(instance_id)[on], sorter=order)]
    return np.bincount(which, minlength=len(track_ids)).astype(np.int64)


def as_riders(out: dict[str, np.ndarray], rider: np.ndarray, center_world: np.ndarray, size: np.ndarray) -> None:
    """Turn the label columns ``out`` of the rows ``rider`` ((N,) bool; their cycle's identity columns) into their
    riders', in place: track id + :data:`RIDER_TRACK_OFFSET`, class :data:`RIDER` (COCO's person), person adult,
    the rider's world box ((R, 3) centre and size; the cycle's yaw)."""
    if not rider.any():
        return
    tracks = out["track_id"][rider]
    if tracks.max() >= RIDER_TRACK_OFFSET:
        raise ValueError(f"track id {int(tracks.max())}: a rider takes its cycle's track id + {RIDER_TRACK_OFFSET}, "
                         "so every cycle's track id must be below it")
    out["track_id"] = np.where(rider, out["track_id"] + RIDER_TRACK_OFFSET, out["track_id"])
    for key, value in (("cls", RIDER), ("category_id", _COCO_ID[RIDER]), ("person", Person.ADULT.value)):
        out[key] = np.where(rider, value, out[key]).astype(out[key].dtype if key != "cls" else object)
    for j, key in enumerate(("x_m", "y_m", "z_m")):
        out[key] = out[key].astype(np.float64)
        out[key][rider] = center_world[:, j]
    for j, key in enumerate(("length_m", "width_m", "height_m")):
        out[key] = out[key].astype(np.float64)
        out[key][rider] = size[:, j]


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
