"""Extrema of the oscillators over a window: amplitudes, the energy of eq. (9) and
which oscillators are on the high-amplitude limit cycle (HALC)."""

import equinox as eqx
import jax.numpy as jnp

from ..._physics.stick import min_slip_speed, sticks
from .base import AbstractObserver, in_window, window_start


class Extrema(AbstractObserver):
    """Running extrema of x_n and x_n' over [t_start, t_end], and the smallest slip
    speed |x_n' - v_d| over each half of that window. Memory: 5 n_osc numbers.

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

    An extremum of a smooth slip phase is missed by at most |x''| sample_dt^2 / 8
    (see `SimulationOptions.sample_dt`).
    """

    t_start: float | None = eqx.field(static=True, default=None)

    def init(self, y0, args, options):
        window_start(self.t_start, options)
        big = jnp.full(y0.shape[-1:], jnp.inf)
        return (-big, big, -big, big, big)

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        start = window_start(self.t_start, options)
        seen = in_window(chunk, start)[:, None]
        late = (chunk.ts >= 0.5 * (start + options.t_end))[:, None]
        x, v = chunk.ys[:, 0], chunk.ys[:, 1]
        x_max, x_min, v_max, slip_early, slip_late = state
        return (jnp.maximum(x_max, jnp.where(seen, x, -jnp.inf).max(0)),
                jnp.minimum(x_min, jnp.where(seen, x, jnp.inf).min(0)),
                jnp.maximum(v_max, jnp.where(seen, v, -jnp.inf).max(0)),
                jnp.minimum(slip_early, min_slip_speed(
                    jnp.where(seen & ~late, v, jnp.inf), args.v_d)),
                jnp.minimum(slip_late, min_slip_speed(
                    jnp.where(seen & late, v, jnp.inf), args.v_d)))

    def result(self, state, args, options):
        x_max, x_min, v_max, slip_early, slip_late = state
        amplitudes = 0.5 * (x_max - x_min)
        slip = jnp.minimum(slip_early, slip_late)
        on_halc = sticks(slip, args.eps)
        return {
            "amplitudes": amplitudes, "energy": 0.5 * jnp.sum(amplitudes**2),
            "on_halc": on_halc, "n_halc": jnp.sum(on_halc),
            "n_halc_halves": jnp.stack([jnp.sum(sticks(slip_early, args.eps)),
                                        jnp.sum(sticks(slip_late, args.eps))]),
            "min_slip_speed": slip, "x_max": x_max, "x_min": x_min, "v_max": v_max,
        }

    def dims(self, options):
        osc = ("osc",)
        return {"amplitudes": osc, "energy": (), "on_halc": osc, "n_halc": (),
                "n_halc_halves": ("half",), "min_slip_speed": osc, "x_max": osc,
                "x_min": osc, "v_max": osc}
