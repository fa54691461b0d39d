"""The work-precision study: its error measures, resumption and command, through
`jc.work_precision`, `jaxchain work-precision` and the CSV they write."""

import contextlib
import csv
import inspect
import io
import json
import shutil

import pytest

import jaxchain as jc
from helpers import scipy_stick_slip_cycle

#: The step budget of `jc.work_precision` by default (static in the compiled runs).
STUDY_MAX_STEPS = inspect.signature(jc.work_precision).parameters["max_steps"].default
#: The columns of the study's CSV, one row per (scene, method, eps, rtol).
COLUMNS = ["scene", "method", "eps", "rtol", "atol", "status", "wall_s", "compile_s",
           "num_steps", "amplitude_error", "energy_error", "trajectory_error",
           "amplitude_max", "key"]
#: The tolerances of the exact engine's outside points (method "exact").
REFERENCE_RTOLS = ("1e-06", "1e-08", "1e-10")


def _command(out, rtols, eps, *extra) -> tuple[int, dict]:
    """`jaxchain work-precision` on the single oscillator with tsit5, no scipy
    points: its exit status and its --json report."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = jc.main(["work-precision", "--scenes", "single", "--solver", "tsit5",
                        "--rtol", ",".join(map(str, rtols)), "--eps", str(eps),
                        "--max-steps", str(STUDY_MAX_STEPS), "--no-scipy", "--json",
                        "--no-progress", "--out", str(out), *extra])
    return code, json.loads(text.getvalue())


def _read(path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_study_errors_fall_with_eps_and_the_recommendation_holds(tmp_path):
    """For the single oscillator, the amplitude and trajectory errors against the
    reference fall with eps (the smoothed law converges to the non-smooth one).
    The recommended setting for 1 % (the command's, resumed from the study's CSV)
    is one that its run at rtol/10 confirms, and its amplitude is within 1 % of the
    stick-slip cycle computed independently with scipy."""
    out = tmp_path / "out"
    rows = jc.work_precision(out / "work_precision.csv", ["single"], ["tsit5"],
                             [1e-6, 1e-7], [1e-2, 1e-3], scipy=False,
                             reference_points=False)
    assert [r["status"] for r in rows] == ["ok"] * 4
    for rtol in ("1e-06", "1e-07"):
        coarse, fine = sorted((r for r in rows if r["rtol"] == rtol),
                              key=lambda r: -float(r["eps"]))
        for error in ("amplitude_error", "trajectory_error"):
            assert float(fine[error]) < 0.5 * float(coarse[error])
    code, report = _command(out, [1e-6, 1e-7], "1e-2,1e-3", "--resume")
    assert code == 0
    best = report["recommended"]["single 0.01"]
    assert best is not None and best["rtol"] == 1e-6  # 1e-7 has no run at 1e-8
    row, = (r for r in rows if r["method"] == best["solver"]
            and float(r["eps"]) == best["eps"] and float(r["rtol"]) == best["rtol"])
    amplitude, _ = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))
    assert abs(float(row["amplitude_max"]) - amplitude) < 1e-2 * amplitude


#: The grid of the command's run: tsit5 on the single oscillator at eps 0.1 (not
#: stiff, so that even rtol 1e-10 is cheap).
COMMAND_RTOLS = (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)


@pytest.fixture(scope="module")
def command_run(tmp_path_factory):
    """The folder and the --json report of `jaxchain work-precision` on
    `COMMAND_RTOLS`, with the reference points of the exact engine."""
    out = tmp_path_factory.mktemp("work-precision") / "out"
    code, report = _command(out, COMMAND_RTOLS, 0.1)
    assert code == 0
    return out, report


@pytest.mark.study
def test_work_precision_command(command_run):
    """The command end to end: the study with its reference points (the exact
    engine at rtol 1e-6, 1e-8 and 1e-10, each a timed non-smooth run), its CSV and
    its figure."""
    out, report = command_run
    assert set(report["outputs"]) == {"work_precision.csv", "work_precision_single.png"}
    assert report["runs"] == len(COMMAND_RTOLS) + len(REFERENCE_RTOLS)
    assert report["failed_runs"] == 0
    assert (out / "work_precision_single.png").stat().st_size > 0
    header = (out / "work_precision.csv").read_text().splitlines()[0]
    assert header.split(",") == COLUMNS
    rows = _read(out / "work_precision.csv")
    assert [r["rtol"] for r in rows if r["method"] == "exact"] == list(REFERENCE_RTOLS)
    assert [float(r["rtol"]) for r in rows if r["method"] == "tsit5"] == list(COMMAND_RTOLS)


@pytest.mark.study
def test_recommend_asks_a_run_at_rtol_over_10_that_agrees(command_run, tmp_path):
    """A setting is confirmed only by a run at exactly a tenth of its rtol that
    moves the largest amplitude by less than target/10, relative; a run at a tiny
    rtol never confirms itself. The command's rows are given these amplitudes and
    wall times in its CSV (their keys kept, so that --resume reads them back), and
    each grid below is the command resumed on part of them."""
    out = tmp_path / "out"
    shutil.copytree(command_run[0], out)
    target, a = 1e-2, 1.5
    # rtol: (largest amplitude, wall time, amplitude error)
    given = {1e-5: (a, 0.1, 1e-3),
             1e-6: (a * (1 + 0.2 * target), 0.2, 1e-3),
             1e-7: (a * (1 + 0.2 * target) * (1 + 0.05 * target), 0.4, 1e-3),
             1e-8: (a, 0.1, 1e-3), 1e-9: (a, 0.2, 1e-3), 1e-10: (1.1 * a, 0.2, 0.5)}
    rows = _read(out / "work_precision.csv")
    for r in rows:
        if r["method"] == "tsit5":
            amplitude, wall, error = given[float(r["rtol"])]
            r |= {"status": "ok", "amplitude_max": str(amplitude), "wall_s": str(wall),
                  "amplitude_error": str(error)}
    with open(out / "work_precision.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    written = (out / "work_precision.csv").read_text()

    def recommended(*rtols):
        code, report = _command(out, rtols, 0.1, "--resume")
        assert code == 0 and report["runs"] == len(rtols) + len(REFERENCE_RTOLS)
        return report["recommended"]["single 0.01"]

    # Tightening rtol from 1e-5 moves the amplitude by 2 target/10: not confirmed.
    assert recommended(1e-5, 1e-6) is None
    # A run at 1e-7 confirms the one at 1e-6 (a move of target/20), not the faster 1e-5.
    assert recommended(1e-5, 1e-6, 1e-7)["rtol"] == 1e-6
    # Tiny rtols: alone, or next to a run at rtol/10 that differs, never confirmed.
    assert recommended(1e-8) is None
    assert recommended(1e-9, 1e-10) is None
    # ... and confirmed by a run at rtol/10 that agrees (1e-8 / 10 is not exactly 1e-9).
    assert recommended(1e-8, 1e-9)["rtol"] == 1e-8
    # Every row was read back: nothing was run, nothing appended.
    assert (out / "work_precision.csv").read_text() == written


#: The grid of the resumption test.
GRID = (["single"], ["tsit5"], [1e-5, 1e-6], [1e-2])


def _measured(rows):
    """The rows without their wall and compilation times."""
    return [{k: v for k, v in r.items() if k not in ("wall_s", "compile_s")} for r in rows]


@pytest.mark.study
def test_resume_reads_back_only_rows_of_equal_settings(tmp_path):
    """A study resumed from a CSV that holds rows of other settings (and rows of
    the old layout, without a key) gives what a fresh study gives, row by row;
    rows of equal settings are read back, nothing recomputed or appended (a row
    computed would be appended with its own wall time)."""
    folder = tmp_path / "stored"
    folder.mkdir()
    old = ",".join(c for c in COLUMNS if c != "key")
    (folder / "wp.csv").write_text(f"{old}\nsingle,tsit5,0.01,1e-05,1e-07,ok,0.1,0,10,"
                                   "0.5,0.5,0.5,1.0\n")
    first = jc.work_precision(folder / "wp.csv", *GRID, scipy=False, reference_points=False)
    assert _measured(first) == _measured(jc.work_precision(
        tmp_path / "fresh.csv", *GRID, scipy=False, reference_points=False))
    # Another step budget (both rtols then fail or are skipped).
    resumed = jc.work_precision(folder / "wp.csv", *GRID, scipy=False,
                                reference_points=False, max_steps=50)
    fresh = jc.work_precision(tmp_path / "max_steps.csv", *GRID, scipy=False,
                              reference_points=False, max_steps=50)
    assert _measured(resumed) == _measured(fresh)
    # The change matters, so reading back `first`'s rows would have shown.
    assert [r["num_steps"] for r in resumed] != [r["num_steps"] for r in first]
    stored = folder / "wp.csv"
    written, mtime = stored.read_text(), stored.stat().st_mtime_ns
    assert jc.work_precision(stored, *GRID, scipy=False, reference_points=False) == first
    assert jc.work_precision(stored, *GRID, scipy=False, reference_points=False,
                             max_steps=50) == resumed
    assert stored.read_text() == written and stored.stat().st_mtime_ns == mtime


@pytest.mark.study
def test_max_steps_is_recorded_and_tighter_rtols_skipped(tmp_path):
    rows = jc.work_precision(tmp_path / "wp.csv", ["single"], ["tsit5"], [1e-4, 1e-6],
                             [1e-4], scipy=False, reference_points=False, max_steps=50)
    assert rows[0]["status"] == jc.Status.max_steps_reached.name
    assert rows[1]["status"] == f"{jc.Status.not_run}: max_steps at eps 0.0001"
