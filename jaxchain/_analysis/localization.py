"""Linear (Anderson) localization of the undamped chain: the localization factor of
the infinite mistuned chain by transfer matrices, the weak-disorder estimate, and
the inverse participation ratio of the modes of a finite chain."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._physics.forces import stiffness_matrix
from .._errors import ValidationError


def passband_frequency(eta_c: float, theta) -> np.ndarray:
    """omega^2 = 1 + 2 eta_c (1 - cos theta) of the homogeneous chain: the squared
    frequency of the wave of phase theta per cell (0 <= theta <= pi spans the
    passband [1, 1 + 4 eta_c]). Dimensionless (eqs. (4)-(6))."""
    return 1.0 + 2.0 * eta_c * (1.0 - np.cos(np.asarray(theta, dtype=float)))


def weak_disorder_localization(sigma: float, eta_c: float, theta) -> np.ndarray:
    """gamma = sigma^2 / (8 eta_c^2 sin^2 theta): the localization factor per cell
    to second order in the disorder (Thouless' perturbation result, in the
    notation of Castanier & Pierre, J. Sound Vib. 183 (1995) 493-515, for
    stiffness deviations delta_n of standard deviation sigma). It holds for
    sigma << eta_c sin theta, away from the band edges (theta -> 0, pi, where it
    diverges) and from the band centre (theta = pi/2, where the Kappus-Wegner
    anomaly changes its coefficient)."""
    theta = np.asarray(theta, dtype=float)
    return sigma**2 / (8.0 * eta_c**2 * np.sin(theta) ** 2)


def _growth(deviations, a0, eta_c):
    """Sum of log |growth| of (x_n, x_(n-1)) under x_(n+1) = a_n x_n - x_(n-1),
    renormalized at each cell; deviations of shape (cells,)."""
    def step(carry, delta):
        x, x_prev = carry
        x_next = (a0 + delta / eta_c) * x - x_prev
        norm = jnp.hypot(x_next, x)
        return (x_next / norm, x / norm), jnp.log(norm)

    _, logs = jax.lax.scan(step, (jnp.asarray(1.0), jnp.asarray(0.0)), deviations)
    return logs


@functools.partial(jax.jit, static_argnames=("warmup", "cells", "batches"))
def _exponents(key, sigma, a0, eta_c, warmup, cells, batches):
    deviations = sigma * jax.random.normal(key, (batches, warmup + cells))
    logs = jax.vmap(_growth, in_axes=(0, None, None))(deviations, a0, eta_c)
    return jnp.mean(logs[:, warmup:], axis=1)


def localization_factor(eta_c: float, sigma: float, omega2, *, cells: int = 200_000,
                        batches: int = 16, warmup: int = 2000, seed: int = 0
                        ) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """The localization factor gamma (Lyapunov exponent per cell) of the infinite
    undamped chain x_n'' + (1 + delta_n) x_n + eta_c (2 x_n - x_(n-1) - x_(n+1)) = 0
    at the squared frequency `omega2`, delta_n independent normal of standard
    deviation `sigma` (the distribution of `mistune`): the growth rate of the
    product of the transfer matrices [[a_n, -1], [1, 0]], a_n = (1 + delta_n +
    2 eta_c - omega2) / eta_c (Castanier & Pierre, J. Sound Vib. 183 (1995)
    493-515; Furstenberg's theorem). An amplitude decays like exp(-gamma |n|)
    along the chain: 1/gamma is the localization length in cells.

    **Arguments:**

    - `eta_c`: coupling stiffness (a number; per-link coupling has no single
        transfer matrix).
    - `sigma`: standard deviation of delta_n, >= 0; at 0 the homogeneous chain's
        exact gamma = arccosh(|a| / 2) outside the passband and 0 inside (error 0).
    - `omega2`: squared frequencies, any shape (dimensionless; the passband is
        [1, 1 + 4 eta_c], `passband_frequency`).
    - `cells`: cells per estimate after `warmup` cells (the start vector's
        transient); `batches` independent estimates from the key `seed`.

    **Returns:**

    (gamma, error), each of the shape of `omega2`: the mean of the `batches`
    estimates and its standard error (the estimates are independent).

    **Raises:**

    `ValidationError` for eta_c <= 0, sigma < 0, or counts below 1 (batches below 2).
    """
    if not np.ndim(eta_c) == 0 or not float(eta_c) > 0:
        raise ValidationError(f"eta_c must be a number > 0, got {eta_c!r}")
    if not float(sigma) >= 0:
        raise ValidationError(f"sigma must be >= 0, got {sigma!r}")
    for name, value, least in (("cells", cells, 1), ("batches", batches, 2),
                               ("warmup", warmup, 0)):
        if int(value) != value or value < least:
            raise ValidationError(f"{name} must be an integer >= {least}, got {value!r}")
    omega2 = np.asarray(omega2, dtype=float)
    if float(sigma) == 0:
        a = np.abs(1.0 + 2.0 * eta_c - omega2) / eta_c
        return np.arccosh(np.maximum(a / 2, 1.0)), np.zeros_like(omega2)
    keys = jax.random.split(jax.random.key(seed), max(omega2.size, 1))
    gammas, errors = [], []
    for key, w2 in zip(keys, omega2.ravel()):
        a0 = (1.0 + 2.0 * eta_c - w2) / eta_c
        est = np.asarray(_exponents(key, float(sigma), a0, float(eta_c), warmup=int(warmup),
                                    cells=int(cells), batches=int(batches)))
        gammas.append(est.mean())
        errors.append(est.std(ddof=1) / np.sqrt(batches))
    return (np.reshape(gammas, omega2.shape), np.reshape(errors, omega2.shape))


def inverse_participation_ratio(params) -> tuple[np.ndarray, np.ndarray]:
    """The modes of the finite undamped chain (eigenvectors phi of
    `stiffness_matrix`, normalized) and their inverse participation ratio
    sum_n phi_n^4: 1/N for a mode spread evenly over N oscillators, 1 for a mode
    on one oscillator.

    **Returns:**

    (omega^2 of each mode, its IPR), shapes (n_osc,), by increasing omega^2.
    """
    values, vectors = np.linalg.eigh(np.asarray(stiffness_matrix(params)))
    return values, np.sum(vectors**4, axis=0)


def damped_decay(eta_c: float, omega2, damping: float) -> np.ndarray:
    """The decay per cell of the forced response of the homogeneous damped chain
    x_n'' + c x_n' + x_n + eta_c (2 x_n - x_(n-1) - x_(n+1)) = F e^(i omega t)
    delta_(n, 0): x_n ~ exp(-kappa |n|) with cosh(kappa + i phi) = a / 2,
    a = (1 + 2 eta_c - omega^2 + i omega c) / eta_c (the decaying root of the
    transfer matrix). With c = 2 xi + mu'(v_d) of steady sliding it is the
    envelope of a state localized by friction, whose neighbours slip about steady
    sliding (documentation, "Anderson meets friction"). Dimensionless.

    **Arguments:**

    - `eta_c`: coupling stiffness, > 0.
    - `omega2`: squared frequencies, any shape.
    - `damping`: c, the effective viscous damping of the neighbours.

    **Returns:**

    kappa, of the shape of `omega2`; at c = 0 it is the undamped chain's
    (0 in the passband).

    **Raises:**

    `ValidationError` for eta_c <= 0.
    """
    if not np.ndim(eta_c) == 0 or not float(eta_c) > 0:
        raise ValidationError(f"eta_c must be a number > 0, got {eta_c!r}")
    omega2 = np.asarray(omega2, dtype=float)
    a = (1.0 + 2.0 * eta_c - omega2 + 1j * np.sqrt(omega2) * damping) / eta_c
    return np.abs(np.real(np.arccosh(a / 2)))
