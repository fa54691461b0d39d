"""The mechanical energy of the chain over a window: its time mean and its maximum."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._physics.model import mechanical_energy
from .base import AbstractObserver, in_window, window_start


class Energy(AbstractObserver):
    """Time mean and maximum of the chain's kinetic plus elastic energy
    (`mechanical_energy`) over [t_start, t_end]: the actual vibration energy that
    the paper's E of eq. (9) (see `Extrema`) stands in for. Memory: 3 numbers.

    **Arguments:**

    - `t_start`: start of the window, `options.transient` by default.

    **Results** (dimensionless, eqs. (4)-(6)):

    - `energy_mean`: (1/T) integral of the energy over the window (trapezoidal
        rule on the dense samples), shape ().
    - `energy_max`: its largest value over the samples (every sample_dt), shape ().
    """

    t_start: float | None = eqx.field(static=True, default=None)

    def init(self, y0, args, options):
        window_start(self.t_start, options)
        return jnp.zeros(()), jnp.zeros(()), jnp.array(-jnp.inf)

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        integral, length, peak = state
        seen = in_window(chunk, window_start(self.t_start, options))
        energy = jax.vmap(lambda y: mechanical_energy(args.params, y))(chunk.ys)
        both = seen[:-1] & seen[1:]
        dt = jnp.diff(chunk.ts)
        integral = integral + jnp.sum(jnp.where(both, 0.5 * (energy[:-1] + energy[1:]) * dt, 0.0))
        length = length + jnp.sum(jnp.where(both, dt, 0.0))
        return integral, length, jnp.maximum(peak, jnp.where(seen, energy, -jnp.inf).max())

    def result(self, state, args, options):
        integral, length, peak = state
        return {"energy_mean": integral / length, "energy_max": peak}

    def dims(self, options):
        return {"energy_mean": (), "energy_max": ()}
