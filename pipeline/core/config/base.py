"""The base of every config model: frozen, no unknown keys, and only finite numbers of a sane size.

YAML can spell numbers that render garbage without any error: ``.inf`` (a black image), ``.nan``
(``NaN`` in a sky colour: a teal sky), ``1e30`` (noise that swamps everything). Every config model
derives from :class:`ConfigModel`, so every float it holds, in a field, a tuple, a list or a mapping
at any depth, is checked once, here, and not field by field:

- non-finite values (``inf``, ``nan``, also as the strings "inf" and "nan") are rejected by
  pydantic's ``allow_inf_nan=False``;
- a finite value must be 0 or have a magnitude in [MIN_ABS, MAX_ABS] = [1e-9, 1e6]: no quantity of
  a scene, sensor, condition, detector or experiment config lies outside that range in its own
  unit (metres, seconds, degrees, pixels, linear radiance, probabilities, learning rates), so a
  value outside it is a typo or an attack, not a setting. A field with a tighter sane range states
  it with ``Field`` bounds as usual.

Errors carry the key path through :func:`pipeline.core.config.loading.format_validation_error`.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from pydantic import BaseModel, ConfigDict, field_validator

__all__ = ["MAX_ABS", "MAX_RUN_SEED", "MIN_ABS", "ConfigModel", "run_seed_problem"]

MAX_ABS = 1e6
MIN_ABS = 1e-9
# A run seed goes to SUMO (--seed, a C int: SUMO prints "not a valid integer" for a larger one and runs with its own
# default seed) and, plus one, to randomTrips for the pedestrians; numpy's generators take no negative seed.
MAX_RUN_SEED = 2**31 - 2


def run_seed_problem(seed: object) -> str | None:
    """Why ``seed`` cannot be a run seed (None: it can): an integer in [0, MAX_RUN_SEED] is expected."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_RUN_SEED:
        return f"expected an integer from 0 to {MAX_RUN_SEED} (SUMO takes a 32-bit seed), got {seed!r}"
    return None


def _floats(value: Any, where: str = "") -> Iterator[tuple[str, float]]:
    """Every float in ``value`` (nested tuples, lists and dicts; not sub-models, which check themselves)."""
    if isinstance(value, float):
        yield where, value
    elif isinstance(value, (tuple, list)):
        for i, item in enumerate(value):
            yield from _floats(item, f"{where}[{i}]")
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _floats(item, f"{where}[{key!r}]")


class ConfigModel(BaseModel):
    """Frozen, unknown keys forbidden, floats finite and of a sane magnitude (see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @field_validator("*", mode="after")
    @classmethod
    def _sane_magnitude(cls, value: Any) -> Any:
        for where, number in _floats(value):
            if number != 0.0 and not MIN_ABS <= abs(number) <= MAX_ABS:
                at = f" (at {where})" if where else ""
                raise ValueError(
                    f"{number!r}{at} is not a sane setting: a number must be 0 or have a magnitude "
                    f"between {MIN_ABS:g} and {MAX_ABS:g}"
                )
        return value
