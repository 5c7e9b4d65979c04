"""``roadsynth render``: one simulated run under one condition -> one canonical dataset record.

Frames are split into shards rendered by this process and a local process pool
(:func:`pipeline.core.processes.run_in_pool`). Finished
shards live in a hidden work folder next to OUT (``.OUT.partial``) keyed by the hash of everything that
determines the output, so an interrupted render resumes with the shards already done; OUT itself appears only
when the whole record is complete (renamed into place). A shard counts as done only when its done file lists
exactly the shard's frames: ``--shard-size`` is not part of the key, and a resume with another shard size gives
the same shard index other frames; a done shard whose tables do not read back whole is rendered again. A render
holds OUT's lock (:mod:`pipeline.core.outputs`), so no two renders share the work folder. Worker
processes die with the render (:func:`pipeline.core.processes.die_with_parent`); on Ctrl-C they are killed and the
shards done so far are kept for the resume. Layout of the record: pipeline/core/record.py and docs/dataset.md.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import hashlib
import json
import logging
import multiprocessing
import os
import pickle
import shutil
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.core.files import replace_path
from pipeline.core.outputs import output_lock
from pipeline.core.processes import RENDER_THRESHOLDS, frozen_heap, keep_freed_memory, pool_context, run_in_pool
from pipeline.core.record import FRAME_COLUMNS, RECORD_FILE, SCHEMA_VERSION, RecordInfo, label_columns
from pipeline.core.record_writers.camera import camera_info
from pipeline.core.record_writers.lidar import lidar_info
from pipeline.core.record_writers.radar import radar_info
from pipeline.core.scene_content import near_duplicate_rate
from pipeline.core.tables import read_ipc, read_ipc_files, read_parquet, require_finite, write_parquet
from pipeline.stages.common import (
    config_hash,
    int_at_least,
    software_versions,
    write_json,
    write_meta,
)
from pipeline.stages.executor import ExecutorSpec, add_executor_arguments, executor_from_args
from pipeline.stages.render_cluster import connected, render_shards_on_ray, warm_up
from pipeline.stages.render_frames import (
    SHARD_FORMAT,
    SIMULATED_COLUMNS,
    ShardJob,
    prepared_state,
    remembered_world,
    render_shard,
    rig_actor_meshes,
)
from pipeline.stages.rig import build_sensors
from pipeline.world.scene import embree_started
from pipeline.world.static import StaticWorld

log = logging.getLogger(__name__)

INPUT_ARGS = ("sim", "condition", "rig")
INTERRUPT_HINT = "the shards already rendered are kept; rerun the same command to resume"
HELP = "render a simulated run's cameras, LiDARs and radars under one condition, with exact ground truth"
WORKER_MODULES = ("pipeline.stages.render_frames", "pipeline.sensors.conditions")  # what a render worker imports
SIM_FILES = ("trajectories.parquet", "tls_states.parquet", "meta.json", "roads/lanes.parquet")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sim", type=Path, required=True, help="a `roadsynth simulate` output folder")
    parser.add_argument("--condition", required=True, help="condition NAME (configs/conditions/) or YAML PATH")
    parser.add_argument("--rig", default="default", help="rig NAME (configs/rigs/) or YAML PATH")
    parser.add_argument("--out", type=Path, required=True, help="record folder to write (replaced when complete)")
    parser.add_argument("--frames", type=int_at_least(1), help="render N frames evenly spaced over the run, "
                        "standing-ego repeats skipped (default: all frames but those; see select_frames)")
    parser.add_argument("--workers", type=int_at_least(1), default=os.cpu_count() or 1,
                        help="processes (default: all cores)")
    parser.add_argument("--shard-size", type=int_at_least(1), default=4,
                        help="frames per shard, the unit of resumption (the last few shards are smaller)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_arguments(parser)  # shards as Ray tasks (pipeline.stages.render_cluster)


STANDING_MIN_TRAVEL_M = 1.0  # a frame counts as new once the ego has moved this far since the last one ...
STANDING_MAX_WAIT_S = 2.0  # ... or this long has passed (traffic around a waiting ego still changes)


def select_frames(available: np.ndarray, count: int | None, ego: pd.DataFrame | None = None) -> list[int]:
    """``count`` frames evenly spaced over the recorded ones that are not standing repeats (all of them when None).

    With ``ego`` (columns frame, time_s, x_m, y_m: the ego's rows), a frame is a standing repeat when the ego has
    moved less than STANDING_MIN_TRAVEL_M since the last frame kept and less than STANDING_MAX_WAIT_S have
    passed since it (walking the frames in order from the first, which is kept): an ego waiting at a red light
    then gives one frame every 2 s instead of a run of near-identical ones. An ego faster than 10 m/s at the
    simulation's 10 Hz loses no frame, so its selection is the evenly spaced one. The frames skipped are logged.
    """
    available = np.sort(np.unique(available))
    if count is not None and count < 1:
        raise ValueError(f"--frames must be >= 1, got {count}")
    if ego is not None and len(available) > 1:
        kept = _not_standing(ego.set_index("frame").loc[available])
        if len(kept) < len(available):
            log.info("skipping %d of %d recorded frames where the ego stands (moved < %g m within %g s of the "
                     "last frame kept)", len(available) - len(kept), len(available), STANDING_MIN_TRAVEL_M,
                     STANDING_MAX_WAIT_S)
        available = kept
    if count is None or count >= len(available):
        return available.tolist()
    return available[np.round(np.linspace(0, len(available) - 1, count)).astype(int)].tolist()


def _not_standing(ego: pd.DataFrame) -> np.ndarray:
    """Frames (index of ``ego``, sorted) kept by the standing rule of :func:`select_frames`."""
    frames, t = ego.index.to_numpy(), ego["time_s"].to_numpy()
    xy = ego[["x_m", "y_m"]].to_numpy()
    keep = [0]
    for i in range(1, len(frames)):
        j = keep[-1]
        if np.hypot(*(xy[i] - xy[j])) >= STANDING_MIN_TRAVEL_M or t[i] - t[j] >= STANDING_MAX_WAIT_S - 1e-9:
            keep.append(i)
    return frames[keep]


def plan_shards(frames: list[int], shard_size: int) -> list[tuple[int, ...]]:
    """The shards of ``frames``, in order: ``shard_size`` frames each, but the last 2-3 shards' worth split into
    shrinking shards (a quarter of the frames left, rounded up), so that the workers, handed shards in order,
    finish within about a frame of each other instead of a whole shard. A function of the frames and the shard
    size only, so a resume with the same ones finds the same shards."""
    full = max(0, (len(frames) - 2 * shard_size) // shard_size)
    shards = [tuple(frames[i * shard_size: (i + 1) * shard_size]) for i in range(full)]
    start = full * shard_size
    while start < len(frames):
        size = -(-(len(frames) - start) // 4)
        shards.append(tuple(frames[start: start + size]))
        start += size
    return shards


def record_rate_hz(frames: list[int], sim_rate_hz: float) -> float:
    """The record's frame rate: frames per second of simulation time between its first and last frame,
    (n - 1) / (t_last - t_first), i.e. 1 / the mean interval between consecutive record frames (``--frames``
    may space them unevenly by one simulation frame). ``frames`` are sorted simulation frame numbers, recorded
    at ``sim_rate_hz``; a record of one frame has no interval and takes the simulation's rate."""
    if len(frames) < 2:
        return float(sim_rate_hz)
    return float(sim_rate_hz) * (len(frames) - 1) / (frames[-1] - frames[0])


def check_sim(sim_dir: Path) -> dict:
    """The meta.json of the simulate output ``sim_dir``, after checking that the files the render reads are there;
    a clear error otherwise."""
    for name in SIM_FILES:
        if not (sim_dir / name).is_file():
            raise FileNotFoundError(f"{sim_dir}: not a simulate output ({name} is missing); "
                                    "make one with `roadsynth simulate`")
    try:
        meta = json.loads((sim_dir / "meta.json").read_text())
    except (UnicodeDecodeError, ValueError) as exc:
        raise ValueError(f"{sim_dir / 'meta.json'}: not valid JSON ({exc}); make the run again with "
                         "`roadsynth simulate`") from None
    missing = [k for k in ("config_hash", "seed", "config") if not isinstance(meta, dict) or k not in meta]
    if missing:
        raise ValueError(f"{sim_dir / 'meta.json'}: not a simulate run's meta.json (no {', '.join(missing)})")
    return meta


def _job_key(sim_meta: dict, sim_dir: Path, rig: RigConfig, condition: ConditionConfig, frames: list[int]) -> str:
    digest = hashlib.sha256((sim_dir / "trajectories.parquet").read_bytes()).hexdigest()
    return config_hash({"sim": sim_meta["config_hash"], "seed": sim_meta["seed"], "trajectories": digest,
                        "rig": rig.model_dump(mode="json"), "condition": condition.model_dump(mode="json"),
                        "frames": frames, "schema": SCHEMA_VERSION, "shards": SHARD_FORMAT,
                        "roadsynth": software_versions()["roadsynth"]})


def _prepare_work(work: Path, key: str) -> None:
    manifest = work / "manifest.json"
    if work.exists() and (not manifest.is_file() or json.loads(manifest.read_text()).get("key") != key):
        log.info("discarding partial render in %s (made with other inputs)", work)
        shutil.rmtree(work)
    if not work.exists():
        (work / "record").mkdir(parents=True)
        (work / "shards").mkdir()
        write_json(manifest, {"key": key})


def _shard_done(shard_dir: Path, index: int, frames: tuple[int, ...], record_dir: Path | None = None) -> bool:
    """Whether shard ``index`` was rendered with exactly ``frames`` (its done file lists them, written last), its
    tables read back whole and, in ``record_dir``, each of its frames' images and sweeps is whole (a PNG's chunks and
    CRCs, a Parquet file's page checksums): a shard with anything damaged or missing is rendered again."""
    done = shard_dir / f"done-{index:05d}"
    if not (done.is_file() and done.read_text().split() == [str(f) for f in frames]):
        return False
    try:
        for table in (f"frames-{index:05d}.arrow", f"labels-{index:05d}.arrow"):
            read_ipc(shard_dir / table)
        if record_dir is not None:
            _check_frame_files(record_dir, frames)
    except (OSError, ValueError) as exc:
        log.warning("rendering shard %d again: %s", index, exc)
        done.unlink()
        return False
    return True


def _check_frame_files(record_dir: Path, frames: tuple[int, ...]) -> None:
    """Raise ValueError naming the file unless every folder of per-frame files in the partial record (a camera's
    image kind, a LiDAR's or radar's scans) holds a whole file for each of ``frames``."""
    import pyarrow as pa

    from pipeline.core.png import check_png
    from pipeline.core.tables import damage_message, open_parquet

    names = {f"{f:06d}" for f in frames}
    folders = {p.parent for pattern in ("*.png", "*.parquet") for p in record_dir.rglob(pattern)}
    for folder in sorted(folders):
        kinds = {p.suffix for p in folder.iterdir() if p.is_file()}
        for frame in sorted(names):
            for suffix in kinds & {".png", ".parquet"}:
                path = folder / f"{frame}{suffix}"
                if not path.is_file():
                    raise ValueError(f"{path}: missing")
                if suffix == ".png":
                    check_png(path.read_bytes(), str(path))
                else:
                    try:
                        open_parquet(path).read()
                    except (pa.ArrowException, OSError) as exc:
                        raise ValueError(damage_message(path, exc)) from None


def pickle_static_world(sim_dir: Path, seed: int, path: Path) -> StaticWorld | None:
    """Build (or load from the build cache: :func:`pipeline.world.static.load_static_world`) and pickle the static
    world to ``path`` and return it, unless the pickle is there already (None)."""
    if path.is_file():
        return None
    from pipeline.world.static import load_static_world

    world = load_static_world(sim_dir / "roads", seed=seed)
    tmp = path.with_suffix(".tmp")
    with tmp.open("wb") as fh:
        pickle.dump(world, fh, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.rename(path)
    return world


def render(sim_dir: Path, condition: ConditionConfig, rig: RigConfig, out: Path, *, frames: int | None = None,
           workers: int = 1, shard_size: int = 4, progress: bool = True,
           executor: ExecutorSpec | None = None, shard_threads: int | None = None) -> dict[str, object]:
    """Render the record; returns a summary (frames, labels, shards resumed). ``executor`` (distributed): the
    shards run as Ray tasks instead of in this process's pool (:mod:`pipeline.stages.render_cluster`).
    ``shard_threads``: the threads of each shard rendered here (None: 1 in a pool, else all cores), for a render
    that runs inside a task of a larger matrix (:mod:`pipeline.stages.matrix`)."""
    keep_freed_memory(RENDER_THRESHOLDS)  # from the start: the static world build's large temporaries too
    # One writer of OUT and its work folder; with a distributed executor, one Ray session for the whole render.
    with output_lock(out, "render"), frozen_heap(), connected(executor):
        return _render(sim_dir, condition, rig, out, frames=frames, workers=workers, shard_size=shard_size,
                       progress=progress, executor=executor, shard_threads=shard_threads)


def worker_context() -> multiprocessing.context.BaseContext:
    """The start method of the render's worker processes (:func:`pipeline.core.processes.pool_context`): fork
    from this process while it has cast no Embree scene (Embree's threads do not survive a fork; the case of a
    `roadsynth render` process, which forks its workers before it renders), else a forkserver that imports
    :data:`WORKER_MODULES`."""
    return pool_context(WORKER_MODULES, fork_safe=not embree_started())


def _render(sim_dir: Path, condition: ConditionConfig, rig: RigConfig, out: Path, *, frames: int | None,
            workers: int, shard_size: int, progress: bool,
            executor: ExecutorSpec | None = None, shard_threads: int | None = None) -> dict[str, object]:
    if shard_size < 1:
        raise ValueError(f"--shard-size must be >= 1, got {shard_size}")
    sim_meta = check_sim(sim_dir)
    rig_actor_meshes(rig)  # read the rig's mesh files now: a bad one fails before any work, and workers inherit them
    seed = int(sim_meta["seed"])
    trajectories = read_parquet(sim_dir / "trajectories.parquet")
    missing = [c for c in ("frame", "is_ego", "time_s", *SIMULATED_COLUMNS) if c not in trajectories.columns]
    if missing:
        raise ValueError(f"{sim_dir / 'trajectories.parquet'}: no column {', '.join(missing)} (an older simulate "
                         "output?); make the run again with `roadsynth simulate`")
    require_finite(trajectories, str(sim_dir / "trajectories.parquet"))  # a NaN would drop actors, write NaN boxes
    selection = select_frames(trajectories["frame"].to_numpy(), frames, trajectories[trajectories["is_ego"]])
    del trajectories
    key = _job_key(sim_meta, sim_dir, rig, condition, selection)
    work = out.with_name(f".{out.name}.partial")
    _prepare_work(work, key)
    shards = plan_shards(selection, shard_size)
    jobs = [ShardJob(i, s, sim_dir, work / "static.pkl", work / "record", work / "shards", rig, condition, seed,
                     threads=(1 if workers > 1 else 0) if shard_threads is None else shard_threads)
            for i, s in enumerate(shards) if not _shard_done(work / "shards", i, s, work / "record")]
    distributed = executor is not None and executor.distributed
    # A forkserver starts now (see there).
    context = worker_context() if workers > 1 and len(jobs) > 1 and not distributed else None
    warm_up(executor, WORKER_MODULES, len(jobs))  # Ray workers import while the static world builds
    world = pickle_static_world(sim_dir, seed, work / "static.pkl")
    resumed = len(shards) - len(jobs)
    if resumed:
        log.info("resuming: %d of %d shards already rendered", resumed, len(shards))
    initial = len(selection) - sum(len(j.frames) for j in jobs)
    progress_bar = functools.partial(tqdm, total=len(selection), initial=initial, unit="frame",
                                     desc=f"render {condition.name}", disable=not progress)
    if distributed:
        render_shards_on_ray(jobs, executor, progress_bar)
    else:
        # This process's shards set OpenCV's threads (render_shard): its own setting comes back at the end.
        with remembered_world(work / "static.pkl", world), _restored_opencv_threads(), \
                prepared_state(jobs[0]) if jobs else contextlib.nullcontext():
            run_in_pool(jobs, render_shard, workers, context, progress_bar)
    summary = _finalize(work, out, sim_dir, sim_meta, rig, condition, seed, selection, len(shards))
    summary["shards_resumed"] = resumed
    return summary


@contextlib.contextmanager
def _restored_opencv_threads() -> Iterator[None]:
    threads = cv2.getNumThreads()
    try:
        yield
    finally:
        cv2.setNumThreads(threads)


def _finalize(work: Path, out: Path, sim_dir: Path, sim_meta: dict, rig: RigConfig, condition: ConditionConfig,
              seed: int, selection: list[int], num_shards: int) -> dict[str, object]:
    record = work / "record"
    shards = work / "shards"
    frames = read_ipc_files([shards / f"frames-{i:05d}.arrow" for i in range(num_shards)])
    labels = read_ipc_files([shards / f"labels-{i:05d}.arrow" for i in range(num_shards)])
    frames = frames.sort_values("frame").reset_index(drop=True).astype(FRAME_COLUMNS)
    if frames["frame"].tolist() != selection:
        raise RuntimeError(f"{work}: the shards hold frames {frames['frame'].tolist()}, not the {len(selection)} "
                           "selected; delete the folder and render again")
    labels = labels.sort_values(["frame", "sensor", "track_id"], kind="stable").reset_index(drop=True)
    write_parquet(frames, record / "frames.parquet")
    columns = label_columns(radars=bool(rig.radars))
    write_parquet(labels[list(columns)].astype(columns), record / "labels.parquet")
    cameras, lidars = build_sensors(rig)
    info = RecordInfo(scenario=sim_meta["config"]["name"], seed=seed, condition=condition.name, rig=rig.name,
                      frame_rate_hz=record_rate_hz(selection, sim_meta["config"]["simulation"]["record_hz"]),
                      cameras=[camera_info(c) for c in cameras], lidars=[lidar_info(lidar) for lidar in lidars],
                      radars=[radar_info(radar) for radar in rig.radars])
    (record / RECORD_FILE).write_text(info.to_json())
    config = {"sim": {"config_hash": sim_meta["config_hash"], "scenario": info.scenario, "seed": seed},
              "rig": rig.model_dump(mode="json"), "condition": condition.model_dump(mode="json"),
              "frames": frames["frame"].tolist()}
    visible = labels[(labels["sensor_type"] == "camera") & labels["visible"]]
    blank = _blank_frames(record, visible, [c.name for c in rig.cameras], condition.name)
    write_meta(record, stage="render", config=config, seed=seed)
    replace_path(record, out)
    shutil.rmtree(work)
    # Per camera: the share of frames nearly repeating the one before (pipeline/core/scene_content.py).
    near_dup = {c.name: round(near_duplicate_rate(frames, labels, c.name), 4) for c in rig.cameras}
    return {"frames": len(frames), "labels": len(labels), "visible_camera_labels": len(visible),
            "near_duplicate_rate": near_dup, "blank_frames": blank}


BLACK_LUMA = 2.0  # mean 8-bit luma below this, with 99 % of pixels under BLACK_P99: a black frame
BLACK_P99 = 10
WHITE_LUMA = 253.0  # mean above this: a white (saturated) frame


def _blank_frames(record: Path, visible: pd.DataFrame, cameras: list[str], condition: str) -> dict[str, dict]:
    """Per camera, the frames whose image came out black or white although their labels say objects are visible
    (an exposure or light out of what the camera can show). A warning names them; a camera whose every frame with a
    visible object is blank is an error: the record would hold labels of objects nobody can see."""
    out = {}
    for camera in cameras:
        frames = sorted(set(visible.loc[visible["sensor"] == camera, "frame"].tolist()))
        black, white = [], []
        for frame in frames:
            path = record / "cameras" / camera / "rgb" / f"{frame:06d}.png"
            luma = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if luma is None:
                raise RuntimeError(f"{path}: the image just rendered cannot be read back")
            mean = float(luma.mean())
            if mean < BLACK_LUMA and np.percentile(luma, 99) < BLACK_P99:
                black.append(frame)
            elif mean > WHITE_LUMA:
                white.append(frame)
        out[camera] = {"black": len(black), "white": len(white), "with_visible_objects": len(frames)}
        if frames and len(black) + len(white) == len(frames):
            how = f"black (mean 8-bit luma < {BLACK_LUMA:g})" if black else f"white (mean 8-bit luma > {WHITE_LUMA:g})"
            raise ValueError(f"camera {camera}: every frame with visible objects came out {how} under condition "
                             f"{condition}; its lens.exposure or its lights are out of what the camera can show")
        if black or white:
            log.warning("camera %s: %d black and %d white frames although objects are visible in them (frames %s)",
                        camera, len(black), len(white), (black + white)[:10])
    return out


def main(args: argparse.Namespace) -> int:
    condition, cpath = load_config(ConditionConfig, args.condition, "conditions")
    rig, rpath = load_config(RigConfig, args.rig, "rigs")
    log.info("rendering %s under %s (%s) with rig %s", args.sim, condition.name, cpath, rpath)
    try:
        rig_actor_meshes(rig)  # the rig's mesh files: an error names the rig file too
    except ValueError as exc:
        raise ValueError(f"{rpath}: {exc}") from exc
    summary = render(args.sim, condition, rig, args.out, frames=args.frames, workers=args.workers,
                     shard_size=args.shard_size, progress=not args.no_progress,
                     executor=executor_from_args(args, local_cpus=args.workers))
    log.info("wrote %s: %d frames, %d labels (%d visible in cameras); near-duplicate frame rate %s", args.out,
             summary["frames"], summary["labels"], summary["visible_camera_labels"], summary["near_duplicate_rate"])
    blank = {c: n for c, n in summary["blank_frames"].items() if n["black"] or n["white"]}
    if blank:
        log.warning("frames that came out black or white while objects are visible in them: %s", blank)
    return 0
