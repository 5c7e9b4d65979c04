"""Checks of the numeric parameters of the driver, the tracker and the closed loop (dataclasses, not configs)."""

from __future__ import annotations

import math


def check_number(owner: str, name: str, value: object, *, low: float = 0.0, allow_low: bool = False,
                 high: float = math.inf, allow_high: bool = True) -> None:
    """Raise ValueError naming ``owner.name`` unless ``value`` is a finite number in the interval from ``low`` to
    ``high`` (each end included where ``allow_low`` / ``allow_high``)."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value >= low if allow_low else value > low) and (value <= high if allow_high else value < high)
    if not ok:
        left, right = "[" if allow_low else "(", "]" if allow_high else ")"
        raise ValueError(f"{owner}.{name}: expected a finite number in {left}{low:g}, {high:g}{right}, got {value!r}")
