"""The nuScenes v1.0 tables of one record: names, tokens, quaternions and the annotation rows.

Conventions (the devkit's schema, nuscenes/utils/data_classes.py and nuscenes.py):

- **global** frame = our world frame (SUMO coordinates, x east, y north, z up, metres);
- ``ego_pose``: translation and rotation (quaternion **w, x, y, z**) of the ego frame in the global frame. Our ego
  frame's origin is the centre of the ego's 3D box (nuScenes': the rear axle on the ground); axes are the same
  (x forward, y left, z up);
- ``calibrated_sensor``: the sensor frame in the ego frame (our ``T_ego_sensor``). Cameras: the OpenCV optical frame,
  as nuScenes' cameras; LiDARs and radars: x forward, y left, z up (nuScenes' LIDAR_TOP is turned -90 deg about z,
  but the files are in the sensor frame either way, and the calibration says which);
- ``sample_annotation``: box centre in the global frame, ``size`` = **(width, length, height)**, rotation = the yaw
  about +z as a quaternion (w, x, y, z); the box's length runs along its rotated x axis;
- timestamps: integer microseconds of simulation time.

Tokens are the first 32 hex digits of the sha256 of the table name and the identity of the row (record stem,
frame, sensor or track), so an export's tokens never depend on the order or the moment of the export.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pandas as pd

from exporters.source import RecordSource, safe_name
from pipeline.core.classes import RIDER

VERSION = "v1.0-roadsynth"
"""The version folder (``NuScenes(version=VERSION, dataroot=OUT)``)."""
ALL_SPLIT = "all"
"""The custom split of splits.json that holds every scene of the export (evaluation's default set)."""

CATEGORY = {"car": "vehicle.car", "van": "vehicle.car", "truck": "vehicle.truck", "bus": "vehicle.bus.rigid",
            "motorcycle": "vehicle.motorcycle", "bicycle": "vehicle.bicycle", "pedestrian": "human.pedestrian.adult",
            "stroller": "human.pedestrian.stroller"}
"""Our class -> nuScenes category (nuScenes counts vans and SUVs as vehicle.car)."""
PERSON_CATEGORY = {"child": "human.pedestrian.child", "wheelchair_user": "human.pedestrian.wheelchair"}
"""A pedestrian's ``person`` -> its nuScenes category where it is not CATEGORY's (adults and teenagers:
human.pedestrian.adult). A wheelchair user is the wheelchair with its occupant, as nuScenes boxes one."""
CATEGORY_DESCRIPTION = {
    "vehicle.car": "Vehicle designed primarily for personal use, e.g. sedans, hatch-backs, wagons, vans, mini-vans, "
                   "SUVs and jeeps (roadsynth: car and van).",
    "vehicle.truck": "Vehicles primarily designed to haul cargo (roadsynth: truck).",
    "vehicle.bus.rigid": "Rigid bus (roadsynth: bus).",
    "vehicle.motorcycle": "Gasoline or electric powered 2-wheeled vehicle (roadsynth: motorcycle, always ridden).",
    "vehicle.bicycle": "Human or electric powered 2-wheeled vehicle (roadsynth: bicycle, always ridden).",
    "human.pedestrian.adult": "Adult subcategory (roadsynth: pedestrian, adults and teenagers).",
    "human.pedestrian.child": "Child subcategory (roadsynth: pedestrian, person child: 6-12 years).",
    "human.pedestrian.wheelchair": "Wheelchairs. If a person is in the wheelchair, include in the annotation "
                                   "(roadsynth: pedestrian, person wheelchair_user).",
    "human.pedestrian.stroller": "Strollers. If a person is in the stroller, include in the annotation (roadsynth: "
                                 "stroller, boxed apart from the person pushing it).",
}
ATTRIBUTE = {
    "vehicle.moving": "Vehicle is moving.",
    "vehicle.stopped": "Vehicle, with a driver/rider in/on it, is currently stationary but has an intent to move.",
    "vehicle.parked": "Vehicle is stationary (usually for longer duration) with no immediate intent to move.",
    "cycle.with_rider": "There is a rider on the bicycle or motorcycle.",
    "cycle.without_rider": "There is NO rider on the bicycle or motorcycle.",
    "pedestrian.moving": "The human is moving.",
    "pedestrian.standing": "The human is standing.",
    "pedestrian.sitting_lying_down": "The human is sitting or lying down.",
}
VISIBILITY = (("1", "v0-40", 0.0), ("2", "v40-60", 0.4), ("3", "v60-80", 0.6), ("4", "v80-100", 0.8))
"""(token, level, lower bound of the visible fraction): nuScenes' visibility table."""
MOVING_SPEED_MPS = 0.5
"""A vehicle or pedestrian faster than this (the devkit's velocity estimate, horizontal) is moving."""
MAX_TIME_DIFF_S = 1.5
"""nuScenes.box_velocity's default: the longest gap (doubled for a central difference) a velocity spans."""


def token(*parts: object) -> str:
    """32 hex digits identifying a row: sha256 of its parts."""
    return hashlib.sha256("\x1f".join(str(p) for p in parts).encode()).hexdigest()[:32]


def quat_wxyz(rotation: np.ndarray) -> list[float]:
    """(w, x, y, z) unit quaternion of a (3, 3) rotation matrix, w >= 0 (Shepperd's method, no scipy)."""
    m = np.asarray(rotation, dtype=np.float64)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q) / np.linalg.norm(q)
    return [float(v) for v in (-q if q[0] < 0 else q)]


