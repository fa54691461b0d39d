"""The engine as a value: `simulate`, `observe` and `ensemble` run the smoothed or the
exact engine, named by a string or given as a value; the exact engine against the
non-smooth reference's own route, the smoothed engine value against the default
call (the same program, bit for bit), and the refusals in one clear line."""

import json

import numpy as np
import pytest

import jaxchain as jc
from helpers import assert_usage_error

#: Two oscillators on a ring, the second excited by eq. (8): stick-slip.
CHAIN = jc.ChainParams(n_osc=2, v_d=1.5)
START = jc.OutOfPhaseExcitation.eq8([False, True])
HORIZON = jc.SimulationOptions(t_end=300.0, transient=150.0)
EXACT = jc.NonsmoothOptions.reference(t_end=300.0, transient=150.0,
                                      chunk_length=HORIZON.chunk_length)


@pytest.mark.numerics
def test_the_exact_engine_is_the_stick_slip_reference():
    """`simulate` on the exact engine at the reference's tolerances gives what the
    reference `simulate_nonsmooth` gives (two compiled programs of the same model,
    both at rtol 1e-12: agreement to 1e-8), in the smoothed engine's layout, with
    the same oscillators on the HALC; `engine="exact"` at the engine's defaults
    (rtol 1e-7) gives the same amplitudes to 100 times its rtol (the periodic
    states of the Fig. 4 scene are within 10 to 30 times it; the final state, a
    phase on the cycle, drifts further)."""
    by_value = jc.simulate(CHAIN, START, engine=jc.Exact(EXACT))
    reference = jc.simulate(CHAIN, START, engine=jc.Exact(EXACT))
    assert isinstance(by_value, jc.Observables)
    np.testing.assert_allclose(by_value.amplitudes, reference.amplitudes, rtol=0, atol=1e-8)
    np.testing.assert_allclose(by_value.y_final, reference.y_final, rtol=0, atol=1e-8)
    assert by_value.on_halc.tolist() == reference.on_halc.tolist()
    assert int(by_value.n_halc) == int(reference.n_halc) >= 1  # a stick phase seen
    by_name = jc.simulate(CHAIN, START, options=HORIZON, engine="exact")
    np.testing.assert_allclose(by_name.amplitudes, reference.amplitudes, rtol=0,
                               atol=100 * jc.NonsmoothOptions().rtol)
    assert by_name.on_halc.tolist() == reference.on_halc.tolist()


@pytest.mark.numerics
def test_the_smoothed_engine_value_is_the_default_run_bit_for_bit():
    solver = jc.SOLVERS["tsit5"]()
    default = jc.simulate(CHAIN, START, solver, HORIZON)
    value = jc.simulate(CHAIN, START, engine=jc.Smoothed(solver, HORIZON))
    named = jc.simulate(CHAIN, START, "tsit5", HORIZON, engine="smoothed")
    for run in (value, named):
        np.testing.assert_array_equal(run.amplitudes, default.amplitudes)
        np.testing.assert_array_equal(run.y_final, default.y_final)
    # the smoothed stick band moves the amplitudes by O(eps) from the exact engine's
    exact = jc.simulate(CHAIN, START, options=HORIZON, engine="exact")
    assert 0 < np.max(np.abs(default.amplitudes - exact.amplitudes)) < 0.05


@pytest.mark.numerics
@pytest.mark.study
def test_an_ensemble_on_the_exact_engine_records_it():
    """Each lane of the ensemble is the exact engine's run of its start (another
    compiled program: agreement to 1e-8 at rtol 1e-12); the dataset names the engine
    and its Runge-Kutta pair."""
    ds = jc.ensemble(CHAIN, [1.5], jc.localized_family(2), options=EXACT, engine="exact",
                     progress=False)
    assert ds.attrs["engine"] == "exact" and ds.attrs["solver"] == EXACT.solver
    assert ds.attrs["root_tol"] == EXACT.root_tol
    for ic, start in enumerate((START, jc.OutOfPhaseExcitation.eq8([True, True]))):
        one = jc.simulate(CHAIN, start, engine=jc.Exact(EXACT))
        lane = ds.isel(v_d=0, ic=ic)
        np.testing.assert_allclose(lane["amplitudes"], one.amplitudes, rtol=0, atol=1e-8)
        assert int(lane["n_halc"]) == int(one.n_halc)
    smoothed = jc.ensemble(CHAIN, [1.5], jc.localized_family(2), options=HORIZON,
                           progress=False)
    assert smoothed.attrs["engine"] == "smoothed" and "solver" in smoothed.attrs


@pytest.mark.numerics
@pytest.mark.study
def test_vmapped_lanes_of_the_exact_engine_are_its_single_runs():
    """The GPU's route on the CPU: lanes of the exact engine vmapped together, where
    the event's root find runs in every lane, also in lanes whose guards did not
    change sign (it raised there before). Each lane is its own run (another compiled
    program, at rtol 1e-12: agreement to 1e-8)."""
    starts = np.random.default_rng(0).uniform(-1.0, 1.0, (3, 2, 2))
    lanes = jc.run_lanes(CHAIN, starts, options=EXACT, engine="exact", schedule="vmap")
    assert (np.asarray(lanes.status) == jc.Status.ok).all()
    for lane, start in enumerate(starts):
        one = jc.simulate(CHAIN, start, engine=jc.Exact(EXACT))
        for field in ("amplitudes", "energy", "y_final"):
            np.testing.assert_allclose(getattr(lanes, field)[lane], getattr(one, field),
                                       rtol=0, atol=1e-8)


