"""The event-driven non-smooth reference, checked against analytical results, scipy
and the energy balance."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import scipy_slip_arc, scipy_stick_slip_cycle


ONE = jc.ChainParams(n_osc=1)


def _stick_exit_state(p):
    return jnp.array([[p.friction.mu_st - 2 * p.xi * p.v_d], [p.v_d]])


@pytest.mark.numerics
def test_stick_exit_time_and_oscillator_match_the_stick_force_formula():
    """A ring whose oscillators all stick moves rigidly with the belt, so f_n grows
    at the rate v_d and the first to leave stick is the one of largest f_n(0), at
    t = (mu_st - f_n(0)) / v_d, with f_n = 2 xi v_d + x_n + eta_c (2 x_n - x_{n+1} -
    x_{n-1}) written out here."""
    p = jc.ChainParams(n_osc=3, eta_c=0.3)
    x = np.array([0.1, 0.4, -0.2])
    f = 2 * p.xi * p.v_d + x + p.eta_c * (2 * x - np.roll(x, 1) - np.roll(x, -1))
    first = int(np.argmax(f))
    t_exit = float((p.friction.mu_st - f[first]) / p.v_d)
    y0 = np.stack([x, np.full(3, p.v_d)])
    obs = jc.simulate(p, y0,
                      engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=t_exit + 0.1,
                                                                  transient=0.0)))
    logged = np.asarray(obs.log_osc) >= 0
    assert int(obs.log_osc[logged][0]) == first
    assert jc.SWITCH_KINDS[int(obs.log_kind[logged][0])] == "stick to slip"
    assert abs(float(obs.log_time[logged][0]) - t_exit) < 1e-10


@pytest.mark.numerics
def test_single_oscillator_cycle_matches_scipy():
    """Amplitude and period of the stick-slip cycle at v_d = 1.5 against scipy's
    DOP853 with events, to 1e-8 relative (the acceptance asks 1e-6)."""
    amplitude, period = scipy_stick_slip_cycle(ONE)
    obs = jc.simulate(ONE, _stick_exit_state(ONE),
                      engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=200.0, transient=100.0)))
    exits = np.asarray(obs.log_time)[np.asarray(obs.log_kind) == 0]
    assert float(obs.amplitudes[0]) == pytest.approx(amplitude, rel=1e-8)
    assert np.allclose(np.diff(exits), period, rtol=1e-8, atol=0)
    assert int(obs.n_halc) == 1 and float(obs.half_difference) < 1e-9


@pytest.mark.numerics
def test_energy_balance_over_a_long_run():
    """Friction work = change of mechanical energy + viscous dissipation, for a ring
    with a localized stick-slip state over 3000 time units. Measured: the residual is
    4.5e-10 of the friction work (3.5e-7 of 762, 3214 switches) at the default rtol =
    atol = 1e-12, and 2.3e-10 at 1e-13: it is the integration error of the smooth
    phases (switch_tol = 1e-10 or 1e-11 leaves it unchanged). Other rings of 4 (1 to
    4 excited, eq. (8) or (10), v_d = 1.3 to 1.7) give 4.9e-10 to 8.9e-10, the single
    oscillator 2.8e-11. The bound, 1e-9, leaves a factor of 2 on this case."""
    p = jc.ChainParams(n_osc=4)
    obs = jc.simulate(p, jc.OutOfPhaseExcitation.eq8(jc.excited_block(4, 2)),
                      engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=3000.0,
                                                                  transient=2000.0)))
    change = jc.mechanical_energy(p, obs.y_final) - jc.mechanical_energy(p, obs.y_initial)
    residual = change - (obs.friction_work - obs.viscous_dissipation)
    assert int(obs.num_events) > 1000  # many switches were crossed
    assert abs(float(residual)) < 1e-9 * float(obs.friction_work)


@pytest.mark.numerics
def test_identical_oscillators_switch_together_like_one():
    """A ring started with every oscillator in the same state has no coupling force:
    all oscillators switch at the same instants (simultaneous events) and each
    follows the single oscillator's cycle."""
    p = jc.ChainParams(n_osc=4)
    y0 = jnp.tile(_stick_exit_state(p), (1, 4))
    opt = jc.NonsmoothOptions.reference(t_end=200.0, transient=100.0)
    ring = jc.simulate(p, y0, engine=jc.Exact(opt))
    single = jc.simulate(ONE, _stick_exit_state(ONE), engine=jc.Exact(opt))
    assert np.allclose(ring.amplitudes, single.amplitudes[0], rtol=1e-9)
    assert int(ring.n_halc) == 4
    times = np.asarray(ring.log_time)
    times = times[np.isfinite(times)].reshape(-1, 4)
    assert np.all(np.ptp(times, axis=1) == 0) and np.all(np.diff(times[:, 0]) > 0)
    assert int(ring.num_events) == int(single.num_events)


