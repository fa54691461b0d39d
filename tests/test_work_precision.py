"""The work-precision study: its error measures, resumption and command."""

import dataclasses
import inspect
import json

import numpy as np
import pytest

import jaxchain as jc
from helpers import flat, internal_module, scipy_stick_slip_cycle

#: The study's module: its scenes, columns and helpers are tested here.
wp = internal_module("work-precision reference")
#: The step budget of `wp.work_precision` by default (static in the compiled runs).
STUDY_MAX_STEPS = inspect.signature(wp.work_precision).parameters["max_steps"].default


@pytest.mark.numerics
def test_numpy_field_for_scipy_matches_the_model():
    p = jc.ChainParams(n_osc=5)
    y = np.random.default_rng(0).normal(size=(2, 5))
    assert np.allclose(wp._numpy_field(p, 1e-2)(0.0, y.reshape(-1)),
                       flat(jc.Smoothed(eps=1e-2).field(p, y)), rtol=1e-13, atol=1e-13)


@pytest.mark.study
@pytest.mark.numerics
def test_study_errors_fall_with_eps_and_the_recommendation_holds(tmp_path):
    """For the single oscillator, the amplitude and trajectory errors against the
    reference fall with eps (the smoothed law converges to the non-smooth one).
    The recommended setting for 1 % is one that its run at rtol/10 confirms, and
    its amplitude is within 1 % of the stick-slip cycle computed independently
    with scipy."""
    rows = wp.work_precision(tmp_path / "wp.csv", ["single"], ["tsit5"], [1e-6, 1e-7],
                             [1e-2, 1e-3], scipy=False, reference_points=False)
    assert [r["status"] for r in rows] == ["ok"] * 4
    for rtol in ("1e-06", "1e-07"):
        coarse, fine = sorted((r for r in rows if r["rtol"] == rtol),
                              key=lambda r: -float(r["eps"]))
        for error in ("amplitude_error", "trajectory_error"):
            assert float(fine[error]) < 0.5 * float(coarse[error])
    best = wp.recommend(rows, "single", 1e-2)
    assert best is not None and best["rtol"] == "1e-06"  # 1e-7 has no run at 1e-8
    amplitude, _ = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))
    assert abs(float(best["amplitude_max"]) - amplitude) < 1e-2 * amplitude


def _row(rtol, amplitude_max, wall_s, amplitude_error=1e-3):
    """A successful row of the single scene as the CSV holds it (strings)."""
    return {"scene": "single", "method": "tsit5", "eps": "0.001", "rtol": str(rtol),
            "status": "ok", "wall_s": str(wall_s), "amplitude_error": str(amplitude_error),
            "amplitude_max": str(amplitude_max)}


def test_recommend_asks_a_run_at_rtol_over_10_that_agrees():
    """A setting is confirmed only by a run at exactly a tenth of its rtol that
    moves the largest amplitude by less than target/10, relative; a run at a tiny
    rtol never confirms itself."""
    target, a = 1e-2, 1.5
    # Tightening rtol from 1e-5 moves the amplitude by 2 target/10: not confirmed.
    moved = [_row(1e-5, a, 0.1), _row(1e-6, a * (1 + 0.2 * target), 0.2)]
    assert wp.recommend(moved, "single", target) is None
    # A run at 1e-7 confirms the one at 1e-6 (a move of target/20), not the faster 1e-5.
    agreed = moved + [_row(1e-7, a * (1 + 0.2 * target) * (1 + 0.05 * target), 0.4)]
    assert wp.recommend(agreed, "single", target)["rtol"] == "1e-06"
    # Tiny rtols: alone, or next to a run at rtol/10 that differs, never confirmed.
    assert wp.recommend([_row(1e-8, a, 0.1)], "single", target) is None
    differs = [_row(1e-9, a, 0.1), _row(1e-10, 1.1 * a, 0.2, amplitude_error=0.5)]
    assert wp.recommend(differs, "single", target) is None
    # ... and confirmed by a run at rtol/10 that agrees (1e-8 / 10 is not exactly 1e-9).
    same = [_row(1e-8, a, 0.1), _row(1e-9, a, 0.2)]
    assert wp.recommend(same, "single", target)["rtol"] == "1e-08"


