"""Parameter values are traced, not static: five values of eps or xi compile each
jitted entry point once (`eqx.debug.assert_max_traces` raises on a second trace),
each traced at all (the patched function is the one the entry point calls), and
each value is used (the results against an independent reference)."""

import functools
import inspect

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import (internal, internal_name, reference_rhs, replace_internal,
                     scipy_slip_arc)

FIVE = (0.04, 0.045, 0.05, 0.055, 0.06)


def trace_once(monkeypatch, what) -> list:
    """Replace the jitted function that computes `what` (its name in jaxchain's
    internals, `helpers.internal`) by the same function, jitted anew, that raises
    if it is traced more than once; return the list to which each trace appends
    the function's name, so that a test can tell that it was traced at all."""
    fn, name = inspect.unwrap(internal(what)), internal_name(what)
    traces = []

    @functools.wraps(fn)
    def counted(*args, **kwargs):
        traces.append(name)  # runs only while JAX traces
        return fn(*args, **kwargs)

    replace_internal(monkeypatch, what,
                     eqx.filter_jit(eqx.debug.assert_max_traces(counted, max_traces=1)))
    return traces


def _periodicity_error(params, y0, period, eps) -> float:
    """|phi_T(y0) - y0| over `period`, by scipy (DOP853) on eq. (5) written in NumPy."""
    y0 = np.ravel(np.asarray(y0))
    end = solve_ivp(reference_rhs(params, eps), (0.0, float(period)), y0, method="DOP853",
                    rtol=1e-11, atol=1e-12).y[:, -1]
    return float(np.max(np.abs(end - y0)))


@pytest.mark.numerics
def test_simulate_compiles_once_for_five_eps(monkeypatch):
    """The excited oscillator reaches the belt speed (n_HALC = 1), where eps acts:
    each eps moves the final state by more than 3e-3 and each agrees with scipy
    (LSODA) to 1e-6."""
    traces = trace_once(monkeypatch, "simulation program")
    options = jc.SimulationOptions(t_end=20.0, transient=10.0, chunk_length=10.0, rtol=1e-10,
                                   atol=1e-12)
    params = jc.ChainParams(n_osc=2)
    for eps in (1e-2, 5e-3, 3e-3, 2e-3, 1e-3):
        y0 = np.asarray(jc.OutOfPhaseExcitation.eq8([True, False])(params))
        obs = jc.simulate(params, y0, engine=jc.Smoothed(options=options, eps=eps))
        assert obs.status == jc.Status.ok and int(obs.n_halc) == 1
        ref = solve_ivp(reference_rhs(params, eps), (0.0, options.t_end), y0.ravel(),
                        method="LSODA", rtol=1e-10, atol=1e-12)
        assert np.allclose(np.ravel(obs.y_final), ref.y[:, -1], rtol=0, atol=1e-6), eps
    assert traces == ["_run_jit"]


@pytest.mark.numerics
def test_simulate_compiles_once_for_three_mistuning_draws(monkeypatch):
    """A draw's record (`ChainParams.mistuning`, its seed) is static but no part of
    the program: three draws compile simulate once. Each run is its own chain's:
    against scipy (LSODA) on eq. (5) with that draw's ground springs, to 1e-6, and
    the draws end more than 1e-3 apart."""
    traces = trace_once(monkeypatch, "simulation program")
    options = jc.SimulationOptions(t_end=20.0, transient=10.0, chunk_length=10.0, rtol=1e-10,
                                   atol=1e-12)
    finals = []
    for seed in range(3):
        params = jc.mistune(jc.ChainParams(n_osc=2), 0.05, seed)
        y0 = np.asarray(jc.OutOfPhaseExcitation.eq8([True, False])(params))
        obs = jc.simulate(params, y0, engine=jc.Smoothed(options=options, eps=1e-2))
        ref = solve_ivp(reference_rhs(params, 1e-2), (0.0, options.t_end), y0.ravel(),
                        method="LSODA", rtol=1e-10, atol=1e-12)
        assert np.allclose(np.ravel(obs.y_final), ref.y[:, -1], rtol=0, atol=1e-6), seed
        finals.append(np.ravel(obs.y_final))
    assert traces == ["_run_jit"]
    assert min(np.abs(a - b).max() for i, a in enumerate(finals) for b in finals[:i]) > 1e-3


@pytest.mark.numerics
def test_jacobian_compiles_once_for_five_eps(monkeypatch):
    """`jacobian` runs as one program with eps traced: at a state where oscillator 0
    slips at 2e-3 against the belt, where eps acts, each eps changes its friction
    entry by more than 1 and each Jacobian is the central difference of eq. (5)
    written in NumPy (`reference_rhs`)."""
    traces = trace_once(monkeypatch, "Jacobian program")
    params = jc.ChainParams(n_osc=3)
    y = np.array(jc.Exact().steady_sliding(params))
    y[1] = params.v_d + np.array([2e-3, -0.3, 0.4])
    z, h = y.ravel(), 1e-8
    entries = []
    for eps in (1e-2, 5e-3, 3e-3, 2e-3, 1e-3):
        f = reference_rhs(params, eps)
        fd = np.stack([(f(0.0, z + h * e) - f(0.0, z - h * e)) / (2 * h) for e in np.eye(6)],
                      axis=1)
        jac = np.asarray(jc.Smoothed(eps=eps).jacobian(params, y))
        assert np.allclose(jac, fd, rtol=1e-5, atol=1e-5), eps
        entries.append(jac[3, 3])
    assert traces == ["_jacobian"]
    assert np.min(np.abs(np.diff(entries))) > 1


