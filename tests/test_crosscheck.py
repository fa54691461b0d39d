"""The cross-check of smoothed against non-smooth, and its command."""

import json
import sys

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from helpers import assert_cf_compliant, scipy_stick_slip_cycle

#: The horizon of the command test below (the default chunks: two of 150 in each
#: phase), so that the command runs the programs these tests compiled.
SMALL = jc.SimulationOptions(t_end=600.0, transient=300.0)
#: Long enough for the localized state of a 4-ring to settle to a periodic orbit.
SETTLED = jc.SimulationOptions(t_end=1200.0, transient=600.0, chunk_length=150.0)


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_periodic_states_agree_within_the_smoothing_error(tmp_path):
    """On a small ring, the default smoothed model gives the reference's n_HALC and
    amplitudes to better than 1 % on periodic states; a second call reads the
    stored reference runs back instead of recomputing them."""
    p = jc.ChainParams(n_osc=4)
    ics = (("eq8", 1), ("eq8", 4))
    ds = jc.crosscheck(p, (1.5,), ics, options=SETTLED, checkpoint=tmp_path)
    assert ds.sizes == {"case": 2, "osc": 4}
    periodic = np.array(["periodic" in c for c in ds["state_class_reference"].values])
    assert periodic.any()
    assert np.all(ds["amplitude_error"].values[periodic] < 1e-2)
    assert np.all(ds["n_halc_agrees"].values)
    assert ds["n_halc_reference"].values.tolist() == [1, 4]

    # read back, not run again: a new run would have measured its own wall time
    again = jc.crosscheck(p, (1.5,), ics, options=SETTLED, checkpoint=tmp_path)
    assert np.array_equal(again["amplitudes_reference"], ds["amplitudes_reference"])
    assert np.array_equal(again["wall_time_s_reference"], ds["wall_time_s_reference"])


#: A tiny cross-check, one oscillator and one case (compiled as in
#: `test_smoothed_error_shrinks_with_eps`).
TINY = {"params": jc.ChainParams(n_osc=1), "v_d": (1.5,), "ics": (("eq8", 1),),
        "options": SMALL}
#: Settings that change the reference run of `TINY`, each on its own: a parameter
#: and a reference option.
OTHER_SETTINGS = {
    "xi": {"params": jc.ChainParams(n_osc=1, xi=0.06)},
    "reference rtol": {"reference_options": jc.NonsmoothOptions.reference(
        t_end=SMALL.t_end, transient=SMALL.transient, rtol=1e-9, atol=1e-9)},
}


def _without_wall_times(ds: xr.Dataset) -> xr.Dataset:
    return ds.drop_vars("wall_time_s_reference")


@pytest.mark.study
def test_stored_reference_runs_are_read_back_only_for_equal_settings(tmp_path):
    """A cross-check resumed in a folder that holds reference runs of other
    settings gives what a fresh one gives, case by case; a run of equal settings
    is read back, its file untouched."""
    stored = tmp_path / "stored"
    first = jc.crosscheck(**TINY, checkpoint=stored)
    for name, change in OTHER_SETTINGS.items():
        resumed = jc.crosscheck(**TINY | change, checkpoint=stored)
        fresh = jc.crosscheck(**TINY | change, checkpoint=tmp_path / name)
        xr.testing.assert_equal(_without_wall_times(resumed), _without_wall_times(fresh))
        # The change matters, so reading back `first`'s run would have shown.
        assert not np.array_equal(resumed["amplitudes_reference"],
                                  first["amplitudes_reference"]), name
    files = sorted(stored.iterdir())
    assert len(files) == 1 + len(OTHER_SETTINGS)  # one per setting, none overwritten
    written = {f: f.stat().st_mtime_ns for f in files}

    again = jc.crosscheck(**TINY, checkpoint=stored)
    # the stored wall time included: a run made again would have measured its own
    xr.testing.assert_equal(again, first)
    assert {f: f.stat().st_mtime_ns for f in sorted(stored.iterdir())} == written


@pytest.mark.numerics
@pytest.mark.study
def test_smoothed_error_shrinks_with_eps():
    """The amplitude error against the reference falls when eps is divided by 10
    (the smoothed law converges to the non-smooth one)."""
    errs = [float(jc.crosscheck(jc.ChainParams(n_osc=1), (1.5,), (("eq8", 1),),
                                engine=jc.Smoothed(options=SMALL, eps=eps)
                                )["amplitude_error"][0]) for eps in (1e-2, 1e-3)]
    assert errs[1] < 0.5 * errs[0]


