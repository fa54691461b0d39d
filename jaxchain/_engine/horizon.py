"""The horizon of a run, shared by both engines: how long, which window is
observed, and the chunks it is integrated in."""

import math

import equinox as eqx
import numpy as np

from .._errors import ValidationError


def _number(value) -> bool:
    """A finite real number (Python, NumPy, or a 0-d JAX array), not a bool."""
    if hasattr(value, "shape") and value.shape == ():
        value = float(value)
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool) and math.isfinite(value))


def positive(value) -> bool:
    """A finite real number > 0."""
    return _number(value) and float(value) > 0


class AbstractHorizon(eqx.Module):
    """The horizon, window and chunking of a run: the base of `SimulationOptions`
    (the smoothed engine) and `NonsmoothOptions` (the non-smooth reference), so
    that both engines cut a run alike and hand their observers (`AbstractObserver`)
    the same window.

    **Fields** (static, dimensionless times, eq. (4) of the paper):

    - `t_end`: final time (the paper's 15000).
    - `transient`: observables are taken over [transient, t_end] (the paper's
        10000, Section 3.2).
    - `chunk_length`: the run advances in chunks of about this length, one
        progress tick each.
    """

    t_end: eqx.AbstractVar[float]
    transient: eqx.AbstractVar[float]
    chunk_length: eqx.AbstractVar[float]

    def check_horizon(self) -> None:
        """**Raises:** `ValidationError` naming the field for t_end or chunk_length
        not a finite number > 0, and transient outside [0, t_end)."""
        name = type(self).__name__
        for field in ("t_end", "chunk_length"):
            value = getattr(self, field)
            if not positive(value):
                raise ValidationError(f"{name}.{field} must be a finite number > 0, "
                                      f"got {value!r}")
        if not (_number(self.transient) and 0 <= self.transient < self.t_end):
            raise ValidationError(f"{name}.transient must lie in [0, t_end = "
                                  f"{self.t_end}), got {self.transient!r}")

    @property
    def mid(self) -> float:
        """The middle of the observed window, where its second half begins."""
        return 0.5 * (self.transient + self.t_end)

    def chunks(self, t0: float, t1: float) -> tuple[int, float]:
        """Number and length of the equal chunks that cover [t0, t1]."""
        n = max(1, math.ceil((t1 - t0) / self.chunk_length - 1e-9))
        return n, (t1 - t0) / n

    def phases(self, halves: bool = False) -> list[tuple[float, float, int, bool]]:
        """The phases of a run as (start, chunk length, number of chunks,
        observed): the transient (not observed, left out when 0), then the
        observed window, whole or (`halves`) cut at `mid` so that a chunk ends
        there."""
        bounds = [(0.0, self.transient, False)]
        if halves:
            bounds += [(self.transient, self.mid, True), (self.mid, self.t_end, True)]
        else:
            bounds += [(self.transient, self.t_end, True)]
        out = []
        for t0, t1, observed in bounds:
            if t1 > t0:
                count, length = self.chunks(t0, t1)
                out.append((t0, length, count, observed))
        return out

    def n_chunks(self, halves: bool = False) -> int:
        """Number of chunks of one run (its progress ticks)."""
        return sum(count for _, _, count, _ in self.phases(halves))
