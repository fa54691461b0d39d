"""The largest Lyapunov exponent by Benettin's method, with its convergence."""

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import AbstractObserver
from ..._errors import ValidationError


class LargestLyapunov(AbstractObserver):
    """The largest Lyapunov exponent of the flow, by Benettin's method (Benettin,
    Galgani, Giorgilli and Strelcyn, Meccanica 15, 1980): a tangent vector u is
    integrated beside the trajectory by the variational equation u' = J(y) u, with
    J u from `jax.jvp` of the vector field, under the solver's error control;
    it is renormalised after every chunk, and the logs of its growths are
    averaged over [t_start, t_end]. Nothing here is specific to the chain: any
    vector field of `integrate` works.

    The variational equation is integrated, rather than the integrator
    differentiated: differentiating an adaptive explicit solver on the stiff
    stick phase gives a tangent that no error control watches, and exponents of
    0.4 on stable limit cycles (Tsit5, rtol 1e-5).

    Keep the chunk length below about 300 / lambda so that the tangent's growth
    over one chunk stays finite in float64.

    **Arguments:**

    - `t_start`: the exponent is averaged over the chunks that start at or after
        `t_start` (`options.transient` by default); the chunks before align the
        tangent vector with the most unstable direction.
    - `n_history`: points of the running estimate kept, evenly spaced over the
        window (its convergence).
    - `seed`: PRNG seed of the initial tangent vector (standard normal entries, so
        that it lies in no invariant subspace of a symmetric state).

    **Results** (in units of 1/time, dimensionless time of eq. (4)):

    - `lyapunov`: the exponent, shape ().
    - `lyapunov_error`: its stated error, shape (): twice the standard error of
        the mean of the chunk-wise exponents (batch means), plus 1/T, T the length
        of the window. The second term is the resolution of a finite-time
        exponent: on a limit cycle the tangent turns into the flow direction
        f(y), whose norm varies along the orbit, so the estimate of the exponent
        0 is off by log(|f(y(t_end))| / |f(y(t_start))|) / T, about 1/T, an
        offset that every chunk shares and the batch means do not see.
    - `lyapunov_history`: the running estimate at `lyapunov_time`, shape
        (n_history,).
    """

    needs_tangent = True
    t_start: float | None = eqx.field(static=True, default=None)
    n_history: int = eqx.field(static=True, default=50)
    seed: int = eqx.field(static=True, default=0)

    def _start(self, options):
        start = options.transient if self.t_start is None else self.t_start
        if not 0 <= start < options.t_end:
            raise ValidationError(f"LargestLyapunov.t_start must lie in [0, t_end = "
                                  f"{options.t_end:g}), got {start!r}")
        return float(start)

    def history_times(self, options):
        """Times of the running estimate, shape (n_history,)."""
        start = self._start(options)
        return start + (options.t_end - start) * jnp.arange(1, self.n_history + 1) / self.n_history

    def initial_tangent(self, y0):
        """The unit tangent vector the run starts from, shaped like `y0`."""
        u = jax.random.normal(jax.random.key(self.seed), jnp.shape(y0))
        return u / jnp.linalg.norm(u)

    def init(self, y0, args, options):
        zero = jnp.zeros(())
        return (zero, zero, zero, zero, zero,
                jnp.full((self.n_history,), jnp.nan))

    def update(self, state, chunk, args, options):
        log_sum, time, mean, m2, n, history = state
        length = chunk.t1 - chunk.t0
        start = self._start(options)
        use = (chunk.t0 >= start - 1e-9 * max(1.0, abs(start))) & (length > 0)
        rate = chunk.log_growth / jnp.where(use, length, 1.0)
        log_sum = log_sum + jnp.where(use, chunk.log_growth, 0.0)
        time = time + jnp.where(use, length, 0.0)
        estimate = log_sum / time
        history = jnp.where(use & (self.history_times(options) >= chunk.t1 - 1e-9 * chunk.t1),
                            estimate, history)
        # Welford's running mean and sum of squared deviations of the chunk rates
        n_new = n + use
        mean_new = jnp.where(use, mean + (rate - mean) / jnp.maximum(n_new, 1), mean)
        m2 = m2 + jnp.where(use, (rate - mean) * (rate - mean_new), 0.0)
        return log_sum, time, mean_new, m2, n_new, history

    def result(self, state, args, options):
        log_sum, time, _, m2, n, history = state
        variance = m2 / (n - 1)
        return {"lyapunov": log_sum / time,
                "lyapunov_error": 2.0 * jnp.sqrt(variance / n) + 1.0 / time,
                "lyapunov_history": history,
                "lyapunov_time": self.history_times(options)}

    def dims(self, options):
        return {"lyapunov": (), "lyapunov_error": (),
                "lyapunov_history": ("lyapunov_time",),
                "lyapunov_time": ("lyapunov_time",)}

