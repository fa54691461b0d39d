"""Parameter values are traced, not static: five values of eps or xi compile each
jitted entry point once (`eqx.debug.assert_max_traces` raises on a second trace)."""

import equinox as eqx
import jax.numpy as jnp

import jaxchain as jc
import jaxchain._bifurcation.continuation as continuation_module
import jaxchain._bifurcation.hopf as hopf_module
import jaxchain._bifurcation.shooting as shooting_module
import jaxchain._nonsmooth.existence as existence_module
import jaxchain._simulate as simulate_module

FIVE = (0.04, 0.045, 0.05, 0.055, 0.06)


def trace_once(monkeypatch, module, name):
    """Replace the jitted `module.name` by the same function, jitted anew, that
    raises if it is traced more than once."""
    fn = getattr(module, name).__wrapped__
    monkeypatch.setattr(module, name,
                        eqx.filter_jit(eqx.debug.assert_max_traces(fn, max_traces=1)))


def test_simulate_compiles_once_for_five_eps(monkeypatch):
    trace_once(monkeypatch, simulate_module, "_run_jit")
    options = jc.SimulationOptions(t_end=20.0, transient=10.0, chunk_length=10.0)
    for eps in (1e-2, 5e-3, 3e-3, 2e-3, 1e-3):
        obs = jc.simulate(jc.ChainParams(n_osc=2, eps=eps), jnp.ones((2, 2)), options=options)
        assert int(obs.status) == 0


def test_hopf_point_compiles_once_for_five_xi(monkeypatch):
    trace_once(monkeypatch, hopf_module, "_hopf_modes")
    for xi in FIVE:
        hopf = jc.hopf_point(jc.ChainParams(n_osc=2, xi=xi))
        assert abs(float(hopf.v_d[0]) - 0.5 * jnp.log(0.5 / xi)) < 1e-9


def test_shooting_compiles_once_for_five_xi(monkeypatch):
    trace_once(monkeypatch, shooting_module, "_solve")
    options = jc.ShootingOptions(newton_steps=2, rtol=1e-6, atol=1e-8, n_samples=64)
    for xi in FIVE:
        jc.periodic_orbit(jc.ChainParams(n_osc=1, xi=xi, eps=1e-2), jnp.array([[2.2], [0.0]]),
                          6.3, options, throw=False)


def test_continuation_compiles_once_for_five_problems(monkeypatch):
    # a new `limit_cycle_problem` for each xi: its residual and records are equal
    # modules, not new lambdas, so the corrector, tangent and records trace once
    for name in ("_correct", "_tangent", "_describe"):
        trace_once(monkeypatch, continuation_module, name)
    options = jc.ShootingOptions(rtol=1e-6, atol=1e-8, n_samples=64)
    for xi in FIVE:
        orbit = jc.periodic_orbit(jc.ChainParams(n_osc=1, xi=xi, eps=1e-2),
                                  jnp.array([[2.2], [0.0]]), 6.3, options)
        branch = jc.continuation(jc.limit_cycle_problem(orbit, options),
                                 options=jc.ContinuationOptions(ds=0.01, max_points=2))
        assert bool(branch.converged[-1])


def test_existence_limit_compiles_once_for_five_xi(monkeypatch):
    trace_once(monkeypatch, existence_module, "_peak")
    limits = [jc.stick_slip_existence_limit(jc.ChainParams(n_osc=1, xi=xi), tol=1e-6)
              for xi in FIVE]
    assert all(a > b for a, b in zip(limits, limits[1:]))  # more damping, earlier loss
