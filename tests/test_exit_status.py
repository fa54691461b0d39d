"""The exit status of every `jaxchain` command: 2 only for a usage error (a bad
option, or an argument the library's own checks refuse: `ValidationError`), 1 with
one line for a run that fails, whatever it raises. Nothing heavy runs here: each
command's first heavy step is replaced by one that raises.

These are the command line's internals, imported from its private modules
(`jaxchain._cli`): its parser and commands, the exit status of an error, and the
first heavy step of each command, which a test replaces."""

import contextlib
import json
import importlib
import io
import re
import tempfile

import equinox as eqx
import jax.numpy as jnp
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxchain as jc
import jaxchain._cli.boundaries as cli_boundaries
import jaxchain._cli.work_precision as cli_work_precision
import jaxchain._studies.work_precision as wp
from jaxchain._cli.common import RunsFailed, UsageError
from jaxchain._cli.main import COMMANDS, build_parser, exit_status, main
from helpers import EXAMPLE_RECORD as RECORD

#: Per command, the first heavy step of its run, (module, name): reached only once
#: the command's own checks and those of the library's entry point have passed
#: (figure, boundaries and snake: their study, whose arguments the command checks).
#: Dask's `connect` is there for --scheduler, which a command reaches before its
#: study when given.
STUDIES = {
    "localized": [("jaxchain._sweeps.ensemble", "lane_params")],
    "sweep": [("jaxchain._sweeps.sweep", "SweepStore")],
    "figure": [("jaxchain._cli.figure", "_scene")],
    "crosscheck": [("jaxchain._studies.crosscheck", "excited_block")],  # the initial states
    "work-precision": [("jaxchain._studies.work_precision", "CsvStore")],
    "boundaries": [("jaxchain._cli.boundaries", "bistable_range")],
    "stress": [("jaxchain._cli.stress", "stress_cases")],  # builds every case
    "basin": [("jaxchain._studies.basin.basin", "sample_states")],
    "snake": [("jaxchain._cli.snake", "localized_branches")],
    "mistuning": [("jaxchain._studies.mistuning.study", "sample_states"),
                  ("jaxchain._studies.mistuning.study", "study_chains"),
                  ("jaxchain._studies.mistuning.design_study", "design_study")],
    "identify": [("jaxchain._studies.identification.fit", "_stage")],
    "response": [("jaxchain._cli.response", "frequency_response")],
    "magnification": [("jaxchain._cli.magnification", "magnification_study")],
    "localized-ranges": [("jaxchain._studies.localized_ranges", "branch_range")],
}
CLUSTER = ("jaxchain._engine.cluster", "connect")

#: The smallest command line of each command (beside --out): its defaults.
#: The commands that compute (`server` shows and stops warm processes: test_warm.py).
COMPUTING = [command for command in COMMANDS if command != "server"]

ARGV = {command: [command] for command in COMPUTING} | {
    "figure": ["figure", "4"], "identify": ["identify", RECORD],
    "response": ["response", "--force", "0.1,0.8", "--to", "1.2"]}


class Reached(BaseException):
    """Raised in place of a command's first heavy step. Not an `Exception`, so that
    neither the library nor `main` catches it."""


def _raise(error: BaseException):
    def replacement(*args, **kwargs):
        raise error
    return replacement


def _patch(mp: pytest.MonkeyPatch, command: str, error: BaseException) -> None:
    """Make `command`'s first heavy step (and Dask's `connect`) raise `error`."""
    for module, name in [*STUDIES[command], CLUSTER]:
        mp.setattr(importlib.import_module(module), name, _raise(error))


def _run(argv: list[str]) -> tuple[int | str, list[str]]:
    """`main(argv)`: its exit status ("reached" when the study was reached) and the
    lines it wrote on stderr."""
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            status = main(argv)
    except Reached:
        status = "reached"
    except SystemExit as exc:  # the parser's own errors
        status = exc.code
    return status, stderr.getvalue().strip().splitlines()


def test_every_command_is_covered():
    assert set(STUDIES) == set(COMPUTING) == set(ARGV)


@pytest.mark.parametrize("argv", [*ARGV.values(), ["mistuning", "--design"],
                                  ["mistuning", "--samples", "0"],
                                  ["sweep", "--scheduler", "local:2"]])
def test_a_default_command_line_reaches_its_study(argv, tmp_path, monkeypatch):
    """The steps replaced below are the ones each command runs: with its defaults,
    every command gets there (so that the tests below exercise its checks)."""
    monkeypatch.delenv("JAXCHAIN_TRACEBACK", raising=False)
    _patch(monkeypatch, argv[0], Reached())
    status, err = _run([*argv, "--out", str(tmp_path)])
    assert status == "reached", err


