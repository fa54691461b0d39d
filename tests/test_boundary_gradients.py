"""Derivatives of the Hopf point of steady sliding on every kind of structure (a
2-D pad with its own masses and damping, a mistuned ring, a line with a measured
friction table), in forward and reverse mode, against central differences: the
implicit function theorem on Re lambda = 0, never an eigenvector's derivative."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc

#: The 2 x 3 pad of issue 81: its own masses and damping ratios.
PAD = jc.ChainParams(graph=jc.Graph.lattice(2, 3, "free"),
                     mass=jnp.array([1.0, 1.05, 1.1, 1.15, 1.2, 0.95]),
                     xi=jnp.array([0.05, 0.055, 0.05, 0.06, 0.05, 0.052]),
                     load=jnp.array([1.0, 1.0, 0.95, 1.0, 1.05, 1.0]),
                     stiffness=jnp.array([1.0, 1.02, 0.98, 1.0, 1.01, 0.99]))


def _eq1_table() -> jc.Tabulated:
    """A measured friction curve: eq. (1) sampled at 21 speeds, with a small bump."""
    v = np.linspace(0.0, 4.0, 21)
    return jc.Tabulated(v=v, mu=0.5 + 0.5 * np.exp(-v / 0.5) + 0.005 * np.sin(v))


def _pad(theta):
    eta_c, mass2, xi3, load1, k4, mu_st, v0 = theta
    law = jc.ExponentialDecay(mu_st=mu_st, mu_d=0.5, v0=v0)
    return eqx.tree_at(
        lambda p: (p.eta_c, p.mass, p.xi, p.load, p.stiffness, p.friction), PAD,
        (eta_c, PAD.mass.at[2].set(mass2), PAD.xi.at[3].set(xi3),
         PAD.load.at[1].set(load1), PAD.stiffness.at[4].set(k4), law))


def _mistuned(theta):
    eta_c, xi, k2 = theta
    ring = jc.mistune(jc.ChainParams(n_osc=5), 0.05, seed=3)
    return eqx.tree_at(lambda p: (p.eta_c, p.xi, p.stiffness), ring,
                       (eta_c, xi, jnp.asarray(ring.stiffness).at[2].set(k2)))


def _tabulated(theta):
    xi, mu5, mu7 = theta
    law = _eq1_table()
    line = jc.ChainParams(n_osc=3, boundary="free", friction=law)
    return eqx.tree_at(lambda p: (p.xi, p.friction.mu), line,
                       (xi, jnp.asarray(law.mu).at[5].set(mu5).at[7].set(mu7)))


CASES = {
    "pad": (_pad, [0.01, 1.1, 0.06, 1.0, 1.01, 1.0, 0.5]),
    "mistuned ring": (_mistuned, [0.01, 0.05, 1.0]),
    "friction table": (_tabulated, [0.05, None, None]),
}


def _central_differences(f, theta, h=1e-5):
    """Fourth-order central differences of a scalar function, one column a
    parameter: truncation O(h^4), rounding about Newton's tolerance 1e-12 / h; a
    small step, as the leading eigenvalue may change hands nearby (a kink)."""
    out = []
    for i in range(theta.size):
        e = np.zeros_like(theta)
        e[i] = h * max(1.0, abs(theta[i]))
        f1 = float(f(theta + e)) - float(f(theta - e))
        f2 = float(f(theta + 2 * e)) - float(f(theta - 2 * e))
        out.append((8 * f1 - f2) / (12 * e[i]))
    return np.asarray(out)


@pytest.mark.numerics
@pytest.mark.parametrize("case", ["pad", *(pytest.param(c, marks=pytest.mark.study)
                                           for c in ("mistuned ring", "friction table"))])
def test_hopf_point_derivatives_on_every_structure(case):
    build, theta = CASES[case]
    if case == "friction table":
        mu = np.asarray(_eq1_table().mu)
        theta = [theta[0], mu[5], mu[7]]
    theta = np.asarray(theta, dtype=float)
    params = build(theta)
    assert jc.hopf_point(params).v_d.shape == (1,)  # the eigenvalue route, not by mode

    def hopf(t):
        return jc.hopf_vd(build(t))

    fd = _central_differences(hopf, theta)
    forward = np.asarray(jax.jacfwd(hopf)(jnp.asarray(theta)))
    reverse = np.asarray(jax.grad(hopf)(jnp.asarray(theta)))
    assert np.all(np.isfinite(fd)) and np.any(np.abs(fd) > 1e-3)
    np.testing.assert_allclose(forward, fd, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(reverse, forward, rtol=1e-12, atol=1e-14)


@pytest.mark.numerics
def test_hopf_frequency_derivative_on_a_pad_against_finite_differences():
    """omega at the Hopf point differentiates too (its eigenvalue, not its
    eigenvector); slope is a diagnostic held constant."""
    theta = np.asarray(CASES["pad"][1])

    def omega(t):
        return jc.hopf_point(_pad(t), throw=False).omega[0]

    fd = _central_differences(omega, theta)
    np.testing.assert_allclose(np.asarray(jax.grad(omega)(jnp.asarray(theta))), fd,
                               rtol=1e-5, atol=1e-9)


def test_hopf_point_prints_its_values():
    text = repr(jc.hopf_point(jc.ChainParams(n_osc=1)))
    assert "1.1512925" in text and "f64[" not in text


def _fold_structures():
    """Single oscillators of the structures `boundaries --chain` takes (its fold is
    that of the chain's first oscillator on its own): a pad's sector with its own
    mass, damping and load; a mistuned ring's oscillator. Each with the
    parameters differentiated, as a vector. (A measured table's limit cycles are
    not continued to their fold: its monotone cubic interpolant is only C^1, and
    the branch's Newton steps fail before the fold.)"""
    pad = jc.single_oscillator(PAD.__class__(graph=PAD.graph, mass=PAD.mass.at[0].set(1.02),
                                             xi=PAD.xi.at[0].set(0.051),
                                             load=PAD.load.at[0].set(0.98)))
    mistuned = jc.single_oscillator(jc.mistune(jc.ChainParams(n_osc=5), 0.02, seed=3))
    return {
        "pad sector": (pad, lambda q, t: eqx.tree_at(lambda p: (p.mass, p.xi, p.load), q,
                                                     tuple(t)), [1.02, 0.051, 0.98]),
        "mistuned ring": (mistuned, lambda q, t: eqx.tree_at(lambda p: (p.stiffness, p.xi), q,
                                                             tuple(t)),
                          [float(mistuned.stiffness), 0.05]),
    }


@pytest.mark.study
@pytest.mark.long
@pytest.mark.numerics
@pytest.mark.parametrize("case", ["pad sector", "mistuned ring"])
def test_fold_derivatives_on_every_structure(case):
    """The fold of limit cycles of each structure's oscillator (from its own Hopf
    point, continued through the fold, refined by the Moore-Spence system):
    `jax.jacfwd` and `jax.grad` of the fold's belt speed against central
    differences of the fold solved again (`solve_fold`)."""
    base, build, theta = _fold_structures()[case]
    theta = np.asarray(theta, dtype=float)
    problem = jc.cycle_problem(jc.hopf_cycle(base))
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.01, ds_max=0.1, p_min=0.5, p_max=3.0, max_points=60))
    fold = jc.fold_point(problem, branch)
    start = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    n = problem.u0.size

    def fold_vd(t):
        solution, _ = jc.solve_fold(problem.with_params(build(base, t)), start)
        return solution[n]

    assert abs(float(fold_vd(theta)) - float(fold.p)) < 1e-8
    fd = _central_differences(fold_vd, theta, h=1e-6)
    forward = np.asarray(jax.jacfwd(fold_vd)(jnp.asarray(theta)))
    reverse = np.asarray(jax.grad(fold_vd)(jnp.asarray(theta)))
    assert np.all(np.isfinite(fd))
    np.testing.assert_allclose(forward, fd, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(reverse, forward, rtol=1e-10, atol=1e-12)


def _scipy_hopf_vd(params) -> float:
    """The Hopf belt speed by an independent route: scipy's brentq on the largest
    real part of NumPy's eigenvalues of the Jacobian at steady sliding, bracketed,
    no Newton method and no JAX derivative."""
    from scipy.optimize import brentq

    def growth(v):
        jac = np.asarray(jc.Smoothed().jacobian(jc.with_parameter(params, "v_d", v)))
        return float(np.max(np.linalg.eigvals(jac).real))

    return brentq(growth, 0.9, 1.4, xtol=1e-15, rtol=1e-15, maxiter=200)


@pytest.mark.numerics
def test_pad_hopf_gradient_against_scipy_central_differences():
    """On the 2 x 3 pad: `jax.grad` and `jax.jacfwd` of `hopf_vd` in eta_c, a mass
    and a damping ratio against central differences of the scipy root."""

    def hopf(t):
        return jc.hopf_vd(_pad(t))

    picked = [0, 1, 2]  # eta_c, mass_2, xi_3
    full = np.asarray(CASES["pad"][1], dtype=float)
    fd = []
    for i in picked:
        e = np.zeros_like(full)
        e[i] = 1e-5 * max(1.0, abs(full[i]))
        f1 = _scipy_hopf_vd(_pad(full + e)) - _scipy_hopf_vd(_pad(full - e))
        f2 = _scipy_hopf_vd(_pad(full + 2 * e)) - _scipy_hopf_vd(_pad(full - 2 * e))
        fd.append((8 * f1 - f2) / (12 * e[i]))
    reverse = np.asarray(jax.grad(hopf)(jnp.asarray(full)))[picked]
    forward = np.asarray(jax.jacfwd(hopf)(jnp.asarray(full)))[picked]
    assert abs(_scipy_hopf_vd(_pad(full)) - float(hopf(full))) < 1e-12
    np.testing.assert_allclose(reverse, fd, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(forward, fd, rtol=1e-5, atol=1e-9)
