"""dvc.yaml: every stage's deps cover the project code its command runs, so `dvc repro` reruns a stage when
that code changes. The code a stage runs is found by reading the import statements (also those inside
functions, which load heavy modules lazily) of its module, transitively."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import yaml

from pipeline.stages.cli import STAGE_MODULES
from tests.conftest import REPO

PROJECT_PACKAGES = ("pipeline", "exporters", "evaluation")


def _module_file(name: str) -> Path | None:
    base = REPO.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _imported_names(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)  # submodules imported by name
    return {n for n in names if n.split(".")[0] in PROJECT_PACKAGES}


def code_of(module: str) -> set[Path]:
    """The project files ``module`` runs: itself, what it imports (anywhere in it) and their parent packages."""
    seen: set[Path] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        parts = name.split(".")
        for k in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__, a/b/__init__ and a/b/c
            path = _module_file(".".join(parts[:k]))
            if path is not None and path not in seen:
                seen.add(path)
                todo.extend(_imported_names(path))
    return seen


def _covered(path: Path, deps: list[str]) -> bool:
    rel = path.relative_to(REPO)
    return any(rel == Path(d) or Path(d) in rel.parents for d in deps)


STAGES = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]


def test_the_import_reader_finds_lazy_imports():
    code = {p.relative_to(REPO).as_posix() for p in code_of("pipeline.stages.render")}
    # render imports the static world inside a function; the static world reads roads through pipeline.traffic
    assert {"pipeline/world/static.py", "pipeline/traffic/roadgeometry.py", "pipeline/stages/common.py"} <= code
    assert not any(p.startswith(("pipeline/detect", "exporters", "evaluation")) for p in code)


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_stage_deps_cover_the_code_it_runs(stage):
    spec = STAGES[stage].get("do", STAGES[stage])  # a foreach stage keeps its definition under "do"
    program, command = spec["cmd"].split()[:2]
    assert program == "roadsynth"
    deps = [d for d in spec["deps"] if d.split("/")[0] in PROJECT_PACKAGES]
    missing = sorted(p.relative_to(REPO).as_posix() for p in code_of(STAGE_MODULES[command])
                     if p.read_text().strip() and not _covered(p, deps))
    assert not missing, f"dvc.yaml stage {stage}: deps miss {missing}"
