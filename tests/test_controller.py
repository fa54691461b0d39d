"""The step-size controller (`PIController`): its rules against the formulas of its
docstring, and its solutions against scipy and against diffrax's controller."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import flat, reference_rhs
from jaxchain._engine.solver.controller import CONTROLLERS, PIController


RTOL, ATOL = 1e-4, 1e-6


def _adapt(controller, state, dt, err, y=1.0):
    """One call of adapt_step_size on a scalar state y with a scaled error `err`."""
    y0 = jnp.array([y])
    y_error = jnp.array([err * (ATOL + RTOL * y)])
    return controller.adapt_step_size(0.0, dt, y0, y0, None, y_error, 3, state)


def _state(prev_err=1.0):
    return ((jnp.asarray(1.0 / prev_err), jnp.asarray(1.0), False), jnp.asarray(0.0),
            jnp.asarray(0.0))


@pytest.mark.numerics
def test_accepted_step_follows_the_pi_rule_and_may_shrink():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, t0, t1, _, state, _ = _adapt(c, _state(prev_err=0.5), 0.1, 0.95)
    expected = 0.1 * 0.9 * 0.95 ** (-(0.5 + 0.2) / 3) * 0.5 ** (0.2 / 3)
    assert bool(keep) and float(t0) == 0.1
    assert np.isclose(float(t1 - t0), expected, rtol=1e-12)
    assert float(t1 - t0) < 0.1  # diffrax's controller would keep 0.1
    _, _, t1_diffrax, _, _, _ = diffrax.PIDController(rtol=RTOL, atol=ATOL).adapt_step_size(
        0.0, 0.1, jnp.array([1.0]), jnp.array([1.0]), None,
        jnp.array([0.95 * (ATOL + RTOL)]), 3, (jnp.asarray(1.0), jnp.asarray(1.0), False))
    assert float(t1_diffrax) - 0.1 == pytest.approx(0.1)


@pytest.mark.numerics
def test_second_rejection_uses_the_observed_order():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, t0, t1, _, state, _ = _adapt(c, _state(), 0.05, 2.65)
    assert not bool(keep) and float(t0) == 0.0
    first = float(t1)  # the asymptotic order 3: 0.9 * 2.65^(-1/3)
    assert np.isclose(first, 0.05 * 0.9 * 2.65 ** (-1 / 3), rtol=1e-12)
    keep, t0, t1, _, state, _ = _adapt(c, state, first, 2.37)
    q = np.log(2.65 / 2.37) / np.log(0.05 / first)
    assert q < 0.5  # the error hardly fell: the order is clipped to min_order
    assert not bool(keep)
    factor = max(c.factormin, 0.9 * 2.37 ** (-1 / 0.5))  # clipped to [factormin, safety]
    assert np.isclose(float(t1), first * factor, rtol=1e-12)
    assert float(t1) < first * 0.9 * 2.37 ** (-1 / 3)  # smaller than order 3 would take
    # an accepted step clears the rejection memory
    keep, t0, t1, _, state, _ = _adapt(c, state, float(t1), 0.5)
    assert bool(keep) and float(state[1]) == 0.0 and float(state[2]) == 0.0


@pytest.mark.numerics
def test_rejection_with_a_nan_error_shrinks_by_factormin():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, _, t1, _, _, _ = _adapt(c, _state(), 0.1, np.nan)
    assert not bool(keep) and np.isclose(float(t1), 0.1 * c.factormin)


@pytest.mark.numerics
@pytest.mark.parametrize("controller", list(CONTROLLERS))
def test_solution_matches_scipy_within_the_tolerance(controller):
    """Three oscillators through stick-slip switches, t in [0, 60]: the final state
    against scipy's DOP853 at rtol 1e-12, within a bound set by rtol = 1e-7 (the
    global error of 60 time units with some 20 switches, a few hundred times the
    local tolerance)."""
    p = jc.ChainParams(n_osc=3, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(np.array([True, False, True]))(p)
    opts = jc.SimulationOptions(t_end=60.0, transient=0.0, rtol=1e-7, atol=1e-9,
                                controller=controller)
    obs = jc.simulate(p, y0, options=opts)
    ref = solve_ivp(reference_rhs(p), (0.0, 60.0), np.asarray(flat(y0)), method="DOP853",
                    rtol=1e-12, atol=1e-13)
    assert obs.status == jc.Status.ok
    assert np.allclose(flat(obs.y_final), ref.y[:, -1], atol=1e-7 * 1e3)


@pytest.mark.numerics
def test_both_controllers_give_the_same_localized_state():
    """The default controller and diffrax's, at the default tolerances: the same
    oscillators on the HALC and amplitudes within the cross-check's 1 %."""
    p = jc.ChainParams(n_osc=8, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(8, 2))(p)
    runs = [jc.simulate(p, y0, options=jc.SimulationOptions(
        t_end=600.0, transient=400.0, controller=c)) for c in ("pi", "diffrax")]
    assert int(runs[0].n_halc) == int(runs[1].n_halc) == 2
    assert np.allclose(runs[0].amplitudes, runs[1].amplitudes, rtol=1e-2,
                       atol=1e-2 * float(np.max(runs[1].amplitudes)))
