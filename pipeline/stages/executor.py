"""Where a stage's independent tasks run: here (``local``, the default) or on a Ray cluster (``ray``).

A task is a picklable function and its arguments, a pure function of them to files on shared storage, with a
label that names it for people (run, condition, frames). :func:`run_tasks` runs a list of them on Ray and returns
their small results (manifests: counts, summaries), never their data: workers write their outputs themselves,
atomically, to the same paths the local executor writes (a shared file system, NFS, mounted at the same path on
every node). Byte-identical outputs follow from the tasks being pure; the executor adds no randomness.

Faults, Ray's way (docs/cluster.md): a task whose worker process dies (killed, out of memory, node lost) is
retried up to :data:`MAX_RETRIES` times on a fresh process; an exception raised by a task is not retried (it would
fail again) but recorded against its label while the other tasks go on; once all have finished,
:class:`TaskFailures` names every failed task and its error. Ray is imported only here and only when ``ray`` is
chosen: ``pip install 'roadsynth[ray]'``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.stages.common import int_at_least

log = logging.getLogger(__name__)

EXECUTORS = ("local", "ray")
RAY_TIMEOUT_S = 30.0  # default bound on connecting to a cluster (--ray-timeout)
PROBE_TIMEOUT_S = 3.0  # a TCP connection to the head's port: nothing listening fails at once, a dead host by this
MAX_RETRIES = 3  # Ray's default for a task whose worker died; said explicitly, it is part of our contract
WAIT_S = 0.2  # how long the driver waits for finished tasks before it looks again (progress updates)


@dataclass(frozen=True)
class ExecutorSpec:
    """How to run a stage's tasks.

    Attributes:
        kind: ``local`` (this machine's process pool) or ``ray``.
        address: the Ray cluster (``HOST:PORT``, ``ray://HOST:PORT`` or ``auto``); None starts a local Ray
            instance unless ``RAY_ADDRESS`` names one (Ray reads it).
        task_cpus: CPUs Ray reserves for each task, and the threads a task may use.
        local_cpus: CPUs of the local Ray instance started when there is no address (None: all cores).
        timeout_s: how long connecting to a cluster may take before it fails with advice (``--ray-timeout``).
    """

    kind: str = "local"
    address: str | None = None
    task_cpus: int = 1
    local_cpus: int | None = None
    timeout_s: float = RAY_TIMEOUT_S

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise ValueError(f"--executor: expected one of {', '.join(EXECUTORS)}, got {self.kind!r}")
        if self.task_cpus < 1:
            raise ValueError(f"--task-cpus: expected an integer >= 1, got {self.task_cpus}")
        if not (isinstance(self.timeout_s, (int, float)) and 0 < self.timeout_s <= 3600):
            raise ValueError(f"--ray-timeout: expected seconds in (0, 3600], got {self.timeout_s!r}")
        if self.address is not None:
            head_host_port(self.address)  # a malformed address fails here, before anything runs

    @property
    def distributed(self) -> bool:
        return self.kind == "ray"


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """``--executor``, ``--ray-address`` and ``--task-cpus``."""
    parser.add_argument("--executor", choices=EXECUTORS, default="local",
                        help="where tasks run: this machine's processes (default) or a Ray cluster")
    parser.add_argument("--ray-address", metavar="HOST:PORT", default=None,
                        help="the Ray cluster to use with --executor ray (default: $RAY_ADDRESS, else a local "
                        "Ray instance of --workers CPUs)")
    parser.add_argument("--task-cpus", type=int_at_least(1), default=1, metavar="N",
                        help="with --executor ray: CPUs reserved for each task, and its threads (default: 1)")
    parser.add_argument("--ray-timeout", type=float, default=None, metavar="S",
                        help=f"with --executor ray: seconds connecting to the cluster may take before it fails "
                        f"(default: {RAY_TIMEOUT_S:g})")


def executor_from_args(args: argparse.Namespace, local_cpus: int | None = None) -> ExecutorSpec:
    timeout = getattr(args, "ray_timeout", None)
    if args.executor == "local" and (args.ray_address is not None or args.task_cpus != 1 or timeout is not None):
        raise ValueError("--ray-address, --task-cpus and --ray-timeout apply to --executor ray only")
    return ExecutorSpec(args.executor, args.ray_address, args.task_cpus, local_cpus,
                        RAY_TIMEOUT_S if timeout is None else timeout)


def head_host_port(address: str) -> tuple[str, int] | None:
    """(host, port) of a cluster address ``HOST:PORT`` or ``ray://HOST:PORT``; None for ``auto`` (Ray finds the
    cluster this machine runs). Anything else is a ValueError naming --ray-address and the expected form."""
    if address == "auto":
        return None
    rest = address[len("ray://"):] if address.startswith("ray://") else address
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536 or "/" in rest:
        raise ValueError(f"--ray-address {address!r}: expected HOST:PORT (the head's GCS port, 6379 by default, as "
                         "`ray start --head` prints), ray://HOST:PORT, or auto")
    return host.strip("[]"), int(port)


def _advice(address: str) -> str:
    return (f"check that a head runs there (`ray status --address {address}`; `ray start --head` starts one); if "
            "the cluster uses token authentication, this process needs it too (RAY_AUTH_MODE=token and the token, "
            "RAY_AUTH_TOKEN or RAY_AUTH_TOKEN_PATH, as on the head); docs/cluster.md")


def _probe(address: str, timeout_s: float) -> None:
    """Fail at once, with advice, when nothing accepts connections at the head's port."""
    import socket

    target = head_host_port(address)
    if target is None:
        return
    try:
        with socket.create_connection(target, timeout=min(timeout_s, PROBE_TIMEOUT_S)):
            pass
    except OSError as exc:
        why = "nothing listens there" if isinstance(exc, ConnectionRefusedError) else f"{exc.strerror or exc}"
        raise RuntimeError(f"--ray-address {address}: cannot reach the Ray head ({why}); {_advice(address)}") \
            from None


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(*args)`` on some worker; ``label`` names it in progress and errors.

    ``after`` lists indices of earlier tasks (in the same :func:`run_tasks` call) that must finish first: their
    results are not passed on, but a failure of one fails this task too, naming it.
    """

    label: str
    fn: Callable[..., Any]
    args: tuple
    after: tuple[int, ...] = ()
    fresh_process: bool = False  # one task per worker process (libsumo: one simulation per process)


class TaskFailures(RuntimeError):
    """Some tasks failed; ``failures`` maps each failed task's label to its error (the others finished)."""

    def __init__(self, failures: dict[str, str], total: int, hint: str, noun: str = "tasks") -> None:
        self.failures = failures
        lines = "\n".join(f"  {label}: {error}" for label, error in failures.items())
        super().__init__(f"{len(failures)} of {total} {noun} failed (the others finished; {hint}):\n{lines}")


@contextlib.contextmanager
def ray_session(spec: ExecutorSpec) -> Iterator[Any]:
    """Ray connected to ``spec.address`` (or a local instance) for the block; yields the ``ray`` module.

    A Ray already initialised in this process (a test's cluster, a notebook) is used as it is and left running.
    """
    try:
        import ray
    except ImportError:
        raise RuntimeError("--executor ray needs Ray: pip install 'roadsynth[ray]'") from None
    if ray.is_initialized():
        yield ray
        return
    address = spec.address or os.environ.get("RAY_ADDRESS") or None
    kwargs: dict[str, Any] = {"address": address, "log_to_driver": False, "configure_logging": False}
    if address is None:  # "local": a new instance, never whatever cluster this machine runs already
        kwargs.update(address="local", num_cpus=spec.local_cpus, include_dashboard=False)
    else:
        _probe(address, spec.timeout_s)
    log.info("connecting to Ray at %s", address or "a new local instance")
    try:
        _init_within(ray, kwargs, spec.timeout_s if address is not None else None)
    except (ConnectionError, RuntimeError, TimeoutError) as exc:
        if address is None:
            raise
        raise RuntimeError(f"--ray-address {address}: could not connect to the Ray cluster ({exc}); "
                           f"{_advice(address)}") from None
    try:
        yield ray
    finally:
        ray.shutdown()


_ABANDONED: list[threading.Thread] = []  # connections given up on (--ray-timeout), still inside Ray


def connection_abandoned() -> bool:
    """Whether this process gave up on connecting to a cluster while Ray's code still tries (``--ray-timeout``).

    That thread runs in Ray's native code, which the interpreter's shutdown may crash in (``std::bad_alloc``,
    SIGABRT, seen once in CI) after the error was printed; it also prints its own retries after it. The
    command line then ends the process without that shutdown (:func:`pipeline.stages.cli.run`).
    """
    return any(thread.is_alive() for thread in _ABANDONED)


def _init_within(ray, kwargs: dict[str, Any], timeout_s: float | None) -> None:
    """``ray.init(**kwargs)``, waited for at most ``timeout_s`` (None: as long as it takes).

    Connecting to a cluster runs in a helper thread: Ray retries a cluster that does not answer for minutes in its
    own code, out of reach of a Python timeout; a thread can be given up on (the process exits soon after, with the
    error). A new local instance (``timeout_s`` None) starts in this thread instead: Ray ties its head's processes
    to the life of the thread that starts them (a parent-death signal), so those started from a helper thread die
    with it, a second after. Either way this process keeps its SIGTERM handling (the CLI's, like Ctrl-C), which
    ``ray.init`` replaces when it runs in the main thread.
    """
    if timeout_s is None:
        main = threading.current_thread() is threading.main_thread()
        handler = signal.getsignal(signal.SIGTERM) if main else None
        try:
            ray.init(**kwargs)
        finally:
            if handler is not None:
                signal.signal(signal.SIGTERM, handler)
        return
    outcome: dict[str, BaseException] = {}

    def connect() -> None:
        quiet = logging.getLogger("ray._private.worker")  # its note that it set no SIGTERM handler from a thread
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:
            ray.init(**kwargs)
        except BaseException as exc:  # handed to the waiting thread
            outcome["error"] = exc
        finally:
            quiet.setLevel(level)

    thread = threading.Thread(target=connect, name="ray-connect", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        _ABANDONED.append(thread)
        raise TimeoutError(f"no answer within {timeout_s:g} s (--ray-timeout)")
    if "error" in outcome:
        raise outcome["error"]


def _in_worker(argv: list[str], fn: Callable[..., Any], *args: Any) -> Any:
    """Run ``fn(*args)`` in a Ray worker as the driver's command would: its command line (meta.json records it)."""
    sys.argv = list(argv)
    return fn(*args)


def run_tasks(tasks: Sequence[Task], spec: ExecutorSpec, *, on_done: Callable[[int, Any], None] | None = None,
              on_failed: Callable[[int, str], None] | None = None,
              hint: str = "rerun the same command to resume", noun: str = "tasks") -> list[Any]:
    """Run ``tasks`` (in order here, or on Ray); returns their results in order. ``on_done(i, result)`` /
    ``on_failed(i, error)`` are called in this process as each task ends (progress, per-run status). Raises
    :class:`TaskFailures` naming every failed task once all have ended; a Ctrl-C cancels the tasks not finished
    (on Ray, their workers are killed)."""
    if not spec.distributed:
        return _run_here(tasks, on_done, on_failed, hint, noun)
    with ray_session(spec) as ray:
        from ray.exceptions import RayError, RayTaskError

        remote = {False: ray.remote(_in_worker), True: ray.remote(max_calls=1)(_in_worker)}
        refs: list[Any] = []
        for task in tasks:
            deps = [refs[i] for i in task.after]
            options = {"num_cpus": spec.task_cpus, "max_retries": MAX_RETRIES, "retry_exceptions": False,
                       "name": task.label}
            # Dependencies travel as extra arguments: Ray starts the task once they are done (their values, small
            # manifests, are dropped by _after).
            function = remote[task.fresh_process].options(**options)
            refs.append(function.remote(sys.argv, _after, task.fn, len(deps), *deps, *task.args))
        index = {ref: i for i, ref in enumerate(refs)}
        results: list[Any] = [None] * len(tasks)
        failures: dict[str, str] = {}
        pending = list(refs)
        try:
            while pending:
                # All that are ready within the timeout, in submission order (a task after those it waits for):
                # one pass over the pending list per batch, not per task, for matrices of thousands of tasks.
                done, pending = ray.wait(pending, num_returns=len(pending), timeout=WAIT_S)
                for ref in done:
                    i = index[ref]
                    try:
                        results[i] = ray.get(ref)
                    except RayError as exc:
                        failed_first = [tasks[j].label for j in tasks[i].after if tasks[j].label in failures]
                        error = (f"not run: {', '.join(failed_first)} failed" if failed_first else
                                 _describe(exc, RayTaskError))
                        failures[tasks[i].label] = error
                        log.error("%s failed: %s", tasks[i].label, error)
                        if on_failed is not None:
                            on_failed(i, error)
                        continue
                    if on_done is not None:
                        on_done(i, results[i])
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
        if failures:
            raise TaskFailures(failures, len(tasks), hint, noun)
        return results


def _run_here(tasks: Sequence[Task], on_done: Callable[[int, Any], None] | None,
              on_failed: Callable[[int, str], None] | None, hint: str, noun: str) -> list[Any]:
    """The local executor: each task in this process, in order; an exception fails that task (and those waiting for
    it), the others go on."""
    results: list[Any] = [None] * len(tasks)
    failures: dict[str, str] = {}
    for i, task in enumerate(tasks):
        failed_first = [tasks[j].label for j in task.after if tasks[j].label in failures]
        if failed_first:
            failures[task.label] = f"not run: {', '.join(failed_first)} failed"
        else:
            try:
                results[i] = task.fn(*task.args)
            except Exception as exc:
                log.debug("%s failed", task.label, exc_info=True)
                failures[task.label] = f"{type(exc).__name__}: {exc}"
        if task.label in failures:
            log.error("%s failed: %s", task.label, failures[task.label])
            if on_failed is not None:
                on_failed(i, failures[task.label])
        elif on_done is not None:
            on_done(i, results[i])
    if failures:
        raise TaskFailures(failures, len(tasks), hint, noun)
    return results


def _after(fn: Callable[..., Any], num_deps: int, *args: Any) -> Any:
    """``fn`` of the arguments after the first ``num_deps`` (results of the tasks this one waited for)."""
    return fn(*args[num_deps:])


def _describe(exc: Exception, task_error: type) -> str:
    """One line: the task's own exception (type and message), or what happened to its worker."""
    if isinstance(exc, task_error):
        cause = exc.cause
        if isinstance(cause, task_error):  # a dependency failed: Ray re-raises its error here
            return f"not run: a task it waits for failed ({_describe(cause, task_error)})"
        if cause is not None:
            return f"{type(cause).__name__}: {cause}"
    first = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {first[0] if first else ''}"
