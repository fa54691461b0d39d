"""Time series of chosen oscillators over a window, at a chosen sampling."""

import math

import equinox as eqx
import jax.numpy as jnp

from .base import AbstractObserver, window_start
from .crossings import hermite_position, hermite_velocity
from ..._errors import ValidationError


class TimeSeries(AbstractObserver):
    """x_n and x_n' of chosen oscillators at t_start, t_start + dt, ... <= t_stop.
    Memory: 2 x (oscillators) x (number of times), set by the window and dt.

    **Arguments:**

    - `oscillators`: 0-based indices; all if None.
    - `dt`: spacing of the series (dimensionless time).
    - `t_start`, `t_stop`: the window, by default [options.transient, t_end]; it
        must lie inside the sampled window.

    **Results:**

    - `series_t`: times, shape (times,).
    - `series`: shape (times, 2, n_series_osc): rows x (by cubic Hermite
        interpolation of the run's dense samples, v = x') and x' (its derivative).

    **Raises:**

    `ValidationError` for dt <= 0 or a window outside [transient, t_end].
    """

    oscillators: tuple[int, ...] | None = eqx.field(static=True, default=None)
    dt: float = eqx.field(static=True, default=0.1)
    t_start: float | None = eqx.field(static=True, default=None)
    t_stop: float | None = eqx.field(static=True, default=None)

    def times(self, options):
        """The series' times, shape (times,)."""
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValidationError(f"TimeSeries.dt must be a finite number > 0, got {self.dt!r}")
        start = window_start(self.t_start, options)
        stop = options.t_end if self.t_stop is None else self.t_stop
        if not start < stop <= options.t_end:
            raise ValidationError(f"TimeSeries.t_stop must lie in (t_start = {start:g}, "
                                  f"t_end = {options.t_end:g}], got {stop!r}")
        return start + self.dt * jnp.arange(math.floor((stop - start) / self.dt + 1e-9) + 1)

    def init(self, y0, args, options):
        m = y0.shape[-1] if self.oscillators is None else len(self.oscillators)
        return jnp.full((self.times(options).size, 2, m), jnp.nan)

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        ys = chunk.ys if self.oscillators is None else chunk.ys[..., jnp.asarray(
            self.oscillators)]
        t = self.times(options)
        h = chunk.ts[1] - chunk.ts[0]
        j = jnp.clip(jnp.floor((t - chunk.ts[0]) / h).astype(int), 0, chunk.ts.size - 2)
        s = ((t - chunk.ts[j]) / h)[:, None]
        x, v = ys[:, 0], ys[:, 1]
        xs = hermite_position(x[j], x[j + 1], v[j], v[j + 1], h, s)
        vs = hermite_velocity(x[j], x[j + 1], v[j], v[j + 1], h, s)
        inside = ((t >= chunk.t0) & (t <= chunk.t1))[:, None, None]
        return jnp.where(inside, jnp.stack([xs, vs], axis=1), state)

    def result(self, state, args, options):
        return {"series_t": self.times(options), "series": state}

    def dims(self, options):
        return {"series_t": ("time",), "series": ("time", "component", "series_osc")}
