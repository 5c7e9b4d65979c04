"""The ``roadsynth`` command line: a thin shell over the stage modules.

Each stage module in :data:`STAGE_MODULES` defines ``HELP`` (one line), ``add_arguments(parser)``,
``main(args) -> int`` and ``INPUT_ARGS`` (the arguments naming its input paths); ``outputs(args)`` when its
outputs are other than one folder ``--out``; ``INTERRUPT_HINT`` when an interrupted run can be resumed.
Modules are imported only when their sub-command runs (or when ``--help`` lists them), so ``roadsynth
evaluate`` never imports libsumo, open3d or torch.

Every stage's outputs follow one rule, checked here before the stage runs, and are locked while it runs
(:mod:`pipeline.core.outputs`): an output is never an input or inside one; an existing output that is not an
earlier output of the same stage is replaced only with ``--overwrite``.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import logging
import os
import re
import signal
import sys
from importlib import metadata
from pathlib import Path

from pipeline.core.outputs import OVERWRITE_FLAG, OutputSpec, claimed_outputs

STAGE_MODULES: dict[str, str] = {
    "simulate": "pipeline.stages.simulate",
    "render": "pipeline.stages.render",
    "preview": "pipeline.stages.preview",
    "evaluate": "pipeline.stages.evaluate",
    "report": "pipeline.stages.report",
    "export": "pipeline.stages.export",
    "train": "pipeline.stages.train",
    "detect": "pipeline.stages.detect",
    "experiment": "pipeline.stages.experiment",
    # The closed-loop evaluation drives the environment, the layer above the stages: loaded by name like them.
    "closedloop": "pipeline.envs.closedloop",
}


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line naming the flag (the usage is one ``--help`` away)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n(`{self.prog} --help` shows the usage)\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The CLI parser; with ``only``, just that sub-command's module is imported."""
    parser = _Parser(prog="roadsynth", description="Labelled synthetic driving data.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging (tracebacks of errors)")
    parser.add_argument("--version", action="version", version=f"roadsynth {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module_name in STAGE_MODULES.items():
        if only is not None and name != only:
            sub.add_parser(name)
            continue
        module = importlib.import_module(module_name)
        stage_parser = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(stage_parser)
        stage_parser.add_argument(OVERWRITE_FLAG, action="store_true",
                                  help="replace an existing output even when it is not an earlier output of this "
                                  "stage (never an input)")
        # Also after the sub-command; SUPPRESS keeps a -v given before it.
        stage_parser.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                                  help="debug logging (tracebacks of errors)")
        stage_parser.set_defaults(_module=module)
    return parser


def _version() -> str:
    try:
        return metadata.version("roadsynth")
    except metadata.PackageNotFoundError:
        return "(not installed)"


def _inputs(module, args: argparse.Namespace) -> list[Path]:
    """The input paths of a stage run: its ``INPUT_ARGS`` that name existing files or folders (a config NAME
    is not a path; a ``NAME=PATH`` value, as report's, names PATH)."""
    found = []
    for name in module.INPUT_ARGS:
        value = getattr(args, name, None)
        for item in value if isinstance(value, list) else [value]:
            if item is None:
                continue
            if not Path(item).exists() and "=" in str(item):
                item = str(item).partition("=")[2]
            if Path(item).exists():
                found.append(Path(item))
    return found


def _outputs(module, args: argparse.Namespace) -> list[OutputSpec]:
    return module.outputs(args) if hasattr(module, "outputs") else [OutputSpec(args.out)]


class Terminated(KeyboardInterrupt):
    """SIGTERM (``timeout``, ``docker stop``, a scheduler): handled like Ctrl-C, so that every clean-up that runs
    for Ctrl-C (temporaries removed, worker processes stopped, locks released) runs for it too."""


def _terminate(signum, frame) -> None:
    raise Terminated


def _stopped(exc: KeyboardInterrupt) -> tuple[str, int]:
    """How a run stopped by a signal ends: the word and the exit status (128 + the signal, as a shell reports)."""
    return ("terminated", 128 + signal.SIGTERM) if isinstance(exc, Terminated) else ("interrupted", 130)


_TEMPORARY = re.compile(r"(^|/)\.([^/]+)\.(?:tmp|old)-\d+(?=/|'|$| )")


def _for_people(exc: BaseException) -> str:
    """The error's message with our temporaries (``.NAME.tmp-PID``, where a stage writes ``NAME`` before it renames
    it into place) shown as the output the user named; a full or read-only disk says that nothing was written."""
    text = _TEMPORARY.sub(r"\1\2", str(exc))
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS):
        text += " (the output was not written: nothing half-written is left; free space or choose another --out)"
    return text


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    if command is None and "--version" in argv:  # without importing every stage to list them
        print(f"roadsynth {_version()}")
        return 0
    previous = signal.signal(signal.SIGTERM, _terminate) if _main_thread() else None
    try:
        return _main(argv, command)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _main(argv: list[str], command: str | None) -> int:
    try:  # importing a stage's modules takes seconds: Ctrl-C may come now
        args = build_parser(command if command in STAGE_MODULES else None).parse_args(argv)
    except KeyboardInterrupt as exc:
        word, status = _stopped(exc)
        print(f"roadsynth {command or ''}: {word}; nothing was written", file=sys.stderr)
        return status
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s"
    )
    module = args._module
    try:
        with claimed_outputs(_outputs(module, args), stage=args.command, inputs=_inputs(module, args),
                             overwrite=args.overwrite):
            return int(module.main(args) or 0)
    except KeyboardInterrupt as exc:
        hint = getattr(module, "INTERRUPT_HINT", "the output is as it was")
        word, status = _stopped(exc)
        print(f"roadsynth {args.command}: {word}; {hint}", file=sys.stderr)
        return status
    except (ValueError, OSError, RuntimeError) as exc:
        # Input and run errors: the message names the file, the field and what was expected;
        # -v shows the traceback.
        logging.getLogger("roadsynth").debug("traceback", exc_info=True)
        print(f"roadsynth {args.command}: error: {_for_people(exc)}", file=sys.stderr)
        return 2


def run() -> None:
    """The ``roadsynth`` program: :func:`main` on the command line's arguments, then exit with its status.

    A connection to a Ray cluster that was given up on (``--ray-timeout``) leaves a thread inside Ray's native
    code; the interpreter's shutdown can crash in it (SIGABRT instead of the error's status 2) and it prints its own
    retries after the error. Such a process ends at once, its streams and logs flushed: every output was already
    closed or removed by then (the stage's claim on them ended with :func:`main`).
    """
    status = main()
    executor = sys.modules.get("pipeline.stages.executor")  # imported only by stages that can use Ray
    if executor is not None and executor.connection_abandoned():
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    sys.exit(status)


if __name__ == "__main__":
    run()
