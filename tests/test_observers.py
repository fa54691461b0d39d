"""Observers and the largest Lyapunov exponent, each against an independent
reference: analytic exponents of linear systems, the period of an orbit found by
shooting, scipy, and the memory of a shorter run. (The exponent of a system that is
no chain, Lorenz-63's published one, is in `test_solvers.py`, with the integrator's
other units.)"""


import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import reference_rhs


class _NoFriction(jc.AbstractFrictionLaw):
    """mu = 0: a chain with friction off (a user's law, `jc.AbstractFrictionLaw`)."""

    @classmethod
    def rules(cls):
        return {}

    def __call__(self, v_rel):
        return 0.0 * v_rel

    def static(self):
        return jnp.asarray(0.0)


@pytest.mark.numerics
def test_damped_linear_chain_has_every_exponent_at_minus_xi():
    """A ring with friction off: x'' + 2 xi x' + x + eta_c (2x - x_+ - x_-) = 0. Every
    mode is underdamped, with eigenvalues -xi +- i w_k: the largest exponent is -xi."""
    xi, eta = 0.05, 0.3
    params = jc.ChainParams(n_osc=5, xi=xi, eta_c=eta, friction=_NoFriction())
    options = jc.SimulationOptions(t_end=2000.0, transient=100.0, chunk_length=50.0,
                                   rtol=1e-8, atol=1e-10, sample_dt=1.0)
    y0 = jnp.array([[1.0, 0.0, -0.5, 0.2, 0.0], [0.0, 0.3, 0.0, 0.0, -0.1]])
    # the field is the ring's alone: no friction force at any state
    ring = np.stack([y0[1], -2 * xi * y0[1] - y0[0]
                     - eta * (2 * y0[0] - np.roll(y0[0], 1) - np.roll(y0[0], -1))])
    np.testing.assert_allclose(jc.Smoothed().field(params, y0), ring, rtol=0, atol=1e-15)
    res = jc.observe(params, y0, [jc.LargestLyapunov()], jc.SOLVERS["tsit5"](), options)
    assert abs(float(res["lyapunov"]) + xi) < float(res["lyapunov_error"]) < 2e-3


#: A ring of 3 at v_d = 1.5, started at steady sliding.
SLIDING = jc.ChainParams(n_osc=3, v_d=1.5)


@pytest.fixture(scope="module")
def steady_sliding_runs():
    """`SLIDING` observed from steady sliding by each solver, the largest exponent and
    the energy in one run (one compiled program per solver, for the two tests
    below)."""
    options = jc.SimulationOptions(t_end=1200.0, transient=200.0, chunk_length=50.0)
    return {solver: jc.observe(SLIDING, jc.Exact().steady_sliding(SLIDING),
                               [jc.LargestLyapunov(), jc.Energy()], jc.SOLVERS[solver](),
                               options)
            for solver in ("ros34pw2", "tsit5")}


@pytest.mark.numerics
@pytest.mark.parametrize("solver", ["ros34pw2", "tsit5"])
@pytest.mark.study
def test_steady_sliding_exponent_is_half_the_effective_damping(steady_sliding_runs, solver):
    """Linearised about steady sliding every mode has the damping 2 xi - mu'(v_d)
    (DESIGN.md): the largest exponent is -(2 xi - mu'(v_d)) / 2 above the Hopf point."""
    params = SLIDING
    law = params.friction
    slope = (law.mu_st - law.mu_d) / law.v0 * np.exp(-params.v_d / law.v0)
    expected = -(2 * params.xi - slope) / 2
    out = steady_sliding_runs[solver]
    assert abs(float(out["lyapunov"]) - expected) < float(out["lyapunov_error"]) < 2e-3


@pytest.fixture(scope="module")
def stick_slip_orbit():
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    return params, jc.periodic_orbit(params, (jnp.array([[2.78], [1.5]]), 6.9))


@pytest.mark.numerics
def test_stable_stick_slip_cycle_has_exponent_zero_within_its_error(stick_slip_orbit):
    params, orbit = stick_slip_orbit
    assert bool(orbit.converged) and bool(orbit.stable)
    options = jc.SimulationOptions(t_end=3000.0, transient=500.0)
    out = jc.observe(params, orbit.y0, [jc.LargestLyapunov(n_history=10)], options=options)
    error = float(out["lyapunov_error"])
    assert abs(float(out["lyapunov"])) < error < 1e-3
    # the running estimate settles: its last points agree within the error
    assert np.ptp(np.asarray(out["lyapunov_history"])[-3:]) < error


