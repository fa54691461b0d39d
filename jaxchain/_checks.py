"""The checks of arguments that many entry points share, written once."""

import numpy as np

from ._errors import ValidationError


def is_count(value) -> bool:
    """Whether `value` is an integer (Python's or NumPy's), and not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def check_count(name: str, value, least: int = 1, most: int | None = None) -> int:
    """`value` as an int, checked to be an integer in [least, most].

    **Arguments:**

    - `name`: the argument's name, as the error names it (`"n_samples"`,
        `"SimulationOptions.max_steps"`).
    - `value`: the value given.
    - `least`, `most`: the bounds, inclusive; no upper bound when `most` is None.

    **Returns:**

    `int(value)`.

    **Raises:**

    `ValidationError` naming the argument and its value for a bool, a non-integer
    or an integer out of bounds.
    """
    if not is_count(value) or value < least or (most is not None and value > most):
        bounds = f">= {least}" if most is None else f"in [{least}, {most}]"
        raise ValidationError(f"{name} must be an integer {bounds}, got {value!r}")
    return int(value)


def check_positive(name: str, value):
    """`value`, checked to be a number > 0 (NaN is not).

    **Raises:**

    `ValidationError` naming the argument and its value for anything else.
    """
    try:
        positive = bool(value > 0)
    except TypeError:
        positive = False
    if not positive:
        raise ValidationError(f"{name} must be > 0, got {value!r}")
    return value
