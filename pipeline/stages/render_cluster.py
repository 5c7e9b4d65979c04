"""The render stage's shards as Ray tasks (``roadsynth render --executor ray``).

The render process plans the shards, builds the static world into the work folder and merges the finished
shards, as with the local pool (:mod:`pipeline.stages.render`); only :func:`render_shard` runs elsewhere, one Ray
task per shard, writing its images, point clouds, tables and done file straight into the work folder on shared
storage. A task returns the number of frames it rendered (its manifest). The done file is the shard's completion
marker: a rerun renders only the shards without one, and the merge reads only shards that have one.

A shard whose worker is killed is rendered again from the start by a fresh worker (its files are overwritten with
the same bytes: a shard is a pure function of its job); a shard that raises is named with its run, condition and
frames while the others finish, and the record is not made.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
from collections.abc import Callable, Iterator, Sequence

from tqdm import tqdm

from pipeline.stages.executor import ExecutorSpec, Task, ray_session, run_tasks
from pipeline.stages.render_frames import ShardJob, render_shard

HINT = "the shards rendered are kept; fix the cause and rerun the same command to render the rest"


def shard_label(job: ShardJob) -> str:
    """A shard for people: the run folder and seed, the condition, the shard and its frames."""
    frames = ", ".join(map(str, job.frames))
    return f"run {job.sim_dir.name} (seed {job.seed}) condition {job.condition.name} shard {job.index} " \
           f"frames [{frames}]"


def render_shards_on_ray(jobs: Sequence[ShardJob], spec: ExecutorSpec, progress: Callable[[], tqdm]) -> None:
    """Render ``jobs`` as Ray tasks of ``spec.task_cpus`` CPUs each (the shard's Embree and OpenCV threads)."""
    if not jobs:
        return
    tasks = [Task(shard_label(job), render_shard, (dataclasses.replace(job, threads=spec.task_cpus),))
             for job in jobs]
    with progress() as bar:
        run_tasks(tasks, spec, on_done=lambda _i, frames: bar.update(frames), hint=HINT, noun="shards")


@contextlib.contextmanager
def connected(spec: ExecutorSpec | None) -> Iterator[None]:
    """Connected to Ray for the block when ``spec`` is distributed (one session for the warm-up and the shards)."""
    if spec is None or not spec.distributed:
        yield
        return
    with ray_session(spec):
        yield


def warm_up(spec: ExecutorSpec | None, modules: Sequence[str], shards: int) -> None:
    """Have up to ``shards`` Ray workers import ``modules`` now, while this process builds the static world: a
    fresh worker otherwise spends seconds importing the renderer before its first shard (the local pool's workers
    fork with the imports done). Nothing waits for these tasks; nothing when local."""
    if spec is None or not spec.distributed or not shards:
        return
    import ray

    slots = int(ray.cluster_resources().get("CPU", 1) // spec.task_cpus) or 1
    remote = ray.remote(_import_modules).options(num_cpus=spec.task_cpus, name="warm up: import the renderer")
    for _ in range(min(slots, shards)):
        remote.remote(list(modules))


def _import_modules(modules: list[str]) -> None:
    for module in modules:
        importlib.import_module(module)
