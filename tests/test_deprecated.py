"""The previous release's orbit names, used by its documentation and notebooks, work
for one more release as deprecated aliases of the method as a value: each warns and
gives what the new form gives, bit for bit (the same compiled program)."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


@pytest.fixture(scope="module")
def start():
    jc.configure()
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    obs = jc.simulate(params, jnp.array([[2.0], [0.0]]),
                      options=jc.SimulationOptions(t_end=600.0, transient=300.0))
    return params, obs.y_final


@pytest.mark.study
def test_the_old_names_warn_and_give_the_new_forms_results(start):
    params, y = start
    with pytest.warns(DeprecationWarning, match="ExactShooting is deprecated"):
        old_exact = jc.ExactShooting(phase_oscillator=0)
    with pytest.warns(DeprecationWarning, match="exact_periodic_orbit"):
        old = jc.exact_periodic_orbit(params, y, 6.3, old_exact)
    new = jc.periodic_orbit(params, (y, 6.3), jc.Shooting(jc.Exact().for_orbits()))
    assert float(old.period) == float(new.period)
    np.testing.assert_array_equal(old.multipliers, new.multipliers)
    with pytest.warns(DeprecationWarning, match="ShootingOptions"):
        options = jc.ShootingOptions()
    smoothed = jc.periodic_orbit(params, (y, 6.3), jc.Shooting())
    with pytest.warns(DeprecationWarning, match="floquet_multipliers"):
        values, trivial = jc.floquet_multipliers(params, smoothed.y0, smoothed.period, options)
    np.testing.assert_array_equal(values, smoothed.multipliers)
    assert int(trivial) == int(smoothed.trivial)
    assert "ShootingOptions" not in jc.__all__


def test_the_old_call_of_periodic_orbit_says_the_new_one(start):
    params, y = start
    with pytest.raises(ValueError, match=r"periodic_orbit\(params, \(y0, period\)"):
        jc.periodic_orbit(params, y, 6.3)


@pytest.mark.study
def test_the_exact_bistable_range_is_bistable_range_on_the_exact_engine():
    """The previous `exact_bistable_range` is `bistable_range` with the exact model's
    method: the same Hopf and grazing points and curves, its summary keys those of
    the fold with `boundary` "grazing"; the grazing point lies at the closed-form
    existence limit (an independent route to it) to 1e-8."""
    jc.configure()
    params = jc.ChainParams(n_osc=1)
    found = jc.bistable_range(params, xi_values=[0.05, 0.06], ratio_values=[2.0, 2.5],
                              method=jc.Shooting(jc.Exact().for_orbits()))
    with pytest.warns(DeprecationWarning, match="exact_bistable_range"):
        old, (curves_xi, _) = jc.exact_bistable_range(params, xi_values=[0.05, 0.06],
                                                      ratio_values=[2.0, 2.5])
    assert found.summary["boundary"] == "grazing" and found.design is None
    assert found.summary == old
    np.testing.assert_array_equal(found.curves_xi.fold_vd, curves_xi.fold_vd)
    assert abs(found.summary["fold_minus_existence_limit"]) < 1e-8


@pytest.mark.study
def test_the_old_exact_runs_are_simulate_on_the_exact_engine():
    """`simulate_nonsmooth` and `run_nonsmooth` warn and give what `simulate` with
    `engine=Exact(...)` and `Exact(...).run` give, bit for bit, in the one
    `Observables` type (the switch log among its fields)."""
    jc.configure()
    params, y0 = jc.ChainParams(n_osc=1, v_d=1.5), jnp.array([[2.0], [0.0]])
    options = jc.NonsmoothOptions.reference(t_end=60.0, transient=30.0)
    new = jc.simulate(params, y0, engine=jc.Exact(options))
    with pytest.warns(DeprecationWarning, match="simulate_nonsmooth is deprecated"):
        old = jc.simulate_nonsmooth(params, y0, options)
    with pytest.warns(DeprecationWarning, match="run_nonsmooth is deprecated"):
        pure = jc.run_nonsmooth(params, y0, options)
    assert type(old) is type(new) is jc.Observables
    for obs in (old, pure):
        np.testing.assert_array_equal(obs.amplitudes, new.amplitudes)
        np.testing.assert_array_equal(obs.log_time, new.log_time)
    assert int(new.num_events) > 0 and "simulate_nonsmooth" not in jc.__all__
