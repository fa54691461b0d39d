"""Stability of steady sliding and its Hopf boundary, against the analytic results
of shared/DESIGN.md and finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


@pytest.mark.numerics
def test_modal_eigenvalues_are_the_spectrum_of_the_jacobian():
    for v_d in (1.0, 1.5):
        params = jc.ChainParams(n_osc=6, v_d=v_d, eta_c=0.2)
        modal = np.asarray(jc.mode_eigenvalues(params)).ravel()
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
    params = jc.ChainParams(n_osc=1)
    shift = float(jc.hopf_point(params, eps=eps).v_d[0] - jc.hopf_vd_analytic(params))
    predicted = float(jc.hopf_eps_correction(params, eps))
    assert shift < 0
    assert abs(shift - predicted) < 0.05 * abs(predicted)


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
