"""Stability of steady sliding and its Hopf boundary, against the analytic results
of shared/DESIGN.md and finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import eq1_mu


@pytest.mark.numerics
def test_modal_eigenvalues_are_the_spectrum_of_the_jacobian():
    for v_d in (1.0, 1.5):
        params = jc.ChainParams(n_osc=6, v_d=v_d, eta_c=0.2)
        modal = np.asarray(jc.steady_sliding_eigenvalues(params))  # the Fourier route
        full = np.linalg.eigvals(np.asarray(jc.Smoothed().jacobian(params)))
        assert max(np.abs(modal - e).min() for e in full) < 1e-12
        assert max(np.abs(full - e).min() for e in modal) < 1e-12


@pytest.mark.numerics
def test_hopf_point_is_the_analytic_one_for_every_mode():
    params = jc.ChainParams(n_osc=6, eta_c=0.2)  # strong coupling: modes far apart
    hopf = jc.hopf_point(params)
    analytic = float(jc.hopf_vd_analytic(params))
    assert abs(analytic - 0.5 * np.log(10)) < 1e-15
    np.testing.assert_allclose(hopf.v_d, analytic, rtol=0, atol=1e-10)
    assert np.all(np.abs(hopf.residual) < 1e-12)
    # the frequencies differ by mode (coupling), the crossing does not
    k = np.arange(6)
    np.testing.assert_allclose(hopf.omega, np.sqrt(1 + 0.8 * np.sin(np.pi * k / 6) ** 2),
                               rtol=1e-12)


@pytest.mark.numerics
@pytest.mark.parametrize("eps", [0.25, 0.2])
def test_eps_correction_of_the_hopf_point(eps):
    """The Hopf point of the engine smoothed at eps lies below the closed form (eps
    -> 0) by the leading order of the smoothing, written here: tanh(v/eps) = 1 - 2
    exp(-2v/eps) and sech^2(v/eps) = 4 exp(-2v/eps) in F'(-v_d) = 2 xi give
    -v0 (2 + 2 mu(v_H) / (xi eps)) exp(-2 v_H / eps), v_H = v0 ln((mu_st - mu_d) /
    (2 xi v0))."""
    params = jc.ChainParams(n_osc=1)
    law, xi = params.friction, float(params.xi)
    v_h = law.v0 * np.log((law.mu_st - law.mu_d) / (2 * xi * law.v0))
    shift = float(jc.hopf_point(params, engine=jc.Smoothed(eps=eps)).v_d[0] - v_h)
    predicted = -law.v0 * (2 + 2 * eq1_mu(params)(v_h) / (xi * eps)) * np.exp(-2 * v_h / eps)
    assert shift < 0
    assert abs(shift - predicted) < 0.05 * abs(predicted)


@pytest.mark.numerics
def test_the_hopf_point_is_differentiable_in_the_engine_s_eps():
    """`jax.grad` of `hopf_vd` with respect to the eps of `Smoothed(eps=...)` (a
    traced leaf) against central differences of `hopf_vd` at eps +- 1e-5 (eps =
    0.2, where the shift is -5.6e-4)."""
    params = jc.ChainParams(n_osc=1)

    def hopf(eps):
        return jc.hopf_vd(params, engine=jc.Smoothed(eps=eps))

    grad = float(jax.grad(hopf)(0.2))
    fd = (float(hopf(0.2 + 1e-5)) - float(hopf(0.2 - 1e-5))) / 2e-5
    assert grad < 0 and abs(grad - fd) < 1e-6 * abs(fd)


@pytest.mark.numerics
def test_on_the_exact_engine_steady_sliding_is_the_limit_eps_to_0():
    """`Exact()`'s steady sliding (the slip law's slope, no smoothing): the Hopf point
    is the closed form v0 ln((mu_st - mu_d)/(2 xi v0)) = 0.5 ln 10 to 1e-12 on a
    mistuned open chain too (uniform damping and load), and the first Lyapunov
    coefficient of the single oscillator the closed form of sign() friction,
    F'''(-v_d)/8 = xi/(4 v0^2) = 0.05."""
    exact = jc.Exact()
    one = jc.ChainParams(n_osc=1)
    hopf = jc.hopf_point(one, engine=exact)
    assert abs(float(hopf.v_d[0]) - 0.5 * np.log(10)) < 1e-12
    at = jc.with_parameter(one, "v_d", hopf.v_d[0])
    l1 = float(jc.first_lyapunov_coefficient(at, engine=exact))
    assert abs(l1 - 0.05 / (4 * 0.5**2)) < 1e-10
    chain = jc.ChainParams(n_osc=3, boundary="free", stiffness=np.array([1.0, 1.1, 0.95]))
    assert abs(float(jc.hopf_vd(chain, engine=exact)) - 0.5 * np.log(10)) < 1e-12
    with pytest.raises(TypeError, match="engine"):
        jc.hopf_point(one, engine=1e-3)


@pytest.mark.numerics
def test_growth_rate_slope_and_hopf_sensitivity_against_finite_differences():
    params = jc.ChainParams(n_osc=1)
    hopf = jc.hopf_point(params)

    def growth(v):
        return float(jc.growth_rates(eqx.tree_at(lambda p: p.v_d, params, v))[0])

    v, h = float(hopf.v_d[0]), 1e-6
    assert abs(float(hopf.slope[0]) - (growth(v + h) - growth(v - h)) / (2 * h)) < 1e-8
    # implicit differentiation through optimistix's Newton method
    _, d_xi = jax.jvp(lambda xi: jc.hopf_vd(eqx.tree_at(lambda p: p.xi, params, xi)),
                      (jnp.asarray(0.05),), (jnp.asarray(1.0),))
    fd = (float(jc.hopf_vd(eqx.tree_at(lambda p: p.xi, params, 0.05 + 1e-6)))
          - float(jc.hopf_vd(eqx.tree_at(lambda p: p.xi, params, 0.05 - 1e-6)))) / 2e-6
    assert abs(float(d_xi) - fd) < 1e-6 * abs(fd)
    assert abs(float(d_xi) - (-params.friction.v0 / params.xi)) < 1e-9


@pytest.mark.numerics
@pytest.mark.parametrize("xi", [0.05, 0.02])
def test_first_lyapunov_coefficient_is_the_analytic_one(xi):
    single = jc.ChainParams(n_osc=1, xi=xi)
    single = eqx.tree_at(lambda p: p.v_d, single, jc.hopf_point(single).v_d[0])
    l1 = float(jc.first_lyapunov_coefficient(single))
    assert abs(l1 - xi / (4 * single.friction.v0**2)) < 1e-10  # subcritical
    ring = jc.ChainParams(n_osc=4, xi=xi)
    ring = eqx.tree_at(lambda p: p.v_d, ring, jc.hopf_point(ring).v_d[0])
    assert abs(float(jc.first_lyapunov_coefficient(ring)) - l1 / 4) < 1e-10


def test_bad_arguments():
    with pytest.raises(ValueError, match="xi"):
        jc.hopf_vd_analytic(jc.ChainParams(xi=0.0))
    with pytest.raises(ValueError, match="mode"):
        jc.first_lyapunov_coefficient(jc.ChainParams(n_osc=4), mode=1)
