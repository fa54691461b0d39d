"""Extrema of the oscillators over a window: amplitudes, the energy of eq. (9) and
which oscillators are on the high-amplitude limit cycle (HALC)."""

import equinox as eqx
import jax.numpy as jnp

from ..._physics.stick import min_slip_speed, sticks
from .base import AbstractObserver, in_halves, window_start


class Extrema(AbstractObserver):
    """Running extrema of x_n and x_n' over [t_start, t_end], and the extrema of
    x_n and the smallest slip speed |x_n' - v_d| over each half of that window.
    Memory: 7 n_osc numbers.

    **Arguments:**

    - `t_start`: start of the window, `options.transient` by default (the paper's
        10000).

    **Results** (dimensionless, eqs. (4)-(6)):

    - `amplitudes`: half of peak-to-peak of x_n, shape (n_osc,).
    - `energy`: E = 1/2 sum A_n^2, eq. (9) of the paper, shape ().
    - `on_halc`: oscillators that stick, `min_slip_speed` <= 3 eps (`sticks`),
        shape (n_osc,); `n_halc` their number, shape ().
    - `n_halc_halves`: n_halc over the first and the second half of the window,
        shape (2,); they differ when a front propagates during the window.
    - `min_slip_speed`, `x_max`, `x_min`, `v_max`: shape (n_osc,).
    - `x_max_halves`, `x_min_halves`: extrema of x_n over the first and the second
        half of the window, shape (2, n_osc); they differ by the integration
        tolerance in a periodic state.

    A sample at the middle of the window belongs to both halves. The smoothed
    engine feeds the dense samples of each chunk, the non-smooth reference the
    state at each located event (turning points, switches) and chunk end; both
    through `observe_chunk`.

    An extremum of a smooth slip phase is missed by at most |x''| sample_dt^2 / 8
    (see `SimulationOptions.sample_dt`).
    """

    t_start: float | None = eqx.field(static=True, default=None)

    def init(self, y0, args, options):
        window_start(self.t_start, options)
        big = jnp.full((2,) + y0.shape[-1:], jnp.inf)
        return (-big, big, -big[0], big)

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        halves = in_halves(chunk, window_start(self.t_start, options), options.t_end)
        x, v = chunk.ys[:, 0], chunk.ys[:, 1]
        x_max, x_min, v_max, slip = state
        seen = halves.any(0)[:, None]

        def per_half(reduce, values, fill):
            return jnp.stack([reduce(jnp.where(h[:, None], values, fill), axis=0)
                              for h in halves])

        return (jnp.maximum(x_max, per_half(jnp.max, x, -jnp.inf)),
                jnp.minimum(x_min, per_half(jnp.min, x, jnp.inf)),
                jnp.maximum(v_max, jnp.where(seen, v, -jnp.inf).max(0)),
                jnp.minimum(slip, jnp.stack([
                    min_slip_speed(jnp.where(h[:, None], v, jnp.inf), args.params.v_d)
                    for h in halves])))

    def result(self, state, args, options):
        x_max_halves, x_min_halves, v_max, slip_halves = state
        x_max, x_min = x_max_halves.max(0), x_min_halves.min(0)
        amplitudes = 0.5 * (x_max - x_min)
        slip = slip_halves.min(0)
        on_halc = sticks(slip, args.eps)
        return {
            "amplitudes": amplitudes, "energy": 0.5 * jnp.sum(amplitudes**2),
            "on_halc": on_halc, "n_halc": jnp.sum(on_halc),
            "n_halc_halves": jnp.sum(sticks(slip_halves, args.eps), axis=-1),
            "min_slip_speed": slip, "x_max": x_max, "x_min": x_min, "v_max": v_max,
            "x_max_halves": x_max_halves, "x_min_halves": x_min_halves,
        }

    def dims(self, options):
        osc = ("osc",)
        return {"amplitudes": osc, "energy": (), "on_halc": osc, "n_halc": (),
                "n_halc_halves": ("half",), "min_slip_speed": osc, "x_max": osc,
                "x_min": osc, "v_max": osc, "x_max_halves": ("half", "osc"),
                "x_min_halves": ("half", "osc")}
