import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from helpers import assert_cf_compliant, assert_usage_error

SMALL = ["--n-osc", "3", "--t-end", "400", "--transient", "200"]
#: The installed console script: beside this interpreter (a venv) or on PATH.
SCRIPT = next((p for p in (Path(sys.executable).parent / "jaxchain",
                           shutil.which("jaxchain")) if p and Path(p).exists()), None)


@pytest.mark.parametrize("argv, says", [
    (["--vd", "abc"], "--vd"),
    (["--vd", "nan"], "--vd"),
    (["--n-osc", "0"], "--n-osc"),
    (["--n-osc", "2.5"], "--n-osc"),
    (["--eps", "-1"], "--eps"),
    (["--eps", "0"], "--eps"),
    (["--t-end", "-5"], "--t-end"),
    (["--transient", "20000"], "--transient"),
    (["--transient", "-1"], "--transient"),
    (["--solver", "euler"], "--solver"),
    (["--ics", "eq9"], "--ics"),
    (["--rtol", "0"], "--rtol"),
    (["--max-steps", "0"], "--max-steps"),
    (["--vd", "-1.5"], "--vd"),
    (["--out", __file__], "--out"),
    (["--bogus"], "--bogus"),
])
def test_bad_option_exits_2_with_one_line(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(["localized", *argv]))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and "error" in err


@pytest.mark.parametrize("argv, says", [
    (["crosscheck", "--transient", "20000"], "--transient"),  # SimulationOptions
    (["crosscheck", "--vd", "1.5,-1"], "--vd"),                # ChainParams
    (["crosscheck", "--eq8", "0"], "--eq8"),
    (["crosscheck", "--ref-rtol", "0"], "--ref-rtol"),
    (["work-precision", "--rtol", "2"], "--rtol"),
    (["work-precision", "--solver", "euler"], "--solver"),
    (["work-precision", "--max-steps", "-3"], "--max-steps"),
    (["boundaries", "--xi", "nan"], "--xi"),
    (["sweep", "--vd", "1.0:2.0:0"], "--vd"),
    (["sweep", "--vd", ""], "--vd"),
    (["sweep", "--vd", "1.2,x"], "--vd"),
    (["sweep", "--vd", "0,1.5"], "--vd"),
    (["sweep", "--ics", "eq8,eq9"], "--ics"),
    (["sweep", "--batch-size", "0"], "--batch-size"),
    (["sweep", "--transient", "20000"], "--transient"),
    (["sweep", "--resume", "--overwrite"], "--resume"),
    (["sweep", "--out", __file__], "--out"),
])
def test_every_command_bad_value_exits_2_with_one_line(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(argv))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and "error" in err


def test_command_draws_with_agg_unless_mplbackend_is_set(monkeypatch):
    before = matplotlib.get_backend()
    try:
        matplotlib.use("svg")
        monkeypatch.setenv("MPLBACKEND", "svg")
        assert jc.main(["work-precision", "--rtol", "2"]) == 2
        assert matplotlib.get_backend() == "svg"
        monkeypatch.delenv("MPLBACKEND")
        jc.main(["work-precision", "--rtol", "2"])
        assert matplotlib.get_backend().lower() == "agg"
    finally:
        matplotlib.use(before)


def test_the_library_leaves_the_backend_alone():
    """Importing jaxchain and drawing keeps the user's backend (Jupyter's inline one
    in a notebook; tests/test_examples.py checks that the figures appear)."""
    code = ("import matplotlib, jaxchain; jaxchain.plot_localized_states; "
            "print(matplotlib.get_backend())")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=os.environ | {"MPLBACKEND": "svg"})
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "svg"


def test_no_command_exits_2_with_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        jc.main([])
    assert exc.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def localized_small(tmp_path_factory):
    """`jaxchain localized` on the small ring (3 oscillators, eq. (8) with k = 1..3
    excited, v_d = 1.5), run once in this process with the command line's cache off
    (as every test here runs it): its JSON and its output folder."""
    out = tmp_path_factory.mktemp("localized")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = jc.main(["localized", *SMALL, "--json", "--out", str(out)])
    assert code == 0
    return json.loads(printed.getvalue()), out


