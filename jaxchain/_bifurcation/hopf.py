"""Stability of steady sliding, mode by mode, and its Hopf boundary."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Complex, Float

from .._friction import friction_coefficient
from .._model import jacobian
from .._params import ChainParams, with_parameter


def fourier_blocks(params: ChainParams) -> Complex[Array, "n_osc 2 2"]:
    """The Jacobian of eq. (5) at steady sliding (`jacobian`, by `jax.jacfwd`),
    block-diagonalised by the discrete Fourier transform of the ring.

    The Jacobian is block-circulant (every oscillator sees the same law, the ring
    is periodic), so each Fourier mode k, x_n ~ exp(2 pi i k n / N), evolves on its
    own with the 2x2 block E_k^H J E_k,

        [[0, 1], [-(1 + 4 eta_c sin^2(pi k / N)), F'(-v_d) - 2 xi]].

    The union of the blocks' eigenvalues is the spectrum of J.

    **Arguments:**

    - `params`: the chain parameters.

    **Returns:**

    Blocks of shape (n_osc, 2, 2), complex, for k = 0..N-1 (k = 0 in phase,
    k = N/2 anti-phase).
    """
    n = params.n_osc
    jac = jnp.reshape(jacobian(params), (2, n, 2, n))
    k, m = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    modes = jnp.asarray(np.exp(2j * np.pi * k * m / n) / np.sqrt(n))  # (k, m)
    return jnp.einsum("km,imjl,kl->kij", modes.conj(), jac, modes)


def mode_eigenvalues(params: ChainParams) -> Complex[Array, "n_osc 2"]:
    """Eigenvalues of each Fourier block of the Jacobian at steady sliding, in
    closed form (lambda = tr/2 +- sqrt(tr^2/4 - det)), so that they are smooth in
    the parameters and JAX differentiates them exactly.

    **Returns:**

    Shape (n_osc, 2), complex, the larger real part first.
    """
    blocks = fourier_blocks(params)
    half_trace = 0.5 * (blocks[:, 0, 0] + blocks[:, 1, 1])
    det = blocks[:, 0, 0] * blocks[:, 1, 1] - blocks[:, 0, 1] * blocks[:, 1, 0]
    root = jnp.sqrt(half_trace**2 - det)
    root = jnp.where(root.real >= 0, root, -root)
    return jnp.stack([half_trace + root, half_trace - root], axis=-1)


def growth_rates(params: ChainParams) -> Float[Array, " n_osc"]:
    """Growth rate max Re(lambda) of each Fourier mode of the ring about steady
    sliding; steady sliding is stable when all are negative.

    **Returns:**

    Shape (n_osc,), dimensionless (per unit of time, eq. (4)).
    """
    return mode_eigenvalues(params)[:, 0].real


def hopf_vd_analytic(params: ChainParams) -> Float[Array, ""]:
    """The Hopf belt speed of steady sliding for sign() friction (eps -> 0):
    the effective damping 2 xi - mu'(v_d) vanishes at

        v_d,H = v0 ln((mu_st - mu_d) / (2 xi v0)),

    the same for every Fourier mode (the coupling is conservative, the damping
    uniform). 0.5 ln(10) = 1.1513 for eq. (7) of the paper (shared/DESIGN.md).

    **Raises:**

    `ValueError` if xi = 0 or mu_st = mu_d (no Hopf point).
    """
    xi, delta = np.asarray(params.xi), np.asarray(params.mu_st) - np.asarray(params.mu_d)
    if np.any(xi <= 0) or np.any(delta <= 0):
        raise ValueError(f"hopf_vd_analytic needs xi > 0 and mu_st > mu_d, got xi = "
                         f"{params.xi!r}, mu_st - mu_d = {delta!r}")
    return params.v0 * jnp.log((params.mu_st - params.mu_d) / (2 * params.xi * params.v0))


def hopf_eps_correction(params: ChainParams) -> Float[Array, ""]:
    """Leading-order shift of the Hopf belt speed by the tanh smoothing,

        v_d,H(eps) - v_d,H(0) = -v0 (2 + 2 mu(v_d,H) / (xi eps)) exp(-2 v_d,H / eps),

    from expanding tanh(v/eps) = 1 - 2 exp(-2v/eps) and sech^2(v/eps) = 4
    exp(-2v/eps) in F'(-v_d) = 2 xi. Exponentially small: 1e-1000 at eps = 1e-3, and
    -5.6e-4 at eps = 0.2 for eq. (7).

    **Returns:**

    The shift, shape (), dimensionless (always negative).
    """
    v = hopf_vd_analytic(params)
    mu = friction_coefficient(params, v)
    return -params.v0 * (2 + 2 * mu / (params.xi * params.eps)) * jnp.exp(-2 * v / params.eps)


class HopfPoint(eqx.Module):
    """The Hopf boundary of steady sliding.

    **Fields:**

    - `v_d`: the Hopf belt speed of every Fourier mode, shape (n_osc,). Steady
        sliding is stable above the largest.
    - `omega`: angular frequency of each mode at its Hopf point, shape (n_osc,).
    - `slope`: d Re(lambda) / d v_d of each mode at its Hopf point, by JAX, shape
        (n_osc,); negative (the speed stabilises steady sliding).
    - `residual`: growth rate at the returned v_d, shape (n_osc,).
    - `newton_steps`: Newton iterations of each mode, shape (n_osc,).
    """

    v_d: Float[Array, " n_osc"]
    omega: Float[Array, " n_osc"]
    slope: Float[Array, " n_osc"]
    residual: Float[Array, " n_osc"]
    newton_steps: Array


def _mode_growth(v_d, args):
    params, k = args
    return growth_rates(with_parameter(params, "v_d", v_d))[k]


@eqx.filter_jit
def _hopf_modes(params: ChainParams, guess, rtol, atol):
    solver = optx.Newton(rtol=rtol, atol=atol)

    def one(k):
        sol = optx.root_find(_mode_growth, solver, guess, (params, k), max_steps=100,
                             throw=False)
        at = with_parameter(params, "v_d", sol.value)
        slope = jax.grad(_mode_growth)(sol.value, (params, k))
        return (sol.value, jnp.abs(mode_eigenvalues(at)[k, 0].imag), slope,
                growth_rates(at)[k], sol.stats["num_steps"], sol.result)

    return jax.vmap(one)(jnp.arange(params.n_osc))


def hopf_point(params: ChainParams, guess: float = 1.0, *, rtol: float = 1e-12,
               atol: float = 1e-12) -> HopfPoint:
    """The Hopf boundary of steady sliding, mode by mode: the root in v_d of each
    Fourier mode's growth rate max Re(lambda)(v_d) = 0 (`growth_rates`), found by
    optimistix's Newton method with the derivative from JAX (the Jacobian of eq.
    (5) by `jax.jacfwd`, its modal eigenvalues differentiated by `jax.jacfwd`).

    Differentiable in the other parameters by implicit differentiation (optimistix's
    `ImplicitAdjoint`): d v_d,H / d xi = -(d g/d xi) / (d g/d v_d).

    **Arguments:**

    - `params`: the chain parameters; `params.v_d` is ignored.
    - `guess`: starting belt speed of Newton's method.
    - `rtol`, `atol`: Newton tolerances on v_d.

    **Returns:**

    A `HopfPoint`, fields of shape (n_osc,).

    **Raises:**

    `RuntimeError` if Newton's method fails for a mode (try another `guess`).
    """
    v, omega, slope, residual, steps, result = _hopf_modes(
        params, jnp.asarray(guess, dtype=float), rtol, atol)
    if not bool(jnp.all(result == optx.RESULTS.successful)) or not bool(jnp.all(v > 0)):
        raise RuntimeError(f"Newton's method did not find the Hopf point from v_d = {guess}; "
                           "try another guess")
    return HopfPoint(v_d=v, omega=omega, slope=slope, residual=residual, newton_steps=steps)