@pytest.mark.parametrize("command", COMPUTING)
@pytest.mark.parametrize("error", [ValueError("boom from numpy: operands could not be "
                                              "broadcast together\nwith shapes (3,) (4,)"),
                                   RuntimeError("boom in a solve"),
                                   KeyError("boom")],
                         ids=["ValueError", "RuntimeError", "KeyError"])
def test_an_error_inside_a_run_exits_1_with_one_line(command, error, tmp_path, monkeypatch):
    """A run that fails, whatever it raises (NumPy's ValueError included), is exit
    status 1 and one line on stderr naming the command and the error: no traceback,
    and never status 2, which says the command line was wrong."""
    monkeypatch.delenv("JAXCHAIN_TRACEBACK", raising=False)
    _patch(monkeypatch, command, error)
    status, err = _run([*ARGV[command], "--out", str(tmp_path)])
    assert status == 1, err
    assert len(err) == 1 and err[0].startswith(f"jaxchain {command}: error: "), err
    assert "boom" in err[0] and "Traceback" not in err[0]


#: A command line of each command that the parser takes and the library's own
#: validation refuses, with a word its message must hold.
REFUSED = [
    (["localized", "--transient", "20000"], "--transient"),      # SimulationOptions
    (["sweep", "--mistuning", "40"], "stiffness"),               # mistune's draw
    (["figure", "4", "--mistuning", "40"], "stiffness"),
    (["crosscheck", "--transient", "2e4"], "--transient"),       # SimulationOptions
    (["work-precision", "--solver", ""], "solver"),            # work_precision
    (["boundaries", "--mistuning", "40"], "stiffness"),
    (["basin", "--samples", "10", "--check", "20"], "--check"),  # basin_stability
    (["snake", "--mistuning", "40"], "stiffness"),
    (["mistuning", "--sigmas", "-1"], "sigmas"),                 # mistuning_study
    (["identify", RECORD, "--fit", "v_d"], "cannot be fitted"),  # unknowns_of
    (["response", "--force", "0.1,0.8", "--to", "1.2", "--harmonics", "4",
      "--time-samples", "8"], "time_samples"),                   # HarmonicBalance
    (["magnification", "--harmonics", "4", "--time-samples", "8"], "time_samples"),
    (["localized-ranges", "--site", "20"], "site"),              # localized_ranges
]


def test_every_command_has_a_refused_line():
    assert {argv[0] for argv, _ in REFUSED} == set(COMPUTING) - {"stress"}  # no library check


@pytest.mark.parametrize("argv, says", REFUSED)
def test_a_validation_error_of_the_library_exits_2(argv, says, tmp_path, monkeypatch):
    """The library's own checks, run by a command before its study: exit status 2
    and one line naming the value; the exception is a `ValidationError`."""
    _patch(monkeypatch, argv[0], Reached())
    argv = [*argv, "--out", str(tmp_path)]
    monkeypatch.delenv("JAXCHAIN_TRACEBACK", raising=False)
    status, err = _run(argv)
    assert status == 2 and len(err) == 1 and says in err[0], err
    monkeypatch.setenv("JAXCHAIN_TRACEBACK", "1")  # the exception itself
    with pytest.raises(jc.ValidationError), contextlib.redirect_stdout(io.StringIO()):
        main(argv)


@pytest.mark.parametrize("err, status", [
    (UsageError("--vd: bad"), 2),
    (jc.ValidationError("SimulationOptions.rtol must be > 0"), 2),
    (ValueError("operands could not be broadcast together"), 1),
    (RuntimeError("max_steps reached"), 1),
    (RunsFailed("1 of 3 runs failed"), 1),
    (KeyError("settings_key"), 1),
    (OSError(28, "No space left on device"), 1),
    (TypeError("unsupported operand"), 1),
])
def test_exit_status_is_2_only_for_usage_and_validation(err, status):
    code, message = exit_status(err)
    assert code == status and "\n" not in message and message
    if status == 2:  # field names shown as the options a user typed
        assert "SimulationOptions" not in message


def test_the_existence_bracket_is_a_failed_run_not_a_usage_error():
    """The issue's example: a bracket that does not bracket the existence limit is
    found by integrating, not by checking the arguments; it stays a ValueError
    (callers that catch ValueError still do) but is no ValidationError: status 1."""
    single = jc.ChainParams(n_osc=1)
    lower = 2.5  # above the limit, about 1.84 for eq. (7) (Fig. 3(a)): no cycle there
    with pytest.raises(ValueError, match="must contain") as exc:
        jc.stick_slip_existence_limit(single, lower=lower, upper=1.5 * lower)
    assert not isinstance(exc.value, jc.ValidationError)
    assert exit_status(exc.value)[0] == 1


