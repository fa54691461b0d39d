"""Random stiffness mistuning of a chain: the deviations delta_n of the ground
stiffness k_n = 1 + delta_n in eq. (5), drawn from a normal distribution; the
record of a draw (`Mistuning`, kept in `ChainParams.mistuning`, which rebuilds the
same chain) and the function that mistunes a chain (`mistune`)."""

import dataclasses

import equinox as eqx
import jax
import numpy as np

from .._checks import is_count
from .._errors import ValidationError


class Mistuning(eqx.Module):
    """The record of a random stiffness mistuning: deviations delta_n of eq. (5)
    drawn from a normal distribution of standard deviation `sigma` with the JAX key
    `jax.random.key(seed)`, so that the chain can be rebuilt from the record.

    **Arguments:**

    - `sigma`: standard deviation of delta_n (>= 0, dimensionless).
    - `seed`: integer seed of the key.

    **Raises:**

    `ValidationError` for a negative or non-finite sigma, or a seed that is not an
    integer.
    """

    sigma: float = eqx.field(static=True)
    seed: int = eqx.field(static=True)

    def __check_init__(self):
        if not (isinstance(self.sigma, (int, float, np.floating, np.integer))
                and np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValidationError(f"Mistuning.sigma must be a finite number >= 0, got "
                                  f"{self.sigma!r}")
        if not is_count(self.seed):
            raise ValidationError(f"Mistuning.seed must be an integer, got {self.seed!r}")

    def deviations(self, n_osc: int) -> np.ndarray:
        """delta_n, shape (n_osc,): sigma times standard normal draws of the key."""
        # a constant, also where a chain is rebuilt under a trace (`with_parameter`
        # of a mistuned chain under `jax.jit`)
        with jax.ensure_compile_time_eval():
            draws = jax.random.normal(jax.random.key(int(self.seed)), (n_osc,), dtype=float)
        return float(self.sigma) * np.asarray(draws)

    def stiffness(self, n_osc: int) -> np.ndarray:
        """1 + delta_n, shape (n_osc,) (the ground stiffness k_n / k of eq. (5))."""
        return 1.0 + self.deviations(n_osc)


def mistune(params: eqx.Module, sigma: float, seed: int) -> eqx.Module:
    """`params` with random stiffness mistuning: k_n = 1 + delta_n, delta_n drawn
    from a normal distribution of standard deviation `sigma` with the JAX key
    `jax.random.key(seed)`, and the `Mistuning` record kept in `params.mistuning`
    (it rebuilds the same chain). sigma = 0 leaves the stiffness as it is (the
    homogeneous chain, bit for bit).

    **Arguments:**

    - `params`: the chain parameters (a `ChainParams`).
    - `sigma`: standard deviation of delta_n (>= 0, dimensionless).
    - `seed`: integer seed.

    **Returns:**

    A new `ChainParams`.

    **Raises:**

    `ValidationError` for a negative sigma or a seed that is not an integer, or when the
    draw gives a stiffness <= 0 (sigma too large).
    """
    record = Mistuning(sigma=sigma, seed=seed)
    stiffness = params.stiffness if sigma == 0 else record.stiffness(params.n_osc)
    # Built again and validated, as `with_fields` builds it: `params`, which checks
    # the type of its record against `Mistuning`, imports this module.
    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    return type(params)(**fields | {"stiffness": stiffness, "mistuning": record})
