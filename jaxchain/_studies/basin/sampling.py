"""Initial states drawn uniformly from a box, with a JAX PRNG key: the sampling of
basin stability (Menck et al., Nature Physics 9, 89-92 (2013))."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._errors import ValidationError


class Box(eqx.Module):
    """A box of initial states in absolute coordinates (dimensionless, eqs.
    (4)-(6)): x_n(0) in [x[0], x[1]] and x_n'(0) in [v[0], v[1]], independently
    for each oscillator n.

    The default, x in [-2, 2] and x' in [0, 2], holds the paper's starts (eq. (8):
    x = F(-v_d) +- 2, x' = 0; eq. (10): x' = 0.56), steady sliding (x = mu(v_d)
    ~ 0.5, x' = 0) and stick (x' = v_d) for the belt speeds of Figs. 3-10.

    **Raises:**

    `ValidationError` naming `x` or `v` unless each is two finite numbers lo < hi.
    """

    x: tuple[float, float] = eqx.field(static=True, default=(-2.0, 2.0))
    v: tuple[float, float] = eqx.field(static=True, default=(0.0, 2.0))

    def __check_init__(self):
        for name in ("x", "v"):
            pair = getattr(self, name)
            ok = (isinstance(pair, (tuple, list)) and len(pair) == 2
                  and all(isinstance(b, (int, float)) and not isinstance(b, bool)
                          and math.isfinite(b) for b in pair) and pair[0] < pair[1])
            if not ok:
                raise ValidationError(f"Box.{name} must be two finite numbers lo < hi, "
                                      f"got {pair!r}")


def sample_states(key: Array, box: Box, n_samples: int, n_osc: int
                  ) -> Float[Array, "n_samples 2 n_osc"]:
    """`n_samples` initial states drawn uniformly and independently from `box`.

    **Arguments:**

    - `key`: a JAX PRNG key (`jax.random.key` or `jax.random.PRNGKey`).
    - `box`: the `Box`.
    - `n_samples`, `n_osc`: how many states, of how many oscillators.

    **Returns:**

    Shape (n_samples, 2, n_osc): rows x and x' of each state.
    """
    kx, kv = jax.random.split(key)
    x = jax.random.uniform(kx, (n_samples, n_osc), minval=box.x[0], maxval=box.x[1])
    v = jax.random.uniform(kv, (n_samples, n_osc), minval=box.v[0], maxval=box.v[1])
    return jnp.stack([x, v], axis=1)