def quat_yaw(yaw_rad: np.ndarray) -> np.ndarray:
    """(N, 4) w, x, y, z of rotations by ``yaw_rad`` (N,) about +z."""
    half = np.asarray(yaw_rad, dtype=np.float64) / 2.0
    zeros = np.zeros_like(half)
    return np.stack([np.cos(half), zeros, zeros, np.sin(half)], axis=1)


def channel(kind: str, name: str, first_lidar: bool = False) -> str:
    """nuScenes channel of a sensor: CAM_<NAME>, RADAR_<NAME>, LIDAR_<NAME>; the first LiDAR is LIDAR_TOP, the
    channel the devkit's renderer and detection evaluation look up. A leading or trailing word naming the
    modality is dropped (radar ``front_radar`` -> RADAR_FRONT)."""
    prefix = {"camera": "CAM", "lidar": "LIDAR", "radar": "RADAR"}[kind]
    if kind == "lidar" and first_lidar:
        return "LIDAR_TOP"
    words = [w for w in safe_name(name).upper().replace("-", "_").replace(".", "_").split("_") if w]
    if len(words) > 1 and words[-1] in (prefix, kind.upper()):
        words = words[:-1]
    elif len(words) > 1 and words[0] in (prefix, kind.upper()):
        words = words[1:]
    return f"{prefix}_{'_'.join(words)}"


def record_channels(src: RecordSource) -> list[tuple[str, str, str]]:
    """(kind, sensor name, channel) of every sensor of the record, cameras, LiDARs, radars in record order."""
    info = src.info
    return ([("camera", c.name, channel("camera", c.name)) for c in info.cameras]
            + [("lidar", x.name, channel("lidar", x.name, i == 0)) for i, x in enumerate(info.lidars)]
            + [("radar", r.name, channel("radar", r.name)) for r in info.radars])


