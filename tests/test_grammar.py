"""One command-line grammar: every command parses --vd with the one function, takes
the solver options with the library's defaults, refuses to overwrite its results
unless asked, and a command that starts from one belt speed refuses a list.

Everything here goes through the `jaxchain` command (`jc.main`): its --help text,
its usage errors (exit status 2, one line) and what a run prints and writes."""

import contextlib
import io
import json
import re

import pytest

import jaxchain as jc
from helpers import EXAMPLE_RECORD


def _help(argv: list[str]) -> str:
    """What `jaxchain ARGV --help` prints (it exits with status 0)."""
    out = io.StringIO()
    with pytest.raises(SystemExit) as exc, contextlib.redirect_stdout(out):
        jc.main([*argv, "--help"])
    assert exc.value.code == 0
    return out.getvalue()


def _commands() -> list[str]:
    """The commands that `jaxchain --help` lists (under COMMAND, four spaces in)."""
    text = _help([]).split("COMMAND\n", 2)[-1]
    return re.findall(r"^    ([a-z][a-z-]*)", text, re.MULTILINE)


def _option_help(text: str, option: str) -> str:
    """The help of `option` in a command's --help text, on one line."""
    match = re.search(rf"^  {re.escape(option)}\b.*?(?=^  -|^\S|\Z)", text,
                      re.MULTILINE | re.DOTALL)
    assert match, f"{option} is not in the help"
    return " ".join(match.group(0).split())


ALL_COMMANDS = _commands()
#: The commands that compute and write results (`server` shows and stops the warm
#: process: test_warm.py).
COMMANDS = [command for command in ALL_COMMANDS if command != "server"]

#: Each command as the tests name it (figure needs a NAME), and the first file it
#: claims under --out.
ARGV = {"localized": ["localized"], "sweep": ["sweep"], "figure": ["figure", "4"],
        "crosscheck": ["crosscheck"], "work-precision": ["work-precision"],
        "boundaries": ["boundaries"], "stress": ["stress"], "basin": ["basin"],
        "snake": ["snake"], "mistuning": ["mistuning"], "identify": ["identify", EXAMPLE_RECORD],
        "response": ["response", "--force", "0.1,0.8", "--to", "1.2"],
        "magnification": ["magnification"], "localized-ranges": ["localized-ranges"]}
FIRST_OUTPUT = {"localized": "localized_vd1.5.nc", "sweep": "sweep.zarr",
                "figure": "figure4.nc", "crosscheck": "crosscheck.nc",
                "work-precision": "work_precision.csv", "boundaries": "boundaries.json",
                "stress": "stress.csv", "basin": "basin.nc", "snake": "snake.json",
                "mistuning": "mistuning.json", "identify": "identified_chain.toml",
                "response": "response.nc", "magnification": "magnification.nc",
                "localized-ranges": "localized_ranges.nc"}

#: The --vd grammar's metavar, of the commands that run a list of belt speeds and of
#: those that start from one.
VD_LIST, VD_ONE = "[--vd V|V,V,...|START:STOP:NUM]", "[--vd V]"
#: Values that the one grammar of --vd refuses, with the words it says (in no other
#: parser of the command line).
VD_REFUSED = {"1:2:0": "NUM must be >= 1, got '1:2:0'",
              "fast": "expected V, a list V1,V2,... or START:STOP:NUM, got 'fast'",
              "1.5,-1": "belt speeds must be finite and > 0, got '1.5,-1'",
              ",": "expected at least one belt speed, got ','"}
#: The commands whose belt may stand still (a forced chain's friction damper): the
#: same grammar, 0 allowed; a negative speed is refused with these words instead.
AT_REST = {"response": "belt speeds must be finite and >= 0 (0: the belt at rest), got "
                       "'1.5,-1'"}
#: The commands that integrate only at their orbit method's own tolerances
#: (`for_orbits`), and so take no solver options.
ORBITS_ONLY = ("response", "magnification", "localized-ranges")


def _usage_error(argv: list[str], capsys) -> str:
    """The one line of a refusal by the parser: `jaxchain ARGV` exits with status 2."""
    with pytest.raises(SystemExit) as exc, contextlib.redirect_stdout(io.StringIO()):
        jc.main(argv)
    assert exc.value.code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    return line


def test_every_command_is_covered():
    assert set(ARGV) == set(FIRST_OUTPUT) == set(COMMANDS)
    assert "server" in ALL_COMMANDS and len(COMMANDS) == 14


@pytest.mark.parametrize("command", COMMANDS)
def test_vd_has_one_grammar(command, capsys):
    """Every command that takes --vd reads it with the one grammar: the same
    metavar in --help, the same refusals in one line; a command that starts from one
    belt speed says so."""
    usage = " ".join(_help([command]).split("\n\n")[0].split())  # its usage lines
    if not re.search(r"\[--vd[ \]]", usage):
        return
    one = VD_ONE in usage
    assert one or VD_LIST in usage, usage
    for value, says in VD_REFUSED.items():
        if value == "1.5,-1" and command in AT_REST:
            says = AT_REST[command]
        line = _usage_error([*ARGV[command], "--vd", value], capsys)
        assert "--vd" in line and says in line, line
    list_line = _usage_error([*ARGV[command], "--vd", "1:2:3"], capsys) if one else None
    assert not one or ("one belt speed" in list_line and "3" in list_line)


