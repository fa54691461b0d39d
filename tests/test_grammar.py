"""One command-line grammar: every command parses --vd with the one function, takes
the solver options with the library's defaults, refuses to overwrite its results
unless asked, and a command that starts from one belt speed refuses a list."""

import contextlib
import io

import pytest

import jaxchain as jc
from helpers import EXAMPLE_RECORD, internal

build_parser, ALL_COMMANDS = internal("command-line parser"), internal("commands")
#: The commands that compute and write results (`server` shows and stops the warm
#: process: test_warm.py).
COMMANDS = [command for command in ALL_COMMANDS if command != "server"]
belt_speeds, one_belt_speed = internal("belt speeds"), internal("one belt speed")

#: Each command as the tests name it (figure needs a NAME), and the first file it
#: claims under --out.
ARGV = {"localized": ["localized"], "sweep": ["sweep"], "figure": ["figure", "4"],
        "crosscheck": ["crosscheck"], "work-precision": ["work-precision"],
        "boundaries": ["boundaries"], "stress": ["stress"], "basin": ["basin"],
        "snake": ["snake"], "mistuning": ["mistuning"], "identify": ["identify", EXAMPLE_RECORD]}
FIRST_OUTPUT = {"localized": "localized_vd1.5.nc", "sweep": "sweep.zarr",
                "figure": "figure4.nc", "crosscheck": "crosscheck.nc",
                "work-precision": "work_precision.csv", "boundaries": "boundaries.json",
                "stress": "stress.csv", "basin": "basin.nc", "snake": "snake.json",
                "mistuning": "mistuning.json", "identify": "identified_chain.toml"}


def _actions(command: str) -> dict:
    jc.configure()
    parser = build_parser([command])
    sub = next(a for a in parser._actions if a.dest == "command")  # argparse's subparsers
    return {a.dest: a for a in sub.choices[command]._actions}


def test_every_command_is_covered():
    assert set(ARGV) == set(FIRST_OUTPUT) == set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS)
def test_vd_has_one_grammar(command):
    actions = _actions(command)
    if "vd" in actions:
        assert actions["vd"].type in (belt_speeds, one_belt_speed)
    assert belt_speeds("1.5") == [1.5]
    assert belt_speeds("1.2,1.5") == [1.2, 1.5]
    assert belt_speeds("1:2:3") == [1.0, 1.5, 2.0]


@pytest.mark.parametrize("command", COMMANDS)
def test_solver_options_are_accepted_with_the_library_defaults(command):
    jc.configure()
    args = build_parser([command]).parse_args(
        [*ARGV[command], "--solver", "ros34pw2", "--rtol", "3e-5"])
    assert args.solver in ("ros34pw2", ["ros34pw2"]) and args.rtol in (3e-5, [3e-5])
    actions, defaults = _actions(command), jc.SimulationOptions()
    assert actions["max_steps"].default == defaults.max_steps
    # work-precision's --rtol is a list of tolerances to compare; identify's default
    # is tighter (its fit needs accurate sensitivities: IdentifyOptions)
    if command not in ("work-precision", "identify"):
        assert actions["rtol"].default == defaults.rtol
        assert actions["atol"].default == defaults.atol
        assert actions["controller"].default == defaults.controller


@pytest.mark.parametrize("command", COMMANDS)
def test_existing_results_are_refused_without_overwrite(command, tmp_path, capsys):
    (tmp_path / FIRST_OUTPUT[command]).write_text("an earlier result")
    assert jc.main([*ARGV[command], "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--overwrite" in err[0] and FIRST_OUTPUT[command] in err[0]
    assert (tmp_path / FIRST_OUTPUT[command]).read_text() == "an earlier result"


def test_a_command_of_one_belt_speed_refuses_a_list(capsys):
    with pytest.raises(SystemExit) as exc, contextlib.redirect_stdout(io.StringIO()):
        jc.main(["snake", "--vd", "1.4,1.5"])
    assert exc.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--vd" in line and "one belt speed" in line


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_help_names_no_issue_and_no_measured_time(command):
    """Measured times live on the documentation's Performance page, and issue
    numbers in the history, never in --help."""
    import re

    jc.configure()
    parser = build_parser([command])
    sub = next(a for a in parser._actions if a.dest == "command")
    text = parser.format_help() + sub.choices[command].format_help()
    assert not re.search(r"\bissues? \d+", text, re.IGNORECASE)
    assert not re.search(r"\b\d+(\.\d+)? ?(s|ms|us|µs|min|minutes|seconds|hours)\b", text)