#: The grid of the resumption test, and the settings that change its rows: another
#: scene (its v_d) and another step budget (both rtols then fail or are skipped).
GRID = (["single"], ["tsit5"], [1e-5, 1e-6], [1e-2])
OTHER_SETTINGS = {"scene v_d": ({"v_d": 1.6}, {}), "max_steps": ({}, {"max_steps": 50})}


def _measured(rows):
    """The rows without their wall and compilation times."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "compile_s")} for r in rows]


def test_resume_reads_back_only_rows_of_equal_settings(tmp_path, monkeypatch):
    """A study resumed from a CSV that holds rows of other settings (and rows of
    the old layout, without a key) gives what a fresh study gives, row by row;
    rows of equal settings are read back, nothing recomputed or appended."""
    single = wp.SCENES["single"]
    folder = tmp_path / "stored"
    folder.mkdir()
    old = ",".join(c for c in wp.COLUMNS if c != "key")
    (folder / "wp.csv").write_text(f"{old}\nsingle,tsit5,0.01,1e-05,1e-07,ok,0.1,0,10,"
                                   "0.5,0.5,0.5,1.0\n")
    first = wp.work_precision(folder / "wp.csv", *GRID, scipy=False, reference_points=False)
    assert _measured(first) == _measured(wp.work_precision(
        tmp_path / "fresh.csv", *GRID, scipy=False, reference_points=False))
    for name, (scene, options) in OTHER_SETTINGS.items():
        monkeypatch.setitem(wp.SCENES, "single", dataclasses.replace(single, **scene))
        resumed = wp.work_precision(folder / "wp.csv", *GRID, scipy=False,
                                    reference_points=False, **options)
        fresh = wp.work_precision(tmp_path / f"{name}.csv", *GRID, scipy=False,
                                  reference_points=False, **options)
        assert _measured(resumed) == _measured(fresh)
        # The change matters, so reading back `first`'s rows would have shown.
        assert [r["num_steps"] for r in resumed] != [r["num_steps"] for r in first], name
        monkeypatch.setitem(wp.SCENES, "single", single)
    written = (folder / "wp.csv").read_text()

    def nothing(*args, **kwargs):
        raise AssertionError("rows of equal settings must not be recomputed")
    monkeypatch.setattr(wp, "diffrax_point", nothing)
    monkeypatch.setattr(wp, "reference", nothing)
    assert wp.work_precision(folder / "wp.csv", *GRID, scipy=False,
                             reference_points=False) == first
    assert wp.work_precision(folder / "wp.csv", *GRID, scipy=False, reference_points=False,
                             max_steps=50) == resumed
    assert (folder / "wp.csv").read_text() == written


def test_max_steps_is_recorded_and_tighter_rtols_skipped(tmp_path):
    rows = wp.work_precision(tmp_path / "wp.csv", ["single"], ["tsit5"], [1e-4, 1e-6],
                             [1e-4], scipy=False, reference_points=False, max_steps=50)
    assert rows[0]["status"] == jc.Status.max_steps_reached.name
    assert rows[1]["status"] == f"{jc.Status.not_run}: max_steps at eps 0.0001"


def test_work_precision_command(tmp_path, capsys, monkeypatch):
    """The command end to end: the study with its reference points (one tolerance
    here: each is a timed non-smooth run, and those at 1e-8 and 1e-10 cost most of
    the study while running the same code), its CSV and its figure. The step budget
    of `wp.work_precision`'s default (the command's is `SimulationOptions`'), so that
    its smoothed runs are the programs `test_study_errors_fall_with_eps...` compiled."""
    monkeypatch.setattr(wp, "REFERENCE_RTOLS", wp.REFERENCE_RTOLS[:1])
    out = tmp_path / "out"
    code = jc.main(["work-precision", "--scenes", "single", "--solver", "tsit5",
                 "--rtol", "1e-6", "--eps", "1e-2", "--max-steps", str(STUDY_MAX_STEPS),
                 "--no-scipy", "--json", "--no-progress", "--out", str(out)])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert set(report["outputs"]) == {"work_precision.csv", "work_precision_single.png"}
    assert report["runs"] == 1 + len(wp.REFERENCE_RTOLS)
    assert (out / "work_precision_single.png").stat().st_size > 0
    header = (out / "work_precision.csv").read_text().splitlines()[0]
    assert header.split(",") == list(wp.COLUMNS)