@pytest.mark.numerics
def test_peak_times_of_a_periodic_orbit_are_spaced_by_its_period(stick_slip_orbit):
    """And the Poincare section at those peaks is one point, the orbit's peak."""
    params, orbit = stick_slip_orbit
    period = float(orbit.period)
    options = jc.SimulationOptions(t_end=400.0, transient=100.0, rtol=1e-8, atol=1e-10)
    out = jc.observe(params, orbit.y0, [jc.PeakTimes(), jc.PoincareSection()],
                     options=options)
    n = int(out["n_peaks"][0])
    times = np.asarray(out["peak_times"])[0, :n]
    assert n == int(out["n_section"]) and abs(n - 300 / period) <= 1
    assert np.max(np.abs(np.diff(times) - period)) < 1e-5
    assert abs((times[-1] - times[0]) / (n - 1) - period) < 1e-6
    section = np.asarray(out["section_states"])[:n, :, 0]
    assert np.max(np.abs(section[:, 1])) < 1e-6  # x' = 0 on the section
    assert np.ptp(section[:, 0]) < 1e-6  # one point
    # shooting's phase condition puts y0 at x' = 0, here a peak (x'' < 0)
    assert float(jc.Smoothed().field(params, orbit.y0)[1, 0]) < 0
    assert abs(section[0, 0] - float(orbit.y0[0, 0])) < 1e-6


@pytest.fixture(scope="module")
def stick_slip_scene():
    """A ring of 3 at v_d = 1.5 (eps = 1e-2) from eq. (8) with 2 excited, over [0, 60]
    at tight tolerances: the time series and the energy in one run (one compiled
    program, for the two tests against scipy below)."""
    params = jc.ChainParams(n_osc=3, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 2))(params)
    options = jc.SimulationOptions(t_end=60.0, transient=10.0, rtol=1e-9, atol=1e-11)
    out = jc.observe(params, y0, [jc.TimeSeries(oscillators=(0, 2), dt=0.5), jc.Energy()],
                     engine=jc.Smoothed(options=options, eps=1e-2))
    return params, y0, out


@pytest.mark.numerics
def test_time_series_match_scipy(stick_slip_scene):
    params, y0, out = stick_slip_scene
    t = np.asarray(out["series_t"])
    assert t[0] == 10.0 and t[-1] == 60.0 and t.size == 101
    ref = solve_ivp(reference_rhs(params, 1e-2), (0.0, 60.0), np.ravel(y0), method="DOP853",
                    t_eval=t, rtol=1e-11, atol=1e-12).y.reshape(2, 3, -1)
    series = np.asarray(out["series"])  # (time, component, series_osc)
    assert np.max(np.abs(series - np.moveaxis(ref[:, [0, 2]], -1, 0))) < 1e-5


def test_observers_are_checked():
    with pytest.raises(ValueError, match="distinct kinds"):
        jc.observe(jc.ChainParams(n_osc=2), jnp.zeros((2, 2)), [jc.Extrema(), jc.Extrema()])
    with pytest.raises(TypeError, match="AbstractObserver"):
        jc.observe(jc.ChainParams(n_osc=2), jnp.zeros((2, 2)), ["amplitudes"])
    with pytest.raises(ValueError, match="t_start"):
        jc.observe(jc.ChainParams(n_osc=2), jnp.zeros((2, 2)), [jc.PeakTimes(t_start=5.0)],
                   options=jc.SimulationOptions(t_end=100.0, transient=50.0))


@pytest.mark.numerics
def test_energy_at_steady_sliding_and_against_scipy(steady_sliding_runs, stick_slip_scene):
    """At steady sliding x_n = mu(v_d), x_n' = 0: the energy is N mu(v_d)^2 / 2. On a
    stick-slip trajectory, the mean and maximum match scipy's dense solution."""
    params = SLIDING
    out = steady_sliding_runs["ros34pw2"]
    mu = float(jc.friction_coefficient(params, params.v_d))
    assert abs(float(out["energy_mean"]) - 1.5 * mu**2) < 1e-10
    assert abs(float(out["energy_max"]) - 1.5 * mu**2) < 1e-10
    params, y0, out = stick_slip_scene
    t = np.linspace(10.0, 60.0, 50001)
    y = solve_ivp(reference_rhs(params, 1e-2), (0.0, 60.0), np.ravel(y0), method="DOP853",
                  t_eval=t, rtol=1e-11, atol=1e-12).y.reshape(2, 3, -1)
    x, v = y
    energy = 0.5 * np.sum(v**2 + x**2 + 0.01 * (np.roll(x, -1, axis=0) - x) ** 2, axis=0)
    assert abs(float(out["energy_mean"]) / (np.trapezoid(energy, t) / 50.0) - 1) < 1e-5
    # the maximum is over the samples (every 0.05: every 50th point here)
    assert abs(float(out["energy_max"]) / energy[::50].max() - 1) < 1e-6


