"""Loading YAML configs into validated models, with errors that name the file, key and allowed values.

A config argument is either a NAME (resolved to ``configs/<kind>/NAME.yaml``) or a PATH to any YAML
file. NAMEs are looked up in ``$ROADSYNTH_CONFIGS`` if set; otherwise first in ``./configs`` when the
current folder has one (a project checkout: DVC runs every stage from the repository root), then in
the configs shipped beside the installed package.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

M = TypeVar("M", bound=BaseModel)


class ConfigError(ValueError):
    """A config file is missing, unreadable or invalid. The message names the file and the key path."""


def config_dirs() -> list[Path]:
    """Folders holding ``scenarios/``, ``rigs/``, ``conditions/``..., searched in order."""
    env = os.environ.get("ROADSYNTH_CONFIGS")
    if env:
        return [Path(env)]
    shipped = Path(__file__).resolve().parents[3] / "configs"
    local = Path.cwd() / "configs"
    return [local, shipped] if local.is_dir() and local.resolve() != shipped else [shipped]


def config_dir() -> Path:
    """The first folder searched (see :func:`config_dirs`)."""
    return config_dirs()[0]


def available_names(kind: str) -> list[str]:
    return sorted({p.stem for folder in config_dirs() for p in (folder / kind).glob("*.yaml")})


def resolve_config_path(name_or_path: str | Path, kind: str) -> Path:
    """Resolve a NAME under ``configs/<kind>/`` or return an existing PATH; fail listing the names."""
    candidate = Path(name_or_path)
    if candidate.is_dir():
        raise ConfigError(f"{candidate}: a folder; expected a {kind[:-1] if kind.endswith('s') else kind} YAML "
                          f"file or a NAME from configs/{kind}/ ({', '.join(available_names(kind)) or 'none'})")
    if candidate.suffix in (".yaml", ".yml") or candidate.is_file():
        if not candidate.is_file():
            raise ConfigError(f"{candidate}: config file not found")
        return candidate
    for folder in config_dirs():
        path = folder / kind / f"{name_or_path}.yaml"
        if path.is_file():
            return path
    names = ", ".join(available_names(kind)) or "(none)"
    raise ConfigError(f"unknown {kind[:-1] if kind.endswith('s') else kind} {name_or_path!r}; available: {names}")


def _format_loc(loc: tuple[Any, ...]) -> str:
    parts: list[str] = []
    for item in loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        else:
            parts.append(("." if parts else "") + str(item))
    return "".join(parts) or "(top level)"


def _shown_input(value: Any, limit: int = 80) -> str:
    """`` got VALUE:`` for the message, unless VALUE is long (a whole section, when a check across its fields fails):
    the key path says where, and a dump of the section would bury the reason."""
    text = repr(value)
    return f" got {text}:" if len(text) <= limit else ""


def format_validation_error(source: str, exc: ValidationError) -> str:
    """One line per error, each naming the key path, the value given and what is expected; the first
    line also names the file, so that a one-line report (a log, a CLI error) says where to look."""
    lines = []
    for err in exc.errors(include_url=False):
        # Tagged unions add the tag name to the location; it is not a key the user wrote.
        loc = tuple(p for p in err["loc"] if p not in ("constant", "uniform", "truncnormal", "lognormal"))
        shown = "" if err["type"] == "missing" else _shown_input(err.get("input"))
        lines.append(f"{_format_loc(loc)}:{shown} {err['msg']}")
    more = f" (and {len(lines) - 1} more below)" if len(lines) > 1 else ""
    return "\n".join([f"{source}: invalid config: {lines[0]}{more}"] + [f"  {line}" for line in lines[1:]])


def parse_config(model: type[M], data: Any, source: str, path: Path | None = None) -> M:
    """Validate already-parsed data into ``model``; errors name ``source`` and the key path. ``path``: the file
    the data came from, against whose folder the config's relative file paths resolve (the current folder if
    None; see pipeline.core.config.actor_meshes)."""
    try:
        context = {"config_file": str(path)} if path is not None else None
        return model.model_validate(data if data is not None else {}, context=context)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(source, exc)) from None


def load_config(model: type[M], name_or_path: str | Path, kind: str) -> tuple[M, Path]:
    """Load ``configs/<kind>/NAME.yaml`` or PATH into ``model``. Returns the model and the file used."""
    path = resolve_config_path(name_or_path, kind)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if data is not None and not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return parse_config(model, data, str(path), path), path
