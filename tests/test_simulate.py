import diffrax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import (SHORT, TIGHT, assert_within_drift, flat, reference_rhs, scipy_slip_arc,
                     scipy_stick_slip_cycle)


def _near_steady_sliding(p):
    return jc.Exact().steady_sliding(p).at[0].add(0.01)


def _growth_rate(p):
    """Re(lambda) of steady sliding for eps -> 0: -(2 xi - mu'(v_d)) / 2."""
    mu_prime = (p.friction.mu_st - p.friction.mu_d) / p.friction.v0 * np.exp(-p.v_d / p.friction.v0)
    return -(2 * p.xi - mu_prime) / 2


@pytest.mark.numerics
@pytest.mark.parametrize("v_d, grows", [(2.0, False), (1.0, True)])
@pytest.mark.study
def test_single_oscillator_near_steady_sliding_decays_or_grows(v_d, grows):
    """Below the Hopf speed 1.1513 steady sliding is unstable, above it stable. The
    envelope follows exp(sigma t) with the analytic sigma; windows of 20 time units
    (3 periods) at t = 0 and t = 150 quantise the envelope by at most one period,
    2 pi/150 = 4 % of the log-ratio, hence the 10 % tolerance."""
    p = jc.ChainParams(n_osc=1, v_d=v_d)
    y0 = _near_steady_sliding(p)
    # the decaying deviation reaches 2e-5 at t = 150: tolerances far below it
    tol = {"rtol": 1e-8, "atol": 1e-10}
    early = jc.simulate(p, y0, options=jc.SimulationOptions(t_end=20.0, transient=0.0, **tol))
    late = jc.simulate(p, y0, options=jc.SimulationOptions(t_end=170.0, transient=150.0,
                                                           **tol))
    ratio = float(late.amplitudes[0] / early.amplitudes[0])
    assert (ratio > 5) if grows else (ratio < 0.2)
    assert np.isclose(np.log(ratio) / 150.0, _growth_rate(p), rtol=0.1)
    # a small oscillation about x' = 0 slips: its closest approach to the belt speed
    # is v_d - max x', far outside the stick band
    assert int(late.n_halc) == 0
    assert float(late.min_slip_speed[0]) == pytest.approx(v_d - float(late.v_max[0]))


def _dense_amplitude(p, y0, t_end, transient, dt):
    """Half peak-to-peak from a run stored densely (every dt), at tight tolerance."""
    ts = jnp.arange(transient, t_end + dt / 2, dt)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(lambda t, y, p: jc.Smoothed().field(p, y)), diffrax.Dopri8(), 0.0,
        t_end, None, y0, p,
        saveat=diffrax.SaveAt(ts=ts), max_steps=None,
        stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-13))
    x = np.asarray(sol.ys[:, 0])
    return 0.5 * (x.max(0) - x.min(0))


@pytest.mark.study
@pytest.mark.numerics
def test_amplitude_resolution_against_densely_saved_run():
    """Observed amplitudes agree with a run saved every 1e-3 to a relative 1e-3;
    sampling 10 times coarser than the default would not (it misses the peaks)."""
    p = jc.ChainParams(n_osc=3)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 1))(p)
    dense = _dense_amplitude(p, y0, 400.0, 200.0, 1e-3)
    opts = jc.SimulationOptions(t_end=400.0, transient=200.0, chunk_length=100.0)
    obs = jc.simulate(p, y0, options=opts)
    assert dense[1] > 1.0  # the excited oscillator is on the HALC
    assert np.allclose(obs.amplitudes, dense, rtol=1e-3)
    coarse = jc.simulate(p, y0, options=jc.SimulationOptions(
        t_end=400.0, transient=200.0, chunk_length=100.0, sample_dt=0.5))
    assert not np.allclose(coarse.amplitudes, dense, rtol=1e-3)


