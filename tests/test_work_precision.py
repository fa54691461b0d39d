"""The work-precision study: its error measures, resumption and command."""

import json

import numpy as np

import jaxchain as jc
import jaxchain._work_precision as wp
from jaxchain._cli.main import main
from helpers import flat


def test_numpy_field_for_scipy_matches_the_model():
    p = jc.ChainParams(n_osc=5, eps=1e-2)
    y = np.random.default_rng(0).normal(size=(2, 5))
    assert np.allclose(wp._numpy_field(p)(0.0, y.reshape(-1)),
                       flat(jc.vector_field(0.0, y, p)), rtol=1e-13, atol=1e-13)


def test_study_errors_fall_with_eps_and_resume_from_the_csv(tmp_path, monkeypatch):
    """For the single oscillator, the amplitude and trajectory errors against the
    reference fall with eps (the smoothed law converges to the non-smooth one); a
    second call finds every row in the CSV and runs nothing."""
    path = tmp_path / "wp.csv"
    rows = wp.work_precision(path, ["single"], ["tsit5"], [1e-8], [1e-2, 1e-3],
                             scipy=False, reference_points=False)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    coarse, fine = sorted(rows, key=lambda r: -float(r["eps"]))
    for error in ("amplitude_error", "trajectory_error"):
        assert float(fine[error]) < 0.5 * float(coarse[error])
    assert wp.recommend(rows, "single", 1.0)["eps"] in ("0.01", "0.001")

    def nothing(*args, **kwargs):
        raise AssertionError("rows already in the CSV must not be recomputed")
    monkeypatch.setattr(wp, "diffrax_point", nothing)
    again = wp.work_precision(path, ["single"], ["tsit5"], [1e-8], [1e-2, 1e-3],
                              scipy=False, reference_points=False)
    assert len(again) == 2


def test_max_steps_is_recorded_and_tighter_rtols_skipped(tmp_path):
    rows = wp.work_precision(tmp_path / "wp.csv", ["single"], ["tsit5"], [1e-4, 1e-6],
                             [1e-4], scipy=False, reference_points=False, max_steps=50)
    assert rows[0]["status"] == "max_steps reached"
    assert rows[1]["status"].startswith("skipped")


def test_work_precision_command(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["work-precision", "--scenes", "single", "--solvers", "tsit5,kencarp4",
                 "--rtols", "1e-6", "--eps", "1e-2", "--no-scipy", "--json",
                 "--no-progress", "--out", str(out)])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["runs"] == 2 + len(wp.REFERENCE_RTOLS)
    assert (out / "work_precision_single.png").stat().st_size > 0
    header = (out / "work_precision.csv").read_text().splitlines()[0]
    assert header.split(",") == list(wp.COLUMNS)