TOKENS = st.sampled_from(["abc", "-1", "0", "1", "3", "nan", "inf", "-inf", "1e-3", "0.5",
                          "", ",", "1.5,", "2", "1:2:3", "1.0,2.0", "0.5,1", "1,0.5",
                          "eq8", "eq10", "x,y", "1e400", "--", "--bogus", "-q",
                          "ros34pw2", "euler", "20", "2.5", "local:0", "local:2",
                          "exponential:mu_st=0.1", "coulomb:mu=1", "single", "chain"])


def _subparser(command: str):
    sub = next(a for a in build_parser([command])._actions if a.dest == "command")
    return sub.choices[command]


def _typical(action) -> list[str]:
    """Values an option takes: its choices, else its default as typed (a list
    comma-joined), twice and a tenth of a number."""
    if action.choices:
        return sorted(map(str, action.choices))
    d = action.default
    if isinstance(d, (list, tuple)):
        return [",".join(map(str, d))]
    if isinstance(d, (int, float)) and not isinstance(d, bool):
        return [str(d), str(2 * d), str(d / 10)]
    return [] if d is None else [str(d)]


def _values(action):
    """What follows an option, as many as it takes: half the time a typical value,
    half a token."""
    typical = _typical(action)
    one = st.one_of(st.sampled_from(typical), TOKENS) if typical else TOKENS
    count = {None: 1, 0: 0, "?": 1, "*": 1, "+": 1}.get(action.nargs, action.nargs)
    return st.lists(one, min_size=count, max_size=count)


def _command_argv(command: str):
    """argv for one command: its positional arguments (one of their choices), then
    options with typical values or tokens (`_values`), and stray tokens."""
    parser = _subparser(command)
    positional = [st.sampled_from(sorted(map(str, a.choices))) if a.choices else TOKENS
                  for a in parser._actions if not a.option_strings]
    options = [st.tuples(st.just([a.option_strings[-1]]), _values(a)).map(lambda t: t[0] + t[1])
               for a in parser._actions if a.option_strings and a.dest != "help"]
    items = st.lists(st.one_of(*options, TOKENS.map(lambda t: [t])), max_size=4)
    return st.tuples(st.tuples(*positional), items).map(
        lambda t: [command, *t[0], *(s for item in t[1] for s in item)])


@pytest.mark.parametrize("command", COMPUTING)
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_fuzzed_command_lines_exit_2_in_one_line_or_reach_the_study(command, data):
    """Random options and values, through `main`: the parser, the command's checks
    and those of the library's entry point. Each line either reaches the command's
    study (replaced by one that raises) or ends with status 2 and one line on
    stderr naming the command: never a traceback, nor another status."""
    argv = data.draw(_command_argv(command))
    with pytest.MonkeyPatch.context() as mp, tempfile.TemporaryDirectory() as folder:
        mp.chdir(folder)  # the default --out and any relative one land here
        mp.delenv("JAXCHAIN_TRACEBACK", raising=False)
        _patch(mp, command, Reached())
        status, err = _run(argv)
    if status != "reached":
        assert status == 2 and len(err) == 1, (argv, status, err)
        assert re.match(rf"jaxchain( {command})?: error: ", err[0]), (argv, err)


def _compiled_error():
    """A failure inside compiled code, as the library's solvers raise it."""
    fail = eqx.filter_jit(lambda x: eqx.error_if(x, x > 0, "max_steps reached: raise "
                                                           "max_steps"))
    fail(jnp.array(1.0))


def _raise_now(err):
    raise err


