"""The command line's number lists, parsed in one place: a grid ``START:STOP:STEP`` (stop
included) or comma-separated numbers, and the five activations."""

from __future__ import annotations

import math

import numpy as np

from persival.vocabulary import MUSCLES, N_ACTIVATIONS


def parse_numbers(text: str, what: str, unit: str = "", *, grid: bool = False, minimum: float | None = None) -> list[float]:
    """Comma-separated finite numbers (or, with ``grid``, START:STOP:STEP); a ValueError names
    the option ``what`` and shows the text."""
    form = "START:STOP:STEP or comma-separated numbers" if grid else "comma-separated numbers"
    suffix = f" ({unit})" if unit else ""
    try:
        if grid and ":" in text:
            start, stop, step = (float(t) for t in text.split(":"))
            if not step > 0 or not np.isfinite([start, stop, step]).all():
                raise ValueError
            values = [float(v) for v in np.arange(start, stop + 1e-9 * max(1.0, abs(stop)), step)]
        else:
            values = [float(t) for t in text.split(",") if t.strip()]
        if not values:
            raise ValueError
    except ValueError:
        raise ValueError(f"{what} must be {form}{suffix}, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what}: a value is not finite, got {text!r}")
    if minimum is not None and min(values) < minimum:
        raise ValueError(f"{what} must be >= {minimum:g}{suffix}, got {text!r}")
    return values


def parse_grid(text: str, what: str) -> list[float]:
    """'0:160:10' (start:stop:step, stop included) or a comma-separated list."""
    return parse_numbers(text, what, grid=True)


def parse_activations(text: str) -> list[float]:
    """The --activations option: five numbers (their range is checked by check_activation_vector)."""
    values = parse_numbers(text, "--activations")
    if len(values) != N_ACTIVATIONS:
        raise ValueError(f"--activations needs {N_ACTIVATIONS} numbers ({', '.join(MUSCLES)}), got {len(values)}")
    return values
