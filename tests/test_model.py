import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import flat, reference_rhs


@pytest.mark.numerics
@pytest.mark.parametrize("n_osc, v_d, eps", [(1, 1.5, 1e-2), (5, 0.8, 1e-3), (20, 2.0, 1e-2)])
def test_steady_sliding_is_a_fixed_point(n_osc, v_d, eps):
    p = jc.ChainParams(n_osc=n_osc, v_d=v_d)
    y = jc.Smoothed(eps=eps).steady_sliding(p)
    # x_n = F(-v_d) = mu(v_d) tanh(v_d/eps), independently of the code under test
    mu = p.friction.mu_d + (p.friction.mu_st - p.friction.mu_d) * np.exp(-v_d / p.friction.v0)
    assert np.allclose(y[0], mu * np.tanh(v_d / eps), rtol=1e-14)
    assert np.all(y[1] == 0)
    assert np.max(np.abs(jc.Smoothed(eps=eps).field(p, y))) < 1e-14
    # without eps, the unsmoothed law's fixed point: x_n = mu(v_d)
    assert np.allclose(jc.Exact().steady_sliding(p)[0], mu, rtol=1e-14)


@pytest.mark.numerics
def test_vector_field_matches_loop_reference_on_both_layouts():
    p = jc.ChainParams(n_osc=7, v_d=1.3)
    y = jax.random.normal(jax.random.key(0), (2, 7))
    expected = reference_rhs(p)(0.0, np.asarray(flat(y)))
    assert np.allclose(flat(jc.Smoothed().field(p, y)), expected, rtol=1e-13)
    assert np.allclose(jc.Smoothed().field(p, flat(y)), expected, rtol=1e-13)


def test_vector_field_rejects_wrong_shape():
    with pytest.raises(ValueError, match="shape"):
        jc.Smoothed().field(jc.ChainParams(n_osc=4), jnp.zeros((2, 3)))


@pytest.mark.numerics
@pytest.mark.parametrize("n_osc, eps", [(1, 1e-2), (2, 1e-2), (8, 1e-2), (8, 0.3)])
def test_steady_sliding_eigenvalues_match_analytic_damping(n_osc, eps):
    """Ring mode k has stiffness 1 + 2 eta_c (1 - cos(2 pi k / N)) and, for every k,
    damping 2 xi - dF/dv_rel at v_rel = -v_d. For eps -> 0, dF/dv_rel -> mu'(v_d) =
    (mu_st - mu_d)/v0 exp(-v_d/v0) (the Hopf condition of DESIGN.md)."""
    p = jc.ChainParams(n_osc=n_osc, v_d=1.4)
    s = p.v_d
    mu = p.friction.mu_d + (p.friction.mu_st - p.friction.mu_d) * np.exp(-s / p.friction.v0)
    law = p.friction
    slope = ((law.mu_st - law.mu_d) / law.v0 * np.exp(-s / law.v0) * np.tanh(s / eps)
             - mu / np.cosh(s / eps) ** 2 / eps)
    damping = 2 * p.xi - slope
    k = np.arange(n_osc)
    stiffness = 1 + 2 * p.eta_c * (1 - np.cos(2 * np.pi * k / n_osc))
    disc = np.sqrt((damping**2 / 4 - stiffness).astype(complex))
    analytic = np.concatenate([-damping / 2 + disc, -damping / 2 - disc])
    numeric = np.linalg.eigvals(np.asarray(jc.Smoothed(eps=eps).jacobian(p)))
    key = lambda z: np.round(z.imag, 9) + 1e3 * np.round(z.real, 9)  # noqa: E731
    assert np.allclose(sorted(numeric, key=key), sorted(analytic, key=key), atol=1e-10)
    if eps == 1e-2:  # the smoothing correction is exp(-2 v_d/eps): nil here
        mu_prime = (p.friction.mu_st - p.friction.mu_d) / p.friction.v0 * np.exp(-s / p.friction.v0)
        assert np.allclose(numeric.real, -(2 * p.xi - mu_prime) / 2, atol=1e-12)


@pytest.mark.numerics
def test_jacobian_matches_finite_differences_off_equilibrium():
    p = jc.ChainParams(n_osc=4)
    y = jc.Exact().steady_sliding(p) + 0.1 * jax.random.normal(jax.random.key(1), (2, 4))
    f = lambda z: np.asarray(jc.Smoothed().field(p, z))  # noqa: E731
    z, h = np.asarray(flat(y)), 1e-6
    fd = np.stack([(f(z + h * e) - f(z - h * e)) / (2 * h) for e in np.eye(8)], axis=1)
    assert np.allclose(jc.Smoothed().jacobian(p, y), fd, rtol=1e-6, atol=1e-7)