@pytest.mark.parametrize("fail, says", [
    (lambda: _raise_now(RuntimeError("the fold was lost at xi = 0.05: lower learning_rate"
                                 "\n  more detail on a second line")), "fold was lost"),
    (_compiled_error, "max_steps reached: raise max_steps"),
    (lambda: _raise_now(KeyError("hopf_vd")), "KeyError: 'hopf_vd'"),
])
def test_boundaries_failure_exits_1_with_one_line(fail, says, monkeypatch, tmp_path, capsys):
    monkeypatch.delenv("JAXCHAIN_TRACEBACK", raising=False)
    monkeypatch.setattr(cli_boundaries, "bistable_range", lambda *a, **k: fail())
    assert jc.main(["boundaries", "--no-progress", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("jaxchain boundaries: error: ")
    assert says in err


def test_work_precision_failed_runs_exit_1(tmp_path, monkeypatch, capsys):
    """A study with a failed run (recorded with its status; the skipped runs after it
    are not failures) reports it, and the status is 1. The study itself is replaced
    by its rows: test_work_precision.py checks that max_steps is recorded."""
    row = dict.fromkeys(wp.COLUMNS, "") | {"scene": "single", "method": "tsit5",
                                            "eps": "0.01", "atol": "1e-08"}
    rows = [row | {"rtol": "1e-06", "status": "ok", "wall_s": "0.1", "num_steps": "90",
                   "amplitude_error": "1e-3", "energy_error": "1e-3",
                   "trajectory_error": "1e-3", "amplitude_max": "1.7"},
            row | {"rtol": "1e-08", "status": "max_steps_reached", "wall_s": "0.3"},
            row | {"rtol": "1e-10", "status": "not_run: max_steps at rtol 1e-08"}]
    monkeypatch.setattr(cli_work_precision, "work_precision", lambda *a, **k: rows)
    code = jc.main(["work-precision", "--scenes", "single", "--solver", "tsit5", "--rtol",
                 "1e-6,1e-8,1e-10", "--eps", "1e-2", "--no-scipy", "--json",
                 "--no-progress", "--out", str(tmp_path)])
    assert code == 1
    captured = capsys.readouterr()
    assert json.loads(captured.out)["failed_runs"] == 1
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "1 of 3 runs failed" in err
    assert (tmp_path / "work_precision_single.png").stat().st_size > 0


def test_the_snake_summary_prints_a_check_without_a_growth_and_an_end_without_a_speed(capsys):
    """A simulation check that agrees carries no expected growth (None in the
    summary), and a stable range may end where no speed was found: the table is
    printed (the command failed with a TypeError once). A branch started at another
    belt speed than the run's says so."""
    from jaxchain._cli.snake import _print_summary

    check = {"v_d": 1.3, "side": "inside", "end": "fold", "persists": True, "agrees": True,
             "expected_growth": None}
    branch = {"label": "k=1", "sites": 1, "stable_ranges": [[1.2, 1.4]], "connects_to": [],
              "stable_range_ends": [[{"type": "fold", "v_d": None}]],
              "simulation_check": [check, check | {"agrees": None, "expected_growth": 0.25}]}
    _print_summary({"branches": [branch], "not_periodic": []})
    out = capsys.readouterr().out
    assert "fold at -" in out and "(agrees)" in out and "undecided: growth 0.25" in out
    assert "started at" not in out  # a summary without the run's v_d (an older one)
    elsewhere = branch | {"label": "k=9", "start": {"v_d": 1.6}}
    _print_summary({"branches": [branch | {"start": {"v_d": 1.5}}, elsewhere],
                    "not_periodic": [], "v_d": 1.5})
    out = capsys.readouterr().out
    assert out.count("started at") == 1 and "started at v_d = 1.6" in out


def test_a_check_by_shooting_that_disagrees_fails_the_localized_ranges_run():
    """`jaxchain localized-ranges --check K` exits 1 where shooting and harmonic
    balance disagree: the draws named are those with an end off by more than the
    tolerance, of another kind, or without a range by shooting (the figures of
    draws 1 and 0 at 2 eta_c, the second as a march stopped short gave it)."""
    from jaxchain._cli.localized_ranges import CHECK_TOLERANCE, check_disagreements

    def draw(d, low, high, low_hb, high_hb, kinds=("fold", "fold"), kinds_hb=None):
        kinds_hb = kinds_hb or kinds
        return {"draw": d, "low": low, "high": high, "low_hb": low_hb, "high_hb": high_hb,
                "low_kind": kinds[0], "high_kind": kinds[1], "low_kind_hb": kinds_hb[0],
                "high_kind_hb": kinds_hb[1], "difference": None if low is None else
                max(abs(low - low_hb), abs(high - high_hb))}

    agree = draw(1, 1.17871, 1.76136, 1.17904, 1.76130, ("Neimark-Sacker", "fold"))
    short = draw(0, 1.36754, 1.76079, 1.36645, 1.70448, kinds_hb=("fold", "period doubling"))
    off = draw(2, 1.35273, 1.75918, 1.35273 + 2 * CHECK_TOLERANCE, 1.75918)
    kind = draw(3, 1.32157, 1.76296, 1.32157, 1.76296, kinds_hb=("Neimark-Sacker", "fold"))
    lost = draw(4, None, None, 1.3, 1.76)
    assert check_disagreements([agree]) == []
    assert check_disagreements([agree, short, off, kind, lost]) == [0, 2, 3, 4]