@pytest.mark.numerics
def test_trajectory_matches_scipy_dop853():
    """A second solver: scipy's DOP853 on an independent NumPy right-hand side."""
    p = jc.ChainParams(n_osc=3, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(np.array([True, False, True]))(p)
    opts = jc.SimulationOptions(t_end=60.0, transient=0.0, rtol=1e-11, atol=1e-13)
    obs = jc.simulate(p, y0, options=opts)
    ref = solve_ivp(reference_rhs(p), (0.0, 60.0), np.asarray(flat(y0)),
                    method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
    assert np.allclose(flat(obs.y_final), ref.y[:, -1], atol=1e-7)
    x = ref.sol(np.arange(0.0, 60.0, 1e-3))[:3]
    # peaks are sampled every 0.05: resolved to the documented relative 1e-3
    assert np.allclose(obs.amplitudes, 0.5 * (x.max(1) - x.min(1)), rtol=1e-3)


@pytest.mark.numerics
def test_single_oscillator_cycle_converges_to_nonsmooth_stick_slip_cycle():
    """The smoothed HALC of one oscillator at v_d = 1.5 sticks (n_HALC = 1) and its
    amplitude approaches the non-smooth stick-slip amplitude as eps -> 0: the error
    shrinks with eps and is below 1 % at the default eps (1e-3).

    Its stick phase lies in the stick band: in stick the smoothed friction balances
    the needed force f = x + 2 xi v_d at the slip speed eps artanh(f / mu_st),
    smallest at stick entry, where the non-smooth cycle (scipy) has f = 0.242,
    0.247 eps. The smoothed minimum approaches it as eps -> 0 (it lags the
    quasi-static value by the O(eps) time of settling into the band): within 10 %
    at eps = 1e-3, and well inside 3 eps at every eps."""
    p1 = jc.ChainParams(n_osc=1)
    reference = scipy_stick_slip_cycle(p1)[0]
    entry_force = scipy_slip_arc(p1).y[0, -1] + 2 * p1.xi * p1.v_d
    quasi_static = np.arctanh(entry_force / p1.friction.mu_st)  # in units of eps
    default = float(jc.Smoothed().eps)
    errors, slip_errors = {}, {}
    for eps in (1e-2, 3e-3, default):
        obs = jc.simulate(p1, jc.OutOfPhaseExcitation.eq8([True]),
                          engine=jc.Smoothed(options=SHORT, eps=eps))
        assert int(obs.n_halc) == 1
        errors[eps] = abs(float(obs.amplitudes[0]) / reference - 1)
        slip_errors[eps] = abs(float(obs.min_slip_speed[0]) / eps / quasi_static - 1)
    assert errors[default] < errors[3e-3] < errors[1e-2]
    assert errors[default] < 1e-2
    assert slip_errors[default] < slip_errors[3e-3] < slip_errors[1e-2]
    assert slip_errors[default] < 0.1


def test_sticks_on_constructed_velocity_signals():
    """The engines' stick criterion (`on_halc`) on velocity signals whose closest approach to
    the belt speed is known: a quasi-static stick phase below and above the belt
    speed (|v_rel| = eps artanh(f / mu_st) for the needed force f rising from 0.25
    to 0.999 mu_st), a small oscillation about x' = 0 (steady sliding), and
    constant slip speeds just inside and outside the band 3 eps."""
    eps, v_d = 1e-3, 1.5
    t = np.linspace(0.0, 2 * np.pi, 4001)  # holds t = pi/2
    stick = eps * np.arctanh(np.linspace(0.25, 0.999, t.size))
    signals = np.stack([v_d - stick, v_d + stick, 0.1 * np.sin(t),
                        np.full(t.size, v_d - 2.99 * eps), np.full(t.size, v_d + 3.01 * eps)], 1)
    # the engines' stick criterion (`on_halc`) on these velocities: the slip speeds
    # each lie at the band 3 eps of an engine whose eps puts them a relative 1e-12
    # inside it, and outside it for a 1e-12 smaller eps
    params = jc.ChainParams(n_osc=5, v_d=v_d)
    ys = np.stack([np.zeros_like(signals), signals], 1)
    expected = [eps * np.arctanh(0.25)] * 2 + [v_d - 0.1, 2.99 * eps, 3.01 * eps]
    for k, speed in enumerate(expected):
        inside = jc.Smoothed(eps=speed / 3.0 * (1 + 1e-12)).on_halc(params, ys)
        outside = jc.Smoothed(eps=speed / 3.0 * (1 - 1e-12)).on_halc(params, ys)
        assert bool(inside[k]) and not bool(outside[k]), k
    sticks = jc.Smoothed(eps=eps).on_halc(params, ys)
    assert np.asarray(sticks).tolist() == [True, True, False, True, False]
    # the band is where tanh(v_rel/eps) leaves sign(v_rel) by more than 0.5 %
    assert 1 - np.tanh(3.0) < 5e-3 < 1 - np.tanh(0.9 * 3.0)
    # the non-smooth limit (the exact engine): only an exactly zero slip speed counts
    exact = np.array([v_d, v_d + 1e-12, np.nan])
    ys = np.stack([np.zeros_like(exact), exact])[None]
    assert np.asarray(jc.Exact().on_halc(jc.ChainParams(n_osc=3, v_d=v_d), ys)).tolist() == [
        True, False, False]


@pytest.mark.numerics
def test_ring_symmetry_rotating_the_initial_condition_rotates_amplitudes():
    """The rotated run differs only by round-off in the error norm of the step-size
    controller, which moves its steps: the rotated amplitudes within the
    integration tolerance (`drift_bound`), at `TIGHT`."""
    p = jc.ChainParams(n_osc=6)
    mask = jc.excited_block(6, 2)
    tight = TIGHT
    a = jc.simulate(p, jc.OutOfPhaseExcitation.eq8(mask), options=tight)
    # a shift by 2 keeps the (-1)^n pattern, so the state is an exact rotation
    b = jc.simulate(p, jc.OutOfPhaseExcitation.eq8(np.roll(mask, 2)), options=tight)
    assert np.max(a.amplitudes) > 1.0 and np.min(a.amplitudes) < 0.5  # a localized state
    assert np.array_equal(b.on_halc, np.roll(a.on_halc, 2))
    assert_within_drift(b.amplitudes, np.roll(a.amplitudes, 2), tight,
                        [a.num_steps, b.num_steps], "amplitudes")


def test_failure_raises_with_advice_or_returns_status():
    p = jc.ChainParams(n_osc=2)
    tiny = jc.SimulationOptions(t_end=200.0, transient=100.0, max_steps=10)
    y0 = jc.OutOfPhaseExcitation.eq8([True, False])
    with pytest.raises(RuntimeError, match="max_steps_reached: ros34pw2 ran out of its 10 "
                                           "steps .* raise max_steps"):
        jc.simulate(p, y0, options=tiny)
    obs = jc.simulate(p, y0, options=tiny, throw=False)
    assert obs.status == jc.Status.max_steps_reached and np.all(np.isnan(obs.amplitudes))


@pytest.mark.study
@pytest.mark.numerics
def test_imex_kencarp_matches_an_explicit_solver():
    """KenCarp4 with the friction force implicit (`split_vector_field`) gives the
    single oscillator's stick-slip amplitude of Tsit5 at tight tolerances, within
    the integration tolerance of two solvers (`drift_bound`, which
    `assert_within_drift` holds below 1 % of the amplitude); a dropped or doubled
    friction term would change it by order one."""
    p = jc.ChainParams(n_osc=1)
    tight = jc.SimulationOptions(t_end=400.0, transient=200.0, rtol=1e-9, atol=1e-11)
    ic = jc.OutOfPhaseExcitation.eq8([True])
    a = jc.simulate(p, ic, diffrax.Tsit5(), tight)
    b = jc.simulate(p, ic, jc.SOLVERS["kencarp4"](), tight)
    assert_within_drift(a.amplitudes, b.amplitudes, tight, [a.num_steps, b.num_steps],
                        "amplitudes")


@pytest.mark.numerics
def test_n_halc_halves_split_the_window_where_scipy_first_sticks():
    """Below the Hopf point a perturbation of steady sliding grows (rate about
    (mu'(v_d) - 2 xi) / 2 = 0.018) into the stick-slip cycle. scipy (LSODA at rtol
    1e-9) finds the first stick (|x' - v_d| <= 3 eps) between the middle and the
    end of the observed window [300, 600] of `SHORT`: n_HALC is 0 over the first
    half and 1 over the second. (The perturbation, 1e-4, is well above the
    tolerance rtol |x| = 5e-6; one below it is not resolved and decays.)"""
    p = jc.ChainParams(n_osc=1, v_d=1.0)
    y0 = np.asarray(jc.Exact().steady_sliding(p)) + np.array([[1e-4], [0.0]])
    ref = solve_ivp(reference_rhs(p), (0.0, SHORT.t_end), y0.ravel(), method="LSODA",
                    rtol=1e-9, atol=1e-11, dense_output=True)
    ts = np.linspace(SHORT.transient, SHORT.t_end, 60001)
    first_stick = ts[np.argmax(np.abs(ref.sol(ts)[1] - p.v_d) <= 3.0 * float(jc.Smoothed().eps))]
    middle = 0.5 * (SHORT.transient + SHORT.t_end)
    assert middle + 20 < first_stick < SHORT.t_end - 20
    obs = jc.simulate(p, y0, options=SHORT)
    assert obs.n_halc_halves.tolist() == [0, 1] and int(obs.n_halc) == 1