def objects(src: RecordSource) -> pd.DataFrame:
    """One row per (frame, track) labelled by any sensor: world box, class and person, num_lidar_pts (sum over the
    LiDAR rows: every object owning a point has one), num_radar_pts (the same over radar rows), visible (0-1: the
    best camera's visible share of the silhouette, (1 - occlusion)(1 - truncation); 0 without a camera row). Sorted
    by (track, frame). Riders' rows are not objects: nuScenes' cycle box holds its rider, as ours does."""
    labels = src.labels
    labels = labels[labels["cls"] != RIDER]  # nuScenes boxes a rider with its cycle: the cycle's rows hold both
    keys = ["frame", "track_id"]
    boxes = labels.drop_duplicates(keys)[[*keys, "cls", "person", "x_m", "y_m", "z_m", "length_m", "width_m",
                                          "height_m", "yaw_rad"]]
    kind = labels["sensor_type"]

    def summed(mask: pd.Series, column: str) -> pd.Series:
        if column not in labels or not mask.any():
            return pd.Series(dtype="int64")
        return labels[mask].groupby(keys)[column].sum().astype("int64")

    cams = labels[kind == "camera"]
    share = ((1.0 - cams["occlusion"].astype("float64").fillna(1.0))
             * (1.0 - cams["truncation"].astype("float64").fillna(0.0))).clip(0.0, 1.0)
    visible = share.groupby([cams["frame"], cams["track_id"]]).max() if len(cams) else pd.Series(dtype="float64")
    out = boxes.set_index(keys)
    out["num_lidar_pts"] = summed(kind == "lidar", "lidar_points").reindex(out.index, fill_value=0)
    out["num_radar_pts"] = summed(kind == "radar", "radar_detections").reindex(out.index, fill_value=0)
    out["visible"] = visible.reindex(out.index).fillna(0.0)
    return out.reset_index().sort_values(["track_id", "frame"], kind="stable").reset_index(drop=True)


def categories(cls: np.ndarray, person: np.ndarray) -> np.ndarray:
    """(N,) nuScenes category of each object of classes ``cls`` and persons ``person`` (labels.parquet's columns):
    CATEGORY's, but PERSON_CATEGORY's for a child or a wheelchair user."""
    out = np.array([CATEGORY[c] for c in np.asarray(cls, object).tolist()], object)
    for who, name in PERSON_CATEGORY.items():
        out[(np.asarray(cls, object) == "pedestrian") & (np.asarray(person, object) == who)] = name
    return out


def velocities(obj: pd.DataFrame, time_us: dict[int, int]) -> np.ndarray:
    """(N, 3) velocity of each object row (:func:`objects`' order), m/s, as ``NuScenes.box_velocity`` estimates it
    from the previous and next annotation of the same track (NaN where it gives none)."""
    track = obj["track_id"].to_numpy()
    pos = obj[["x_m", "y_m", "z_m"]].to_numpy(dtype=np.float64)
    t = np.array([time_us[int(f)] for f in obj["frame"]], dtype=np.float64) * 1e-6
    n = len(obj)
    has_prev = np.zeros(n, bool)
    has_prev[1:] = track[1:] == track[:-1]
    has_next = np.zeros(n, bool)
    has_next[:-1] = track[:-1] == track[1:]
    idx = np.arange(n)
    first = np.where(has_prev, idx - 1, idx)
    last = np.where(has_next, idx + 1, idx)
    dt = t[last] - t[first]
    limit = np.where(has_prev & has_next, 2 * MAX_TIME_DIFF_S, MAX_TIME_DIFF_S)
    ok = (has_prev | has_next) & (dt <= limit) & (dt > 0)
    vel = np.full((n, 3), np.nan)
    vel[ok] = (pos[last[ok]] - pos[first[ok]]) / dt[ok, None]
    return vel


