"""The chain's topology: which oscillators the springs eta_c join (a ring, eq. (5)
of the paper, or an open line), their neighbours, and mistuning. The coupling
force of the springs is in `forces`."""

import equinox as eqx
import jax
import numpy as np

from .._errors import ValidationError

#: The boundaries of the chain:
#: - "ring": eq. (5) of the paper, oscillator N coupled to oscillator 1 (n_osc links;
#:   link n joins oscillators n and n+1, link N joins N and 1);
#: - "free": an open line, the end oscillators coupled to one neighbour (n_osc - 1
#:   links; link n joins n and n+1);
#: - "fixed": an open line whose ends are also tied to the ground by eta_c
#:   (n_osc + 1 links; link 0 joins the ground and oscillator 1, link N oscillator
#:   N and the ground).
BOUNDARIES = ("ring", "free", "fixed")


def n_links(boundary: str, n_osc: int) -> int:
    """The number of coupling springs of a chain of `n_osc` oscillators.

    **Raises:**

    `ValidationError` for an unknown boundary.
    """
    if boundary not in BOUNDARIES:
        raise ValidationError(f"boundary must be one of {', '.join(BOUNDARIES)}, got {boundary!r}")
    return {"ring": n_osc, "free": n_osc - 1, "fixed": n_osc + 1}[boundary]


def neighbours(boundary: str, n_osc: int) -> tuple[np.ndarray, np.ndarray]:
    """The left and the right neighbour of each oscillator, 0-based indices of shape
    (n_osc,): on the ring oscillator N's right neighbour is oscillator 1 (a ring of
    one is its own neighbour); on an open line ("free", "fixed") the ends have none,
    -1.

    **Raises:**

    `ValidationError` for an unknown boundary.
    """
    n_links(boundary, n_osc)
    index = np.arange(n_osc)
    left, right = (index - 1) % n_osc, (index + 1) % n_osc
    if boundary != "ring":
        left[0], right[-1] = -1, -1
    return left, right


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
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise ValidationError(f"Mistuning.seed must be an integer, got {self.seed!r}")

    def deviations(self, n_osc: int) -> np.ndarray:
        """delta_n, shape (n_osc,): sigma times standard normal draws of the key."""
        draws = jax.random.normal(jax.random.key(int(self.seed)), (n_osc,), dtype=float)
        return float(self.sigma) * np.asarray(draws)

    def stiffness(self, n_osc: int) -> np.ndarray:
        """1 + delta_n, shape (n_osc,) (the ground stiffness k_n / k of eq. (5))."""
        return 1.0 + self.deviations(n_osc)