@pytest.mark.numerics
def test_existence_limit_brackets_the_scipy_slip_arc():
    """Just below the limit the scipy slip arc returns to the belt speed; just above,
    it does not."""
    limit = jc.stick_slip_existence_limit(ONE)
    assert 1.5 < limit < 2.5
    below = scipy_slip_arc(jc.ChainParams(n_osc=1, v_d=limit - 1e-4))
    above = scipy_slip_arc(jc.ChainParams(n_osc=1, v_d=limit + 1e-4))
    assert below.status == 1 and above.status == 0


def test_existence_limit_rejects_a_bad_bracket():
    # no stick-slip cycle at the lower end (above the limit 1.8366)
    with pytest.raises(ValueError, match="bracket"):
        jc.stick_slip_existence_limit(ONE, lower=1.9, upper=2.5)
    # too low an upper end is raised until the cycle is lost there
    assert abs(jc.stick_slip_existence_limit(ONE, lower=1.2, upper=1.5, tol=1e-8)
               - jc.stick_slip_existence_limit(ONE, tol=1e-8)) < 1e-7


def test_failures_are_a_status_or_an_error():
    # the options of the single oscillator's cycle above: its compiled run
    opt = jc.NonsmoothOptions.reference(t_end=200.0, transient=100.0)
    bad = jnp.full((2, 1), jnp.nan)
    obs = jc.simulate(ONE, bad, engine=jc.Exact(opt), throw=False)
    assert obs.status == jc.Status.non_finite_state and int(obs.n_halc) == -1
    with pytest.raises(RuntimeError, match="non-finite"):
        jc.simulate(ONE, bad, engine=jc.Exact(opt))
    chatter = jc.NonsmoothOptions.reference(t_end=50.0, transient=0.0, max_events=2)
    obs = jc.simulate(ONE, _stick_exit_state(ONE), engine=jc.Exact(chatter), throw=False)
    assert obs.status == jc.Status.event_not_resolved and np.isnan(float(obs.energy))


@pytest.mark.parametrize("field,value", [("rtol", 0.0), ("switch_tol", -1.0),
                                         ("transient", 50.0), ("max_events", 0),
                                         ("solver", "rk4")])
def test_bad_options_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"NonsmoothOptions.{field}"):
        jc.NonsmoothOptions(t_end=50.0, **{field: value})


def _richardson(f, x, h):
    """Central differences of f at x, extrapolated from steps h and h/2: error
    O(h^4)."""
    def central(step):
        return (f(x + step) - f(x - step)) / (2 * step)

    return (4 * central(h / 2) - central(h)) / 3


@functools.cache
def _scipy_cycle_derivatives(v_d, xi, h):
    """d(amplitude, period)/d(v_d, xi) of the scipy cycle, shape (2, 2), by
    `_richardson` (once for both modes of the test)."""
    base = {"v_d": v_d, "xi": xi}
    return np.stack([_richardson(lambda x, name=name: np.array(scipy_stick_slip_cycle(
        jc.ChainParams(n_osc=1, **(base | {name: x})))), base[name], h)
        for name in ("v_d", "xi")], axis=1)


def _cycle(v_d, xi, options):
    """Amplitude and period of the single oscillator's stick-slip cycle by the exact
    engine (eq. (1), started at its stick exit): the amplitude over the window, the
    period between its last two stick-to-slip switches."""
    params = jc.ChainParams(n_osc=1, v_d=v_d, xi=xi)
    obs = jc.Exact(options).run(params, _stick_exit_state(params))
    exits = jnp.sort(jnp.where(obs.log_kind == 0, obs.log_time, -jnp.inf))
    return jnp.stack([obs.amplitudes[0], exits[-1] - exits[-2]])