def attribute_names(category: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """(N,) nuScenes attribute of each object of nuScenes ``category`` (:func:`categories`): vehicles moving or
    stopped (we do not know parked), cycles always with a rider, pedestrians (adults and children) moving or
    standing; an object without a velocity estimate counts as not moving; a stroller and a wheelchair none ("":
    nuScenes' attributes describe vehicles, cycles and the people themselves; these categories name the object)."""
    speed = np.hypot(vel[:, 0], vel[:, 1])
    moving = np.nan_to_num(speed, nan=0.0) > MOVING_SPEED_MPS
    category = np.asarray(category, dtype=object)
    out = np.where(moving, "vehicle.moving", "vehicle.stopped").astype(object)
    out[(category == "vehicle.motorcycle") | (category == "vehicle.bicycle")] = "cycle.with_rider"
    ped = (category == "human.pedestrian.adult") | (category == "human.pedestrian.child")
    out[ped] = np.where(moving[ped], "pedestrian.moving", "pedestrian.standing")
    out[(category == "human.pedestrian.stroller") | (category == "human.pedestrian.wheelchair")] = ""
    return out


def visibility_token(visible: np.ndarray) -> np.ndarray:
    """(N,) visibility token of visible shares in [0, 1] (nuScenes' bins)."""
    bounds = np.array([b for _, _, b in VISIBILITY[1:]])
    tokens = np.array([t for t, _, _ in VISIBILITY], dtype=object)
    return tokens[np.searchsorted(bounds, np.asarray(visible, dtype=np.float64), side="right")]


def annotation_tables(stem: str, obj: pd.DataFrame, time_us: dict[int, int],
                      sample_of: dict[int, str]) -> tuple[list[dict], list[dict], np.ndarray]:
    """sample_annotation and instance rows of one record's objects (:func:`objects`), and their velocities."""
    vel = velocities(obj, time_us)
    category = categories(obj["cls"].to_numpy(), obj["person"].to_numpy())
    attrs = attribute_names(category, vel)
    vis = visibility_token(obj["visible"].to_numpy())
    quats = quat_yaw(obj["yaw_rad"].to_numpy()).tolist()
    tracks, frames = obj["track_id"].to_numpy(), obj["frame"].to_numpy()
    toks = [token("sample_annotation", stem, int(f), int(t)) for f, t in zip(frames, tracks, strict=True)]
    cols = {c: obj[c].to_numpy(dtype=np.float64).tolist() for c in ("x_m", "y_m", "z_m", "length_m", "width_m",
                                                                     "height_m")}
    lidar, radar = obj["num_lidar_pts"].tolist(), obj["num_radar_pts"].tolist()
    anns, instances = [], []
    n = len(obj)
    for i in range(n):
        same_prev = i > 0 and tracks[i - 1] == tracks[i]
        same_next = i + 1 < n and tracks[i + 1] == tracks[i]
        anns.append({
            "token": toks[i], "sample_token": sample_of[int(frames[i])],
            "instance_token": token("instance", stem, int(tracks[i])), "visibility_token": vis[i],
            "attribute_tokens": [token("attribute", attrs[i])] if attrs[i] else [],
            "translation": [cols["x_m"][i], cols["y_m"][i], cols["z_m"][i]],
            "size": [cols["width_m"][i], cols["length_m"][i], cols["height_m"][i]], "rotation": quats[i],
            "prev": toks[i - 1] if same_prev else "", "next": toks[i + 1] if same_next else "",
            "num_lidar_pts": int(lidar[i]), "num_radar_pts": int(radar[i]),
        })
        if not same_prev:
            start = i
        if not same_next:
            instances.append({
                "token": token("instance", stem, int(tracks[i])),
                "category_token": token("category", category[i]),
                "nbr_annotations": i - start + 1, "first_annotation_token": toks[start],
                "last_annotation_token": toks[i],
            })
    return anns, instances, vel


def static_tables() -> dict[str, list[dict]]:
    """category, attribute and visibility tables (the categories we map to, every attribute, every level)."""
    names = sorted({*CATEGORY.values(), *PERSON_CATEGORY.values()})
    return {
        "category": [{"token": token("category", c), "name": c, "description": CATEGORY_DESCRIPTION[c]}
                     for c in names],
        "attribute": [{"token": token("attribute", a), "name": a, "description": d} for a, d in ATTRIBUTE.items()],
        "visibility": [{"token": t, "level": level, "description": f"visibility of the annotation is {level[1:]} %"}
                       for t, level, _ in VISIBILITY],
    }
