"""Periodic orbits by shooting and their Floquet multipliers, against long
simulations, scipy and finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import SHORT, reference_rhs, scipy_stick_slip_cycle


def scipy_flow(params, y, period):
    sol = solve_ivp(reference_rhs(params), (0.0, period), np.ravel(y), method="DOP853",
                    rtol=1e-12, atol=1e-13)
    return sol.y[:, -1]


@pytest.mark.numerics
def test_stable_stick_slip_cycle_agrees_with_long_simulation():
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    obs = jc.simulate(params, jnp.array([[2.0], [0.0]]), options=SHORT)
    orbit = jc.periodic_orbit(params, (obs.y_final, 6.3))
    assert bool(orbit.converged) and bool(orbit.stable)
    assert abs(float(orbit.amplitudes[0] / obs.amplitudes[0]) - 1) < 1e-3
    assert int(orbit.n_halc) == 1
    assert abs(complex(orbit.multipliers[orbit.trivial]) - 1) < 1e-6
    # an independent integrator returns to the start after one period
    back = scipy_flow(params, orbit.y0, float(orbit.period))
    assert np.max(np.abs(back - np.ravel(orbit.y0))) < 1e-6
    # the smoothed period is near the non-smooth cycle's (difference O(eps))
    _, period = scipy_stick_slip_cycle(params)
    assert abs(float(orbit.period) / period - 1) < 1e-3


@pytest.mark.numerics
@pytest.mark.parametrize("state", ["stick-slip", "steady sliding"])
def test_n_halc_agrees_between_simulation_shooting_and_reference(state):
    """One definition of the HALC (`jc.sticks`) for the smoothed run, shooting and
    the non-smooth reference. At v_d = 1.5 the single oscillator is bistable
    (v_d,H = 1.15): from x = 2 it reaches the stick-slip cycle, on the HALC for all
    three; at steady sliding (an equilibrium, a periodic orbit of any period) it
    stays at slip speed v_d, on the HALC for none."""
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    sliding = state == "steady sliding"
    y0 = jc.Exact().steady_sliding(params) if sliding else jnp.array([[2.0], [0.0]])
    obs = jc.simulate(params, y0, options=SHORT)
    ref = jc.simulate(params, y0, engine=jc.Exact(jc.NonsmoothOptions.reference(
        t_end=SHORT.t_end, transient=SHORT.transient)))
    if sliding:
        shooting_unknowns = jnp.concatenate([jnp.ravel(y0), jnp.array([2 * np.pi])])
        orbit = jc.Shooting().describe(shooting_unknowns, params)
    else:
        orbit = jc.periodic_orbit(params, (obs.y_final, 6.3))
    expected = 0 if sliding else 1
    assert int(obs.n_halc) == int(orbit.n_halc) == int(ref.n_halc) == expected
    if sliding:  # both models rest at x' = 0
        assert np.allclose([obs.min_slip_speed[0], ref.min_slip_speed[0]], 1.5)
    else:  # stick: inside the band, and exactly zero without smoothing
        assert 0 < float(obs.min_slip_speed[0]) < 3.0 * float(jc.Smoothed().eps)
        assert float(ref.min_slip_speed[0]) == 0.0


@pytest.mark.numerics
def test_small_hopf_cycle_monodromy_against_finite_differences():
    params = jc.ChainParams(n_osc=1)
    orbit = jc.hopf_cycle(params, offset=0.01)
    v_h = float(jc.hopf_vd_analytic(params))
    assert abs(float(orbit.params.v_d) - (v_h + 0.01)) < 1e-12  # subcritical side
    # normal form of the subcritical Hopf: A = sqrt(8 v0 (v_d - v_d,H))
    assert abs(float(orbit.amplitudes[0]) / np.sqrt(8 * 0.5 * 0.01) - 1) < 0.03
    assert not bool(orbit.stable) and float(abs(orbit.critical_multiplier)) > 1
    monodromy = np.asarray(jc.Shooting().monodromy(orbit.params, orbit.y0, orbit.period))
    h, y, T = 1e-6, np.ravel(orbit.y0), float(orbit.period)
    fd = np.stack([(scipy_flow(orbit.params, y + h * e, T) - scipy_flow(orbit.params, y - h * e, T))
                   / (2 * h) for e in np.eye(2)], axis=1)
    np.testing.assert_allclose(monodromy, fd, rtol=0, atol=1e-6)
    assert abs(complex(orbit.multipliers[orbit.trivial]) - 1) < 1e-6


@pytest.mark.numerics
def test_shooting_jacobian_against_finite_differences():
    params = jc.ChainParams(n_osc=2, v_d=1.5, eta_c=0.1)
    method = jc.Shooting()
    u = jnp.array([1.2, 0.9, 0.0, 0.3, 6.3])

    def residual(z):
        return method.residual(z, params)

    jac = jax.jacfwd(residual)(u)
    h = 1e-6
    fd = jnp.stack([(residual(u + h * e) - residual(u - h * e)) / (2 * h)
                    for e in jnp.eye(5)], axis=1)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6)


def test_bad_arguments():
    params = jc.ChainParams(n_osc=1)
    with pytest.raises(ValueError, match="y0"):
        jc.periodic_orbit(params, (jnp.zeros((2, 3)), 6.3))
    with pytest.raises(ValueError, match="period"):
        jc.periodic_orbit(params, (jnp.zeros((2, 1)), -1.0))
    with pytest.raises(ValueError, match="rtol"):
        jc.Shooting(jc.Smoothed().for_orbits(rtol=0.0))
    with pytest.raises(RuntimeError, match="Shooting did not converge"):
        jc.periodic_orbit(params, (jnp.array([[50.0], [0.0]]), 1.0),
                          jc.Shooting(newton_steps=3, damped_steps=0))


def test_the_method_takes_another_phase_oscillator_and_keeps_the_rest():
    """`with_phase_oscillator` (the snake shoots each start on its own oscillator)
    changes that one static field and nothing else; an engine at simulation
    tolerances is refused, with the way to tighten it."""
    method = jc.Shooting(jc.Exact().for_orbits(), newton_steps=7)
    moved = method.with_phase_oscillator(2)
    assert moved.phase_oscillator == 2 and moved.newton_steps == 7
    assert moved.engine == method.engine
    with pytest.raises(ValueError, match="for_orbits"):
        jc.Shooting(jc.Smoothed())  # rtol 3e-5 at eps 1e-3: too loose


@pytest.mark.numerics
@pytest.mark.parametrize("n_osc", [1, 2])
@pytest.mark.study
def test_deflated_multipliers_obey_liouville(n_osc):
    """The non-trivial multipliers come from the monodromy matrix with the flow
    direction deflated; their product times the trivial one is det M, which
    Liouville's formula gives as exp(integral of tr J over the period). On the
    small Hopf cycle (pure slip, smooth tr J) that integral is taken by Simpson's
    rule along scipy's orbit, independently of the monodromy."""
    from scipy.integrate import simpson
    orbit = jc.hopf_cycle(jc.ChainParams(n_osc=n_osc), offset=0.01)
    T = float(orbit.period)
    ts = np.linspace(0.0, T, 8001)
    sol = solve_ivp(reference_rhs(orbit.params), (0.0, T), np.ravel(orbit.y0),
                    method="DOP853", rtol=1e-12, atol=1e-13, t_eval=ts)
    smoothed = jc.Smoothed()
    traces = jax.vmap(lambda y: jnp.trace(smoothed.jacobian(orbit.params,
                                                            jnp.reshape(y, (2, -1)))))(
        jnp.asarray(sol.y.T))
    det = np.exp(simpson(np.asarray(traces), x=ts))
    values = np.asarray(orbit.multipliers)
    assert abs(values[int(orbit.trivial)] - 1) < 1e-6
    assert abs(np.prod(values).real / det - 1) < 1e-6
    assert abs(np.prod(values).imag) < 1e-9
    # the deflated spectrum is the full one without the multiplier at 1
    full = np.linalg.eigvals(np.asarray(jc.Shooting().monodromy(orbit.params, orbit.y0,
                                                                orbit.period)))
    others = np.delete(full, np.argmin(np.abs(full - 1)))
    nontrivial = np.delete(values, int(orbit.trivial))
    for m in nontrivial:
        assert np.min(np.abs(others - m)) < 1e-6 * max(1.0, abs(m))