@pytest.mark.numerics
@pytest.mark.parametrize("adjoint", ["reverse", "forward"])
@pytest.mark.study
def test_cycle_gradients_against_finite_differences_of_scipy(adjoint):
    """d(amplitude, period)/d(v_d, xi) of the stick-slip cycle (xi 0.05) at v_d 1.2,
    1.5, 1.7: reverse mode (`jax.jacrev`, checkpointed loops) and forward mode
    (`jax.jacfwd`) through every switch of the exact engine, against central
    differences of the independent scipy cycle (`scipy_stick_slip_cycle`, DOP853
    at 1e-12 with events), Richardson-extrapolated from h = 1e-4 and 5e-5: the
    truncation, O(h^4), and the noise, 1e-12 / h, both far below the 1e-4 relative
    asked (a plain central difference at h = 1e-4 is off by 1.2e-4 in d period /
    d xi at v_d 1.7, near the cycle's existence limit). The derivative of an event time is the
    implicit function theorem's, that of the amplitude x at a turning point's
    fixed time (x' = 0 there)."""
    options = jc.NonsmoothOptions.reference(t_end=40.0, transient=20.0, adjoint=adjoint)

    def cycle(v_d, xi, options):  # the value beside the derivative, from one program
        value = _cycle(v_d, xi, options)
        return value, value

    jac = jax.jit(jax.jacrev(cycle, argnums=(0, 1), has_aux=True) if adjoint == "reverse"
                  else jax.jacfwd(cycle, argnums=(0, 1), has_aux=True), static_argnums=2)
    h = 1e-4
    for v_d in (1.2, 1.5, 1.7):
        derivatives, value = jac(v_d, 0.05, options)
        got = np.stack([np.asarray(d) for d in derivatives], axis=1)
        value = np.asarray(value)
        ref = np.array(scipy_stick_slip_cycle(jc.ChainParams(n_osc=1, v_d=v_d, xi=0.05)))
        np.testing.assert_allclose(value, ref, rtol=1e-8)
        fd = _scipy_cycle_derivatives(v_d, 0.05, h)
        np.testing.assert_allclose(got, fd, rtol=1e-4, err_msg=f"v_d {v_d}")


@pytest.mark.numerics
@pytest.mark.parametrize("tol", [1e-6, 1e-9, 1e-12])
def test_a_slip_arc_that_barely_reaches_the_belt_speed_switches_there(tol):
    """A slip arc whose velocity rises only 1e-3 above v_d, for about 0.07 time
    units, shorter than a step at loose tolerances: the relative velocity falls
    through zero and rises again within one step, so that the guard is positive at
    both of its ends. The switch must still be found where scipy (DOP853, rtol
    1e-12, an event on x' = v_d) puts the crossing, to the accuracy that the
    tolerance gives a crossing at this shallow angle. Before
    the guard was checked inside each step (`_INTERIOR`), the engine slipped
    through it at rtol 1e-6 (no switch, or a later one)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq
    from helpers import eq1_mu

    p = jc.ChainParams(n_osc=1, v_d=1.5, xi=0.05)
    mu = eq1_mu(p)

    def slip(t, y):  # slip with x' < v_d (the engine's mode), continued beyond v_d
        return [y[1], -2 * p.xi * y[1] - y[0] + mu(abs(p.v_d - y[1]))]

    def peak_excess(x0, events=False):
        def crossing(t, y):
            return y[1] - p.v_d
        crossing.direction = 1

        def falling(t, y):  # the velocity's first maximum ends the search
            return slip(t, y)[1]
        falling.terminal, falling.direction = True, -1
        sol = solve_ivp(slip, (0.0, 20.0), [x0, 0.0], method="DOP853", rtol=1e-12,
                        atol=1e-12, events=[crossing, falling], dense_output=True)
        return sol if events else sol.y[1, -1] - p.v_d - 1e-3

    x0 = brentq(peak_excess, -1.0, -0.75, xtol=1e-14)  # from rest at x0 < 0
    sol = peak_excess(x0, events=True)
    t_cross = float(sol.t_events[0][0])
    obs = jc.simulate(p, jnp.array([[x0], [0.0]]), engine=jc.Exact(jc.NonsmoothOptions(
        rtol=tol, atol=tol, t_end=t_cross + 1.0, transient=0.0)))
    logged = np.asarray(obs.log_kind) >= 0
    assert logged.any(), "no switch: the slip arc went through v_d unseen"
    # a velocity error e moves a crossing at acceleration a by e / a: the dense
    # output (fourth order) is good to about 1e3 x tol after a few dozen steps
    a_cross = slip(t_cross, sol.sol(t_cross))[1]
    assert abs(float(obs.log_time[logged][0]) - t_cross) < 1e3 * tol / a_cross + 1e-9