@pytest.mark.numerics
@pytest.mark.study
def test_localized_json_and_files(localized_small):
    """The JSON and its files, and what they say against the paper and the
    event-driven non-smooth reference (an independent solver, no smoothing): eq. (8)
    with k excited ends with the k excited oscillators on the HALC (Fig. 4), as the
    reference does from the same start, and the amplitudes agree with the
    reference's to the smoothing error at the default eps (below 1 %, as
    test_crosscheck.py finds on periodic states); E is eq. (9), 1/2 sum A_n^2."""
    doc, out = localized_small
    assert set(doc["outputs"]) == {"localized_vd1.5.nc", "localized_vd1.5.png"}
    assert "wall_time_s" in doc and len(doc["runs"]) == 1
    res = doc["runs"][0]
    for key in ("v_d", "n_excited", "n_halc", "energy", "amplitudes", "status"):
        assert key in res
    assert res["n_excited"] == [1, 2, 3]
    assert len(res["amplitudes"]) == 3 and len(res["amplitudes"][0]) == 3
    assert res["status"] == ["ok"] * 3
    ds = xr.load_dataset(out / "localized_vd1.5.nc")
    assert_cf_compliant(out / "localized_vd1.5.nc")
    assert ds["energy"].values[0].tolist() == pytest.approx(res["energy"])
    assert ds.attrs["eps"] == float(jc.Smoothed().eps) and ds.attrs["n_osc"] == 3
    assert (out / "localized_vd1.5.png").stat().st_size > 1000
    amplitudes = np.array(res["amplitudes"])
    np.testing.assert_allclose(res["energy"], 0.5 * np.sum(amplitudes**2, axis=1),
                               rtol=1e-12)
    params = jc.ChainParams(n_osc=3, v_d=1.5)
    reference = jc.NonsmoothOptions.reference(t_end=400.0, transient=200.0)
    for k, n_halc, amplitude in zip(res["n_excited"], res["n_halc"], amplitudes):
        y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, k))(params)
        exact = jc.simulate(params, y0, engine=jc.Exact(reference))
        assert n_halc == int(exact.n_halc) == k
        np.testing.assert_allclose(amplitude, np.asarray(exact.amplitudes), rtol=1e-2)


def test_failed_runs_give_valid_json_with_nulls_and_exit_1(tmp_path, capsys):
    argv = ["localized", "--n-osc", "2", "--t-end", "300", "--transient", "200",
            "--max-steps", "5", "--json", "--out", str(tmp_path)]
    assert jc.main(argv) == 1
    captured = capsys.readouterr()
    res = json.loads(captured.out)["runs"][0]  # strict JSON: NaN would not parse here
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "2 of 2 trajectories failed" in err
    assert res["status"] == [jc.Status.max_steps_reached.name] * 2
    assert res["energy"] == [None, None] and res["n_halc"] == [-1, -1]


@pytest.mark.skipif(SCRIPT is None, reason="the jaxchain console script is not installed")
@pytest.mark.study
def test_installed_command_table_and_usage_error(localized_small, tmp_path):
    """The console script as a user runs it, in a fresh process. It keeps the
    compiled integration in the persistent compilation cache (JAXCHAIN_CACHE_DIR,
    off elsewhere in the tests), which holds no host callback: a cold start traces
    and keeps the program, a warm start reads it back. Both give the bits of the
    same run without the cache (`localized_small`, in this process)."""
    cache = tmp_path / "cache"
    env = dict(os.environ, JAXCHAIN_CACHE_DIR=str(cache))
    results = []
    for folder in ("cold", "warm"):
        run = subprocess.run([SCRIPT, "localized", *SMALL, "--out", str(tmp_path / folder)],
                             capture_output=True, text=True, env=env)
        assert run.returncode == 0, run.stderr
        results.append(xr.load_dataset(next((tmp_path / folder).glob("*.nc"))))
        if folder == "cold":  # the traced programs are kept beside the compiled ones:
            # the integration and the lanes' start (initial states, steady sliding)
            assert len(list((cache / "traced").glob("*.jaxexport"))) == 2
            assert any(p.name.startswith("jit_call") for p in cache.iterdir())
            kept = {p: p.stat().st_mtime_ns for p in (cache / "traced").iterdir()}
    # the warm start read the kept program back: it wrote nothing new
    assert {p: p.stat().st_mtime_ns for p in (cache / "traced").iterdir()} == kept
    # the kept program (cold: just traced, warm: read back) is the program that
    # `_run_block` compiles without the cache: bitwise the same results
    _, out = localized_small
    uncached = xr.load_dataset(out / "localized_vd1.5.nc")
    for name in ("energy", "amplitudes", "y_final", "n_halc", "num_steps"):
        assert all(np.array_equal(r[name].values, uncached[name].values, equal_nan=True)
                   for r in results), name
    lines = run.stdout.splitlines()
    assert lines[1].split()[:3] == ["n_excited", "n_HALC", "E"]
    assert len(lines) == 2 + 3  # the table; the note of wall time and files on stderr
    bad = subprocess.run([SCRIPT, "localized", "--eps", "x"], capture_output=True,
                         text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("argv, says", [
    (["--target", "0"], "--target"),
    (["--ratio-values", "0.9,2"], "--ratio-values"),
    (["--xi-values", ""], "--xi-values"),
    (["--n-osc", "0"], "--n-osc"),
])
def test_boundaries_bad_option_exits_2_with_one_line(argv, says, capsys):
    assert_usage_error(["boundaries", *argv], says, capsys)