@pytest.mark.parametrize("call, message", [
    (lambda: jc.simulate(CHAIN, START, engine="stick"), "engine must be one of"),
    (lambda: jc.simulate(CHAIN, START, "tsit5", engine="exact"), "takes no solver"),
    (lambda: jc.simulate(CHAIN, START, options=HORIZON, engine=jc.Exact()),
     "inside the engine value"),
    (lambda: jc.ensemble(CHAIN, [1.5], START, engine="queue"), "schedule='queue'"),
    (lambda: jc.observe(CHAIN, START, [jc.Energy()], options=HORIZON, engine="exact"),
     "engine='smoothed'"),
])
def test_an_engine_it_cannot_use_is_refused_in_one_line(call, message):
    with pytest.raises(jc.ValidationError, match=message) as err:
        call()
    assert "\n" not in str(err.value)


@pytest.mark.numerics
def test_a_sweep_on_the_exact_engine_is_each_lanes_run_and_keys_its_store(tmp_path):
    """Each trajectory of a stored sweep on the exact engine is that engine's run
    of its start (another compiled program: agreement to 1e-8 at rtol 1e-12); the
    engine is part of the store's key, so the smoothed engine never resumes it."""
    store = tmp_path / "sweep.zarr"
    ds = jc.sweep(CHAIN, [1.5], jc.localized_family(2), options=EXACT, engine="exact",
                  store=store, progress=False).load()
    assert ds.attrs["engine"] == "exact" and ds.attrs["solver"] == EXACT.solver
    for ic, start in enumerate((START, jc.OutOfPhaseExcitation.eq8([True, True]))):
        one = jc.simulate(CHAIN, start, engine=jc.Exact(EXACT))
        lane = ds.isel(v_d=0, ic=ic)
        np.testing.assert_allclose(lane["amplitudes"], one.amplitudes, rtol=0, atol=1e-8)
        assert int(lane["n_halc"]) == int(one.n_halc)
    with pytest.raises(jc.ValidationError, match="other settings|differ"):
        jc.sweep(CHAIN, [1.5], jc.localized_family(2), options=HORIZON, store=store,
                 resume=True, progress=False)
    with pytest.raises(jc.ValidationError, match="no eps"):
        jc.sweep(CHAIN, [1e-3], jc.localized_family(2), engine="exact", where="eps",
                 progress=False)


@pytest.mark.numerics
def test_basin_stability_on_the_exact_engine_classifies_each_samples_run():
    """Each sample's class is the n_HALC of the exact engine's run from its state
    (`simulate`, to the same n_HALC); with no peak times, the periodic share is NaN,
    and the convergence check still compares the classes at 2 t_end."""
    ds = jc.basin_stability(CHAIN, [1.5], 3, key=1, options=EXACT, engine="exact",
                            n_check=2, progress=False)
    assert ds.attrs["engine"] == "exact"
    for i in range(3):
        one = jc.simulate(CHAIN, ds["y0"].values[i], engine=jc.Exact(EXACT))
        assert int(ds["n_halc"].values[0, i]) == int(one.n_halc)
    assert np.isnan(ds["periodic_fraction"].values).all()
    assert 0 <= float(ds["changed_fraction"].values[0]) <= 1


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_the_crosscheck_of_the_exact_engine_agrees_with_its_reference():
    """The exact engine's lanes against its own reference runs (the same model, the
    lanes at rtol 1e-12 and the reference at its 1e-10): the same n_HALC and
    amplitudes to 1e-6, its variables named after the engine."""
    ds = jc.crosscheck(CHAIN, [1.5], [("eq8", 1), ("eq8", 2)], options=EXACT,
                       engine="exact")
    assert ds.attrs["engine"] == "exact"
    assert ds["n_halc_exact"].values.tolist() == ds["n_halc_reference"].values.tolist()
    assert float(ds["amplitude_error"].max()) < 1e-6
    assert "amplitudes_smoothed" not in ds


@pytest.mark.study
def test_the_commands_run_the_exact_engine_or_refuse_it_in_one_line(tmp_path, capsys):
    """`--engine exact` runs `jaxchain localized` (the engine in its JSON, eps and
    the solver not), each start's n_HALC that of the exact engine's run; a command
    that differentiates refuses it with status 2 and one line."""
    argv = ["localized", "--n-osc", "2", "--t-end", "300", "--transient", "150",
            "--engine", "exact", "--out", str(tmp_path / "a"), "--json"]
    assert jc.main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    # the exact engine's own settings, its Runge-Kutta solver among them; no eps and
    # not the smoothed engine's solver
    assert out["engine"] == "exact" and "eps" not in out
    assert out["solver"] == jc.Exact().options.solver != "ros34pw2"
    one = jc.simulate(CHAIN, START, engine=jc.Exact(EXACT))
    assert out["runs"][0]["n_halc"][0] == int(one.n_halc)
    assert (out["rtol"], out["atol"]) == (jc.NonsmoothOptions().rtol, jc.NonsmoothOptions().atol)
    # --rtol and --atol typed on the command line are the exact engine's tolerances
    # (they were ignored, the defaults shown being the smoothed engine's)
    assert jc.main(argv[:-3] + ["--rtol", "1e-3", "--atol", "1e-3", "--out",
                                str(tmp_path / "loose"), "--json"]) == 0
    loose = json.loads(capsys.readouterr().out)
    assert (loose["rtol"], loose["atol"]) == (1e-3, 1e-3)
    assert loose["runs"][0]["energy"] != out["runs"][0]["energy"]
    assert_usage_error(["mistuning", "--engine", "exact", "--out", str(tmp_path / "b")],
                       "--engine exact", capsys)