@pytest.mark.numerics
def test_hopf_point_compiles_once_for_five_xi(monkeypatch):
    traces = trace_once(monkeypatch, "Hopf modes")
    for xi in FIVE:
        hopf = jc.hopf_point(jc.ChainParams(n_osc=2, xi=xi))
        assert abs(float(hopf.v_d[0]) - 0.5 * jnp.log(0.5 / xi)) < 1e-9
    assert traces == ["_hopf_modes"]


@pytest.mark.numerics
def test_shooting_compiles_once_for_five_xi(monkeypatch):
    """Two Newton steps from a rough guess bring each orbit to within 1e-5 of
    periodic, by scipy's integration over its period."""
    traces = trace_once(monkeypatch, "shooting solve")
    # two Newton steps and no damped Newton method after them
    method = jc.Shooting(jc.Smoothed(eps=1e-2).for_orbits(1e-6, 1e-8), newton_steps=2,
                         damped_steps=0, n_samples=64)
    for xi in FIVE:
        params = jc.ChainParams(n_osc=1, xi=xi)
        orbit = jc.periodic_orbit(params, (jnp.array([[2.2], [0.0]]), 6.3), method,
                                  throw=False)
        assert _periodicity_error(params, orbit.y0, orbit.period, 1e-2) < 1e-5, xi
    assert traces == ["_root"]


@pytest.mark.numerics
@pytest.mark.study
def test_continuation_compiles_once_for_five_problems(monkeypatch):
    """A new `cycle_problem` for each xi: its residual and records are equal
    modules, not new lambdas, so the corrector, tangent and records trace once; the
    shooting that starts each branch makes its record by the same program.
    The continued point is a periodic orbit at its belt speed, by scipy."""
    traces = [trace_once(monkeypatch, what) for what in (
        "continuation corrector", "continuation tangent", "continuation records")]
    # shooting's results are records of the same program (`periodic_orbit`)
    replace_internal(monkeypatch, "shooting records", internal("continuation records"))
    method = jc.Shooting(jc.Smoothed(eps=1e-2).for_orbits(1e-6, 1e-8), n_samples=64)
    for xi in FIVE:
        params = jc.ChainParams(n_osc=1, xi=xi)
        orbit = jc.periodic_orbit(params, (jnp.array([[2.2], [0.0]]), 6.3), method)
        branch = jc.continuation(jc.cycle_problem(orbit, method),
                                 options=jc.ContinuationOptions(ds=0.01, max_points=2))
        assert bool(branch.converged[-1])
        u, v_d = np.asarray(branch.u[-1]), float(branch.p[-1])
        assert v_d != float(params.v_d)  # it moved along the branch
        moved = jc.with_parameter(params, "v_d", v_d)
        assert _periodicity_error(moved, u[:-1], u[-1], 1e-2) < 1e-5, xi
    assert traces == [["_correct"], ["_tangent"], ["describe_point"]]


@pytest.mark.numerics
def test_existence_limit_compiles_once_for_five_xi(monkeypatch):
    """Each limit (to 1e-6) against scipy's slip arc: it returns to the belt 1e-5
    below the limit and not 1e-5 above it."""
    traces = trace_once(monkeypatch, "slip arc peak")
    limits = [jc.stick_slip_existence_limit(jc.ChainParams(n_osc=1, xi=xi), tol=1e-6)
              for xi in FIVE]
    assert all(a > b for a, b in zip(limits, limits[1:]))  # more damping, earlier loss
    for xi, limit in zip(FIVE, limits):
        for d, returns in ((-1e-5, True), (1e-5, False)):
            arc = scipy_slip_arc(jc.ChainParams(n_osc=1, xi=xi, v_d=limit + d))
            assert (arc.status == 1) == returns, (xi, d)
    assert traces == ["_peak"]


@pytest.mark.study
def test_bifurcation_programs_hold_no_host_callback(monkeypatch):
    """JAX keeps no program that calls back into Python in its persistent
    compilation cache, and equinox's checks (in diffrax, lineax and optimistix)
    are such callbacks by default: the programs of shooting, continuation, the
    Hopf point and the existence limit trace them as NaN (`checks_as_nan`), so
    that the next process (a command, a notebook) loads them instead of compiling
    them again. Each program is lowered at the arguments it was called with, and
    its text holds no callback; the results are those of a periodic orbit (by
    scipy), as above."""
    names = ("shooting solve", "continuation corrector", "continuation tangent",
             "continuation records", "Hopf modes", "slip arc peak")
    programs, calls = {what: internal(what) for what in names}, {}

    def recording(what):
        def call(*args, **kwargs):
            calls[what] = (args, kwargs)
            return programs[what](*args, **kwargs)
        return call

    for what in names:
        replace_internal(monkeypatch, what, recording(what))
    replace_internal(monkeypatch, "shooting records", recording("continuation records"))
    params = jc.ChainParams(n_osc=1, xi=FIVE[0])
    method = jc.Shooting(jc.Smoothed(eps=1e-2).for_orbits(1e-6, 1e-8), n_samples=64)
    orbit = jc.periodic_orbit(params, (jnp.array([[2.2], [0.0]]), 6.3), method)
    branch = jc.continuation(jc.cycle_problem(orbit, method),
                             options=jc.ContinuationOptions(ds=0.01, max_points=2))
    assert bool(branch.converged[-1])
    assert _periodicity_error(orbit.params, orbit.y0, orbit.period, 1e-2) < 1e-5
    assert 1.0 < jc.hopf_vd(params) < jc.stick_slip_existence_limit(params, tol=1e-6)
    assert set(calls) == set(names)
    for what, (args, kwargs) in calls.items():
        text = programs[what].lower(*args, **kwargs).as_text()
        assert "callback" not in text, what
