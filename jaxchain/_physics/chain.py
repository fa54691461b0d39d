"""The chain's topology and its coupling: which oscillators the springs eta_c join
(a ring, eq. (5) of the paper, or an open line), the one coupling force used by the
smoothed model, the non-smooth reference and the energy, and mistuning."""

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import ValidationError

if TYPE_CHECKING:
    from .params import ChainParams

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


def link_extensions(params: "ChainParams", x: Float[Array, " n_osc"]
                    ) -> Float[Array, " n_links"]:
    """The extension of each coupling spring, x_right - x_left (the ground's
    displacement is 0), in the link order of `BOUNDARIES`.

    **Arguments:**

    - `params`: the chain parameters (`boundary`).
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    Shape (n_links,).
    """
    if params.boundary == "ring":
        return jnp.roll(x, -1) - x
    if params.boundary == "free":
        return x[1:] - x[:-1]
    ground = jnp.zeros((1,), dtype=x.dtype)
    return jnp.diff(jnp.concatenate([ground, x, ground]))


def coupling_force(params: "ChainParams", x: Float[Array, " n_osc"]
                   ) -> Float[Array, " n_osc"]:
    """The restoring force of the coupling springs on each oscillator, the coupling
    term of eq. (5) of the paper generalised to any boundary and to one eta_c per
    link: the sum over oscillator n's links l of eta_l (x_n - x_other(l)).

    On the homogeneous ring (scalar eta_c) this is eq. (5)'s
    eta_c (2 x_n - x_{n+1} - x_{n-1}), evaluated in that form, so that the paper's
    runs are reproduced bit for bit.

    **Arguments:**

    - `params`: the chain parameters (`boundary`, `eta_c` of shape () or (n_links,)).
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    Shape (n_osc,), dimensionless (in units of the normal load P); it enters eq. (5)
    with a minus sign.
    """
    if params.boundary == "ring" and jnp.ndim(params.eta_c) == 0:
        return params.eta_c * (2 * x - jnp.roll(x, 1) - jnp.roll(x, -1))
    tension = params.eta_c * link_extensions(params, x)
    if params.boundary == "ring":  # link n pulls oscillator n forward, n+1 back
        return jnp.roll(tension, 1) - tension
    if params.boundary == "free":
        nothing = jnp.zeros((1,), dtype=tension.dtype)
        tension = jnp.concatenate([nothing, tension, nothing])
    return tension[:-1] - tension[1:]


def coupling_energy(params: "ChainParams", x: Float[Array, " n_osc"]
                    ) -> Float[Array, " n_links"]:
    """The elastic energy of each coupling spring, eta_l (extension)^2 / 2, shape
    (n_links,), dimensionless (in units of P x_0). Its gradient in x is
    `coupling_force`."""
    return 0.5 * params.eta_c * link_extensions(params, x) ** 2


def stiffness_matrix(params: "ChainParams") -> Float[Array, "n_osc n_osc"]:
    """The stiffness matrix K of the linear chain, x'' = -K x + ...: the ground
    springs (`stiffness`, 1 + delta_n in eq. (5)) on the diagonal plus the Jacobian
    of `coupling_force` (by `jax.jacfwd`). Symmetric; its eigenvalues are the
    squared natural frequencies of the undamped chain.

    **Returns:**

    Shape (n_osc, n_osc), dimensionless.
    """
    n = params.n_osc
    coupling = jax.jacfwd(lambda x: coupling_force(params, x))(jnp.zeros(n))
    return jnp.diag(jnp.broadcast_to(params.stiffness, (n,))) + coupling


def is_homogeneous_ring(params: "ChainParams") -> bool:
    """Whether the chain is the paper's homogeneous ring: boundary "ring" and every
    per-oscillator or per-link field a scalar (a lane-batched `ChainParams` counts
    by its fields' trailing shape). Then the Jacobian at steady sliding is
    block-circulant (the Fourier route of `mode_eigenvalues`)."""
    if params.boundary != "ring":
        return False
    return all(np.ndim(leaf) == 0 for leaf in per_oscillator_leaves(params))


def per_oscillator_leaves(params: "ChainParams") -> list:
    """The fields that may hold one value per oscillator or per link: stiffness,
    load, xi, eta_c and the friction law's parameters."""
    return ([params.stiffness, params.load, params.xi, params.eta_c]
            + jax.tree_util.tree_leaves(params.friction))


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
