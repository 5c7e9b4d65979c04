"""The ``roadsynth`` command line: a thin shell over the stage modules.

Each stage module in :data:`STAGE_MODULES` defines ``HELP`` (one line), ``add_arguments(parser)``
and ``main(args) -> int``. Modules are imported only when their sub-command runs (or when ``--help``
lists them), so ``roadsynth evaluate`` never imports libsumo, open3d or torch.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

STAGE_MODULES: dict[str, str] = {
    "simulate": "pipeline.stages.simulate",
    "render": "pipeline.stages.render",
    "preview": "pipeline.stages.preview",
    "evaluate": "pipeline.stages.evaluate",
    "report": "pipeline.stages.report",
    "export": "pipeline.stages.export",
    "train": "pipeline.stages.train",
    "detect": "pipeline.stages.detect",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The CLI parser; with ``only``, just that sub-command's module is imported."""
    parser = argparse.ArgumentParser(prog="roadsynth", description="Labelled synthetic driving data.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module_name in STAGE_MODULES.items():
        if only is not None and name != only:
            sub.add_parser(name)
            continue
        module = importlib.import_module(module_name)
        stage_parser = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(stage_parser)
        stage_parser.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    command = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser(command if command in STAGE_MODULES else None).parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO, format="%(levelname)s %(name)s: %(message)s"
    )
    try:
        return int(args._module.main(args) or 0)
    except (ValueError, OSError, RuntimeError) as exc:
        # Input and run errors: the message names the file, the field and what was expected;
        # -v shows the traceback.
        logging.getLogger("roadsynth").debug("traceback", exc_info=True)
        print(f"roadsynth {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