def _prescribed_stream(params, ts):
    """A prescribed stream of states (2, n_osc) at times `ts`: oscillator n moves as
    x = A_n cos(t + phi_n), except where it sticks (x' = v_d exactly, held over a
    stretch); it is no solution of eq. (5), only samples to observe."""
    n = params.n_osc
    amplitude = 0.5 + 0.1 * np.arange(n)
    phase = 0.7 * np.arange(n)
    x = amplitude * np.cos(ts[:, None] + phase)
    v = -amplitude * np.sin(ts[:, None] + phase)
    stuck = (np.arange(n) % 2 == 0) & (np.sin(0.1 * ts[:, None]) > 0.5)
    v = np.where(stuck, float(params.v_d), v)
    return np.stack([x, v], axis=1)


class _ObserverArgs(eqx.Module):
    """What an engine hands its observers as `args` (`jc.AbstractObserver`): the
    chain and the smoothing velocity of its friction (0 for the exact engine)."""

    params: jc.ChainParams
    eps: float


def test_both_engines_observe_a_prescribed_stream_alike():
    """The smoothed engine hands `Extrema` chunks of dense samples (the end sample
    of one chunk repeated at the start of the next), the exact engine the samples
    it locates (each a chunk of one sample, here one at a time), both through the
    observer's `update` (`jc.AbstractObserver`): the same stream gives the same
    extrema, bitwise, and those of NumPy over each half of the window."""
    # jitted as the engines run it: one program, not an op-by-op dispatch
    update = eqx.filter_jit(lambda observer, state, chunk, args, options:
                            observer.update(state, chunk, args, options))
    params = jc.ChainParams(n_osc=4, v_d=1.5)
    options = jc.SimulationOptions(t_end=100.0, transient=40.0, chunk_length=15.0)
    ts = np.linspace(options.transient, options.t_end, 241)  # mid = 70 among them
    ys = _prescribed_stream(params, ts)
    observer = jc.Extrema()

    smoothed = _ObserverArgs(params, 1e-3)
    chunked = observer.init(ys[0], smoothed, options)
    for lo in range(0, 240, 20):  # chunks [ts[lo], ts[lo + 20]], ends shared
        chunk = jc.Chunk(t0=ts[lo], t1=ts[lo + 20], ts=jnp.asarray(ts[lo:lo + 21]),
                         ys=jnp.asarray(ys[lo:lo + 21]), log_growth=None)
        chunked = update(observer, chunked, chunk, smoothed, options)
    exact = _ObserverArgs(params, 0.0)  # the exact engine's: it does not smooth
    located = observer.init(ys[0], exact, options)
    for t, y in zip(ts, ys):  # one located sample at a time, a chunk of its own
        sample = jc.Chunk(t0=jnp.asarray(t), t1=jnp.asarray(t), ts=jnp.asarray([t]),
                          ys=jnp.asarray(y)[None], log_growth=None)
        located = update(observer, located, sample, exact, options)

    zero_eps = _ObserverArgs(params, 1e-300)  # the exact engine's band, v_rel = 0
    smooth = observer.result(chunked, zero_eps, options)
    event = observer.result(located, zero_eps, options)
    for name in ("x_max_halves", "x_min_halves", "min_slip_speed", "v_max", "on_halc",
                 "n_halc_halves", "amplitudes"):
        np.testing.assert_array_equal(smooth[name], event[name], err_msg=name)

    mid = 0.5 * (options.transient + options.t_end)
    halves = [ts <= mid, ts >= mid]
    x, v = ys[:, 0], ys[:, 1]
    np.testing.assert_array_equal(event["x_max_halves"], [x[h].max(0) for h in halves])
    np.testing.assert_array_equal(event["x_min_halves"], [x[h].min(0) for h in halves])
    np.testing.assert_array_equal(event["min_slip_speed"],
                                  np.abs(v - float(params.v_d)).min(0))
    np.testing.assert_array_equal(event["on_halc"], np.arange(4) % 2 == 0)