def test_state_class_names():
    assert jc.state_class(0, 20, "periodic") == "steady sliding"
    assert jc.state_class(3, 20, "periodic") == "localized (periodic)"
    assert jc.state_class(20, 20, "irregular") == "stick-slip (irregular)"
    assert jc.state_class(1, 1) == "stick-slip"
    assert jc.state_class(-1, 20, "periodic") == "failed"


@pytest.mark.numerics
@pytest.mark.study
def test_the_public_class_tolerances_drive_the_crosscheck():
    """`jc.ClassTolerances` is the cross-check's: with its defaults the single
    oscillator's stick-slip cycle is periodic in both models; with half-window
    tolerances below rounding the smoothed model's is irregular (its extrema,
    sampled every sample_dt, move by ~1e-4 between the two halves), so the
    fields are read."""
    kwargs = {k: TINY[k] for k in ("v_d", "ics", "options")}
    ds = jc.crosscheck(TINY["params"], tolerances=jc.ClassTolerances(), **kwargs)
    assert ds["state_class_smoothed"].values.tolist() == ["stick-slip (periodic)"]
    assert ds["state_class_reference"].values.tolist() == ["stick-slip (periodic)"]
    strict = jc.ClassTolerances(halves=1e-300, halves_reference=1e-300)
    ds = jc.crosscheck(TINY["params"], tolerances=strict, **kwargs)
    assert ds["state_class_smoothed"].values.tolist() == ["stick-slip (irregular)"]
    assert ds.attrs["periodic_tol_smoothed"] == ds.attrs["periodic_tol_reference"] == 1e-300
    for field in ("delay", "halves", "halves_reference"):
        with pytest.raises(ValueError, match=f"ClassTolerances.{field}"):
            jc.ClassTolerances(**{field: 0.0})
    with pytest.raises(ValueError, match="ClassTolerances.max_period"):
        jc.ClassTolerances(max_period=0)


@pytest.mark.numerics
@pytest.mark.study
def test_crosscheck_command_json_and_files(tmp_path, capsys):
    """The command on the single oscillator (the window of `SMALL`), against scipy's
    event-driven stick-slip cycle: the reference amplitude to 1e-6, the smoothed
    one to 1 %, and the reported amplitude error is the smoothed amplitude's
    distance from scipy's."""
    out = tmp_path / "out"
    # --eq8 left at its default: on one oscillator its cases are the one k = 1
    code = jc.main(["crosscheck", "--n-osc", "1", "--vd", "1.5", "--eq10", "",
                    "--t-end", "600", "--transient", "300", "--json", "--out", str(out)])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["outputs"]) == {"crosscheck_cases", "crosscheck.nc", "crosscheck.png"}
    (case,) = report["cases"]
    assert case["ic"] == "eq8 k=1" and case["v_d"] == 1.5
    assert case["n_halc_smoothed"] == case["n_halc_reference"] == 1 and case["n_halc_agrees"]
    assert case["class_reference"] == case["class_smoothed"] == "stick-slip (periodic)"
    assert (out / "crosscheck.png").stat().st_size > 0
    ds = xr.load_dataset(out / "crosscheck.nc", engine="h5netcdf")
    assert_cf_compliant(out / "crosscheck.nc")
    assert ds.attrs["reference_rtol"] == 1e-12 and ds.attrs["eps"] == float(jc.Smoothed().eps)
    expected, _ = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1, v_d=1.5))
    reference = float(ds["amplitudes_reference"].values[0, 0])
    smoothed = float(ds["amplitudes_smoothed"].values[0, 0])
    assert abs(reference / expected - 1) < 1e-6
    assert abs(smoothed / expected - 1) < 1e-2
    assert case["amplitude_error"] == pytest.approx(abs(smoothed - expected) / expected,
                                                    abs=1e-5)


@pytest.mark.parametrize("argv, says", [
    (["--eq8", "5", "--n-osc", "4"], "--eq8"),
    (["--eq10", "5", "--n-osc", "4"], "--eq10"),
    (["--eq8", "", "--eq10", ""], "--eq8"),
    (["--vd", "1.5,x"], "--vd"),
    (["--vd", "-1"], "--vd"),
    (["--ref-rtol", "0"], "--ref-rtol"),
])
def test_crosscheck_bad_options_exit_2(argv, says, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(["crosscheck", *argv, "--out", str(tmp_path)]))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err
