"""Measured records: read from CSV files and Datasets, converted from SI units, and
refused before any fit, each bad case with its error naming the file and column."""

import numpy as np
import pytest

import jaxchain as jc


def _write(path, header, rows):
    path.write_text(",".join(header) + "\n"
                    + "\n".join(",".join(str(v) for v in row) for row in rows) + "\n")
    return path


def test_a_record_is_read_in_its_columns_and_converted_from_si(tmp_path):
    """Columns x3 and x1 (any order, any subset) come back sorted by oscillator with
    their velocities; a record in SI units is divided by the chain's scales."""
    t = np.linspace(0.0, 1.0, 5)
    rows = np.stack([t, 2 * t, 3 * t, -t, np.full(5, 1.5)], axis=1)
    path = _write(tmp_path / "r.csv", ["t", "x3", "x1", "v1", "v_d"], rows)
    with pytest.raises(ValueError, match="v<n> must be those of the x<n>"):
        jc.read_record(path)
    rows = np.stack([t, 2 * t, 3 * t, -t, 4 * t, np.full(5, 1.5)], axis=1)
    path = _write(tmp_path / "r.csv", ["t", "x3", "x1", "v1", "v3", "v_d"], rows)
    record = jc.read_record(path)
    assert record.oscillators == (1, 3) and record.v_d == 1.5
    np.testing.assert_array_equal(record.x, np.stack([3 * t, 2 * t], axis=1))
    np.testing.assert_array_equal(record.v, np.stack([-t, 4 * t], axis=1))
    scales = jc.Scales.of(mass=2.0, stiffness=800.0, force=40.0)
    si = jc.read_record(path, scales=scales)
    np.testing.assert_allclose(si.t, t / scales.time)
    np.testing.assert_allclose(si.x, record.x / scales.length)
    assert si.v_d == pytest.approx(1.5 / scales.velocity)
    import xarray as xr

    ds = xr.Dataset({"x1": ("t", 3 * t)}, coords={"t": t})
    assert jc.record_from_dataset(ds, v_d=1.2).oscillators == (1,)


@pytest.mark.parametrize("header, rows, kw, says", [
    (["time", "x1"], [[0, 1], [1, 2]], {"v_d": 1.0}, "no column t"),
    (["t", "x1"], [[0, 1], [0, 2]], {"v_d": 1.0}, "column t must increase"),
    (["t", "x1"], [[0, 1], [1, "nan"]], {"v_d": 1.0}, "column x1, sample 2"),
    (["t", "x1"], [[0, 1], [1, "a"]], {"v_d": 1.0}, "column x1, line 3"),
    (["t", "y1"], [[0, 1], [1, 2]], {"v_d": 1.0}, "unknown column 'y1'"),
    (["t", "x1"], [[0, 1], [1, 2]], {}, "no column v_d"),
    (["t", "x1", "v_d"], [[0, 1, 1.0], [1, 2, 1.1]], {}, "v_d must be constant"),
    (["t", "x0"], [[0, 1], [1, 2]], {"v_d": 1.0}, "unknown column 'x0'"),
])
def test_bad_records_are_refused_naming_the_file_and_column(tmp_path, header, rows, kw, says):
    path = _write(tmp_path / "bad.csv", header, rows)
    with pytest.raises(ValueError, match=says) as err:
        jc.read_record(path, **kw)
    assert "bad.csv" in str(err.value)


def test_a_record_is_checked_against_the_chain_and_the_fit(tmp_path):
    path = _write(tmp_path / "r.csv", ["t", "x4"], [[0, 1], [1, 2], [2, 3]])
    record = jc.read_record(path, v_d=1.0)
    with pytest.raises(ValueError, match="column x4: the chain has 3 oscillators"):
        record.check(n_osc=3)
    with pytest.raises(ValueError, match="3 measured values for 4 unknowns"):
        record.check(n_osc=4, n_parameters=4)
    assert record.check(n_osc=4, n_parameters=3) is record


@pytest.mark.parametrize("header, rows, options, says", [
    (["time", "x1"], [[0, 1], [1, 2]], ["--vd", "1"], "no column t"),
    (["t", "x1"], [[0, 1], [0, 2]], ["--vd", "1"], "column t must increase"),
    (["t", "x1"], [[0, 1], [1, "nan"]], ["--vd", "1"], "column x1, sample 2"),
    (["t", "x1", "v_d"], [[0, 1, 1], [1, 2, 1], [2, 3, 1]], [],
     "3 measured values for 6 unknowns"),
    (["t", "x2", "v_d"], [[0, 1, 1], [1, 2, 1]], ["--n-osc", "1"],
     "column x2: the chain has 1 oscillators"),
])
def test_the_command_line_refuses_a_bad_record_in_one_line(tmp_path, capsys, header, rows,
                                                           options, says):
    """Each bad record of item 1 is refused by `jaxchain identify` before any fit:
    exit status 2 and one line naming the file and the column."""
    path = _write(tmp_path / "bad.csv", header, rows)
    status = jc.main(["identify", str(path), *options, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert says in err[0] and "bad.csv" in err[0], err


def test_the_command_lines_eps_builds_the_fitted_engine(tmp_path, capsys):
    """--eps is the eps of the fit's engine, built before any fit: an eps whose stick
    band the fit's tolerances (rtol 1e-6) cannot resolve (100 eps = 1e-7) is refused
    by the engine, exit status 2 and one line naming eps."""
    t = np.arange(40) * 0.5
    path = _write(tmp_path / "rig.csv", ["t", "x1", "v_d"],
                  [[v, np.sin(v), 1.0] for v in t])
    status = jc.main(["identify", str(path), "--eps", "1e-9", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert "stick band" in err[0] and "eps = 1e-09" in err[0], err
    assert not (tmp_path / "out").exists()


def test_the_fit_takes_its_model_as_an_engine_value():
    """`IdentifyOptions.engine` is an engine value; a name gives that engine at the
    fit's settings (eps 1e-5, rtol 1e-6, atol 1e-8, as docs/identification.md
    says), and the settings the options held beside it before are refused in one
    line that says where they go."""
    smoothed, exact = (jc.IdentifyOptions(engine=name).engine for name in ("smoothed", "exact"))
    assert smoothed.attributes() == {"engine": "smoothed", "eps": 1e-5, "solver": "Ros34PW2",
                                     "rtol": 1e-6, "atol": 1e-8}
    assert isinstance(exact, jc.Exact) and (exact.options.rtol, exact.options.atol) == (
        1e-6, 1e-8)
    assert jc.IdentifyOptions().engine.attributes() == smoothed.attributes()
    for old in ({"eps": 1e-4}, {"rtol": 1e-7}, {"solver": "tsit5"}):
        with pytest.raises(jc.ValidationError, match="the engine holds them now") as err:
            jc.IdentifyOptions(**old)
        assert "\n" not in str(err.value) and "jaxchain.Smoothed(" in str(err.value)
    with pytest.raises(jc.ValidationError, match="'smoothed', 'exact' or an engine value"):
        jc.IdentifyOptions(engine="stick")
