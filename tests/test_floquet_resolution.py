"""What Floquet multipliers the computed monodromy matrix resolves, and its
determinant by Liouville's formula, against an independent scipy integral."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import eq1_mu, reference_rhs, scipy_slip_arc


def scipy_liouville(params: jc.ChainParams, eps: float, y0, period: float) -> float:
    """The integral of the trace of eq. (5)'s Jacobian over [0, period] along the
    orbit from y0, by scipy (DOP853, rtol 1e-12) on eq. (5) written out
    (`reference_rhs`) with the trace beside it, written out too: each
    oscillator's -2 xi + dF/dv, F = -mu(|w|) tanh(w / eps), w = v - v_d and
    mu of eq. (1)."""
    n, law = params.n_osc, params.friction
    mu = eq1_mu(params)
    rhs = reference_rhs(params, eps)

    def dforce(w):
        dmu = -(law.mu_st - law.mu_d) / law.v0 * np.exp(-abs(w) / law.v0)
        return (-dmu * np.sign(w) * np.tanh(w / eps)
                - mu(abs(w)) * (1 - np.tanh(w / eps) ** 2) / eps)

    def augmented(t, z):
        v = z[n:2 * n]
        trace = sum(-2 * params.xi + dforce(v[i] - params.v_d) for i in range(n))
        return np.concatenate([rhs(t, z[:2 * n]), [trace]])

    sol = solve_ivp(augmented, (0.0, period), np.concatenate([np.ravel(y0), [0.0]]),
                    method="DOP853", rtol=1e-12, atol=1e-12)
    return float(sol.y[-1, -1])


@pytest.mark.numerics
@pytest.mark.parametrize(("eps", "truth"), [(1e-2, 3.9e-12), (1e-3, 5.8e-124)])
def test_the_stick_slip_cycles_vanishing_multiplier_is_unresolved(eps, truth):
    """The stable stick-slip cycle of one oscillator (v_d 1.5): its non-trivial
    multiplier is det M (Liouville), 3.9e-12 at eps 1e-2 and 5.8e-124 at eps
    1e-3, far below what a monodromy computed at rtol 1e-10 resolves; the
    eigenvalue of the computed matrix is noise (-7.5e-11 at eps 1e-2: a sign that
    the cycle cannot have; 3.9e-11 at eps 1e-3). It is reported unresolved, below
    the bound, and the determinant by Liouville's formula matches the scipy
    integral (measured: 4.6e-9 and 4.8e-8 relative)."""
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    arc = scipy_slip_arc(params)  # the non-smooth cycle's turning point: the guess
    x_turn = float(arc.y_events[1][0, 0])
    period = float(arc.t[-1]) + (float(arc.y[0, 0]) - float(arc.y[0, -1])) / params.v_d
    orbit = jc.periodic_orbit(params, (jnp.array([[x_turn], [0.0]]), period),
                              jc.Shooting(jc.Smoothed(eps=eps).for_orbits()))
    assert bool(orbit.converged) and int(orbit.n_halc) == 1
    values, resolved = np.asarray(orbit.multipliers), np.asarray(orbit.resolved)
    trivial = int(orbit.trivial)
    bound = float(orbit.multiplier_resolution)
    assert resolved[trivial] and abs(values[trivial] - 1) < 1e-6
    # nothing negative (nor anything else) is reported resolved but the trivial one
    assert not np.any(np.delete(resolved, trivial))
    assert np.all(np.abs(np.delete(values, trivial)) <= bound)
    assert np.all((np.abs(values) > bound) == resolved)
    assert 0 < bound < 1e-6
    log_det = scipy_liouville(params, eps, orbit.y0, float(orbit.period))
    assert np.exp(log_det) == pytest.approx(truth, rel=0.02)  # the figures
    assert float(orbit.monodromy_determinant) == pytest.approx(np.exp(log_det), rel=1e-6)
    # the determinant lies below the bound: the cycle's second multiplier is
    # resolved only through Liouville's formula
    assert float(orbit.monodromy_determinant) < bound


@pytest.mark.numerics
@pytest.mark.parametrize("n_osc", [1, pytest.param(2, marks=pytest.mark.study)])
def test_the_determinant_is_the_product_of_resolved_multipliers(n_osc):
    """On the small cycle near the Hopf point (pure slip: no stick band, every
    multiplier resolved), Liouville's determinant equals the product of the
    multipliers and the scipy integral of the trace."""
    method = jc.Shooting()
    orbit = jc.hopf_cycle(jc.ChainParams(n_osc=n_osc), offset=0.01, method=method)
    values = np.asarray(orbit.multipliers)
    assert np.all(np.asarray(orbit.resolved))
    assert float(orbit.multiplier_resolution) < 1e-6
    det = float(orbit.monodromy_determinant)
    assert abs(np.prod(values) / det - 1) < 1e-6
    log_det = scipy_liouville(orbit.params, float(method.engine.eps), orbit.y0, float(orbit.period))
    assert det == pytest.approx(np.exp(log_det), rel=1e-8)