@pytest.mark.parametrize("vd, speeds", [("1.5", [1.5]), ("1.2,1.5", [1.2, 1.5]),
                                        ("1:2:3", [1.0, 1.5, 2.0])])
def test_vd_forms_give_the_belt_speeds_run(vd, speeds, tmp_path, capsys):
    """What each form of --vd reads as: the belt speeds that `jaxchain localized`
    runs (a ring of one, two time units), in its JSON and its files."""
    argv = ["localized", "--n-osc", "1", "--t-end", "2", "--transient", "1", "--vd", vd,
            "--json", "--no-progress", "--out", str(tmp_path)]
    assert jc.main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [run["v_d"] for run in doc["runs"]] == speeds
    assert sorted(doc["outputs"]) == sorted(f"localized_vd{v:g}.{ext}" for v in speeds
                                            for ext in ("nc", "png"))


@pytest.mark.parametrize("command", COMMANDS)
def test_solver_options_are_accepted_with_the_library_defaults(command, tmp_path, capsys):
    """--solver and --rtol parse in every command that simulates (it goes on to
    refuse the existing result, not the options), and --help shows the library's
    defaults; a command of orbits only refuses them."""
    if command in ORBITS_ONLY:
        assert "--solver" not in _help([command])
        return
    (tmp_path / FIRST_OUTPUT[command]).write_text("an earlier result")
    argv = [*ARGV[command], "--solver", "ros34pw2", "--rtol", "3e-5", "--out", str(tmp_path),
            "--no-progress"]
    assert jc.main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--overwrite" in line and FIRST_OUTPUT[command] in line, line
    text, defaults = _help([command]), jc.SimulationOptions()
    assert f"(default {defaults.max_steps})" in _option_help(text, "--max-steps")
    # work-precision's --rtol is a list of tolerances to compare; identify's default
    # is tighter (its fit needs accurate sensitivities: IdentifyOptions)
    if command not in ("work-precision", "identify"):
        assert f"(default {defaults.controller}:" in _option_help(text, "--controller")
        # the library's rtol and atol follow eps: the rule --help states is the
        # smoothed engine's, at the default eps and at others
        assert defaults.rtol is None and defaults.atol is None
        for option in ("rtol", "atol"):
            said = re.search(r"\(default min\(([0-9.e+-]+), eps/([0-9.]+)\)",
                             _option_help(text, f"--{option}"))
            assert said, _option_help(text, f"--{option}")
            cap, per_eps = float(said.group(1)), float(said.group(2))
            for eps in (1e-2, 1e-3, 3e-4, 1e-5):
                engine = jc.Smoothed(eps=eps, options=defaults)
                assert min(cap, eps / per_eps) == pytest.approx(
                    getattr(engine.options, option), rel=1e-12), (option, eps)


def test_solver_options_typed_reach_the_run_and_defaults_are_the_library_s(tmp_path,
                                                                          capsys):
    """What --solver, --rtol, --atol, --controller and --max-steps set, as a run
    records it (its JSON and its file's attributes); left out, the library's."""
    import xarray as xr

    base = ["localized", "--n-osc", "1", "--t-end", "2", "--transient", "1", "--json",
            "--no-progress"]
    typed = ["--solver", "tsit5", "--rtol", "1e-5", "--atol", "1e-8", "--controller",
             "diffrax", "--max-steps", "5000"]
    for argv, out in ((typed, tmp_path / "typed"), ([], tmp_path / "defaults")):
        assert jc.main([*base, *argv, "--out", str(out)]) == 0
        doc = json.loads(capsys.readouterr().out)
        with xr.open_dataset(out / "localized_vd1.5.nc") as ds:
            attrs = dict(ds.attrs)
        assert (doc["solver"], doc["rtol"], doc["atol"]) == (
            attrs["solver"], attrs["rtol"], attrs["atol"])
        if argv:
            assert (attrs["solver"], attrs["rtol"], attrs["atol"], attrs["controller"],
                    attrs["max_steps"]) == ("Tsit5", 1e-5, 1e-8, "diffrax", 5000)
        else:
            library = jc.Smoothed()
            assert attrs["solver"] == type(library.solver).__name__
            assert (attrs["rtol"], attrs["atol"]) == (library.options.rtol,
                                                      library.options.atol)
            assert attrs["controller"] == jc.SimulationOptions().controller
            assert attrs["max_steps"] == jc.SimulationOptions().max_steps


@pytest.mark.parametrize("command", COMMANDS)
def test_existing_results_are_refused_without_overwrite(command, tmp_path, capsys):
    (tmp_path / FIRST_OUTPUT[command]).write_text("an earlier result")
    assert jc.main([*ARGV[command], "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--overwrite" in err[0] and FIRST_OUTPUT[command] in err[0]
    assert (tmp_path / FIRST_OUTPUT[command]).read_text() == "an earlier result"


def test_a_command_of_one_belt_speed_refuses_a_list(capsys):
    line = _usage_error(["snake", "--vd", "1.4,1.5"], capsys)
    assert "--vd" in line and "one belt speed" in line


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_help_names_no_issue_and_no_measured_time(command):
    """Measured times live on the documentation's Performance page, and issue
    numbers in the history, never in --help."""
    text = _help([]) + _help([command])
    assert not re.search(r"\bissues? \d+", text, re.IGNORECASE)
    assert not re.search(r"\b\d+(\.\d+)? ?(s|ms|us|µs|min|minutes|seconds|hours)\b", text)
