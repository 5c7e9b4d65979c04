"""bench/ uses the project's public names only: no ``from pipeline... import _private`` (private names may change
without notice; a bench needing one means the module lacks a public entry point)."""

from __future__ import annotations

import ast

from tests.conftest import REPO

PROJECT_PACKAGES = ("pipeline", "exporters", "evaluation")


def test_benches_import_no_private_project_names():
    private = []
    for path in sorted((REPO / "bench").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in PROJECT_PACKAGES:
                private += [f"{path.name}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert not private, private
