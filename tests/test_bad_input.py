"""Bad input to the Python API raises at once, naming the argument and what it
accepts: nothing is traced or run first. Hypothesis fuzzes the validation of the
parameters and the options."""

import contextlib
import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxchain as jc

P = jc.ChainParams(n_osc=3)
OPTS = jc.SimulationOptions(t_end=20.0, transient=10.0)
Y0 = np.zeros((2, 3))
FAMILY = jc.localized_family(3)

CASES = {
    "y0 of the wrong shape": (lambda: jc.simulate(P, np.zeros((3, 3)), options=OPTS),
                              ValueError, "y0 must have shape"),
    "y0 of strings": (lambda: jc.simulate(P, [["a"] * 3] * 2, options=OPTS), TypeError, "y0"),
    "y0 of booleans": (lambda: jc.simulate(P, np.ones((2, 3), dtype=bool), options=OPTS),
                       TypeError, "y0"),
    "y0 ragged": (lambda: jc.simulate(P, [[0.0, 1.0], [0.0]], options=OPTS), TypeError, "y0"),
    "y0 complex": (lambda: jc.simulate(P, np.zeros((2, 3), complex), options=OPTS),
                   TypeError, "y0"),
    "an unknown solver name": (lambda: jc.simulate(P, Y0, "euler", options=OPTS),
                               ValueError, "solver must be one of"),
    "a solver that is not one": (lambda: jc.simulate(P, Y0, object(), options=OPTS),
                                 TypeError, "solver must be a diffrax solver"),
    "options that are not options": (lambda: jc.simulate(P, Y0, options="fast"),
                                     TypeError, "options must be"),
    "params that are not ChainParams": (lambda: jc.simulate({"v_d": 1.5}, Y0, options=OPTS),
                                        TypeError, "params must be"),
    "an empty list of belt speeds": (lambda: jc.ensemble(P, [], FAMILY, options=OPTS),
                                     ValueError, "v_d must be a 1-d list of at least one"),
    "a negative belt speed": (lambda: jc.ensemble(P, [1.5, -1.0], FAMILY, options=OPTS),
                              ValueError, "v_d must hold finite belt speeds > 0"),
    "a NaN belt speed": (lambda: jc.ensemble(P, [np.nan], FAMILY, options=OPTS),
                         ValueError, "v_d must hold"),
    "belt speeds of strings": (lambda: jc.ensemble(P, ["fast"], FAMILY, options=OPTS),
                               TypeError, "v_d must be an array of real numbers"),
    "an empty ensemble": (lambda: jc.ensemble(P, [1.5], jc.GivenState(np.zeros((0, 2, 3))),
                                              options=OPTS),
                          ValueError, "at least one initial condition"),
    "ics that are not ics": (lambda: jc.ensemble(P, [1.5], [Y0], options=OPTS),
                             TypeError, "ics must be initial conditions"),
    "ics for another ring": (lambda: jc.ensemble(P, [1.5], jc.localized_family(4), options=OPTS),
                             ValueError, "excited must have shape"),
    "an empty sweep grid": (lambda: jc.sweep(P, [], {"eq8": FAMILY}, options=OPTS),
                            ValueError, "at least one value"),
    "a sweep with no families": (lambda: jc.sweep(P, [1.5], {}, options=OPTS),
                                 ValueError, "at least one family"),
    "an empty cross-check": (lambda: jc.crosscheck(P, [1.5], [], options=OPTS),
                             ValueError, "ics must list at least one"),
    "solutions outside the ring": (lambda: jc.observe_solutions(P, [0], [jc.Extrema()],
                                                                options=OPTS),
                                   ValueError, "solutions must be numbers"),
    "an observer that is not one": (lambda: jc.observe(P, Y0, ["amplitudes"], options=OPTS),
                                    TypeError, "AbstractObserver"),
    "t_end <= transient": (lambda: jc.SimulationOptions(t_end=5.0, transient=10.0),
                           ValueError, "SimulationOptions.transient must lie in"),
    "a fractional max_steps": (lambda: jc.SimulationOptions(max_steps=2.5),
                               ValueError, "SimulationOptions.max_steps must be an integer"),
    "a string transient": (lambda: jc.SimulationOptions(transient="a"),
                           ValueError, "SimulationOptions.transient"),
    "a string parameter": (lambda: jc.ChainParams(xi="a"), TypeError, "ChainParams.xi"),
    "a boolean parameter": (lambda: jc.ChainParams(v_d=True), TypeError, "ChainParams.v_d"),
    "a NaN parameter": (lambda: jc.ChainParams(eps=np.nan), ValueError, "ChainParams.eps"),
    "mu_st below mu_d": (lambda: jc.ChainParams(mu_st=0.2), ValueError,
                         "ExponentialDecay.mu_st"),
    "a time series with dt <= 0": (lambda: jc.observe(P, Y0, [jc.TimeSeries(dt=0.0)],
                                                      options=OPTS),
                                   ValueError, "TimeSeries.dt"),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_input_raises_naming_the_argument(case):
    call, error, says = CASES[case]
    with pytest.raises(error, match=says):
        call()


def test_integer_states_are_taken_as_numbers():
    obs = jc.simulate(P, np.asarray(jc.steady_sliding(P)).round().astype(int), options=OPTS,
                      throw=False)
    assert obs.y_initial.dtype == np.float64


FIELDS = ("xi", "mu_d", "mu_st", "v0", "eta_c", "v_d", "eps")
RULES = {"xi": lambda a: a >= 0, "mu_d": lambda a: (a > 0) & (a <= 1.0),
         "mu_st": lambda a: a >= 0.5,
         "v0": lambda a: a > 0, "eta_c": lambda a: a >= 0, "v_d": lambda a: a > 0,
         "eps": lambda a: a > 0}
VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10, 10),
                   st.text(max_size=3), st.booleans(), st.none(),
                   st.lists(st.floats(-2, 2), max_size=3))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(FIELDS), VALUES)
def test_fuzzed_parameters_are_accepted_exactly_when_valid(field, value):
    """One field at a time, the others at eq. (7) (mu_d = 0.5, mu_st = 1): a value is
    accepted exactly when it is a finite real number (or a list of them) obeying
    the field's rule, and a scalar (a list of up to 3 values has the wrong length
    for the 20 oscillators of eq. (7)); otherwise ValueError or TypeError names the
    field (a mu_d above mu_st is reported as "ExponentialDecay.mu_st must be >=
    mu_d")."""
    numbers = (not isinstance(value, (str, bool)) and value is not None)
    a = np.asarray(value, dtype=float) if numbers else None
    valid = (numbers and np.all(np.isfinite(a)) and np.all(RULES[field](a))
             and np.ndim(a) == 0)
    if valid:
        jc.ChainParams(**{field: value})
    else:
        owner = "ExponentialDecay" if field in ("mu_st", "mu_d", "v0") else "ChainParams"
        says = "mu_d" if field == "mu_d" else f"{owner}.{field}"
        with pytest.raises((ValueError, TypeError), match=says):
            jc.ChainParams(**{field: value})


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(("t_end", "transient", "rtol", "atol", "sample_dt", "chunk_length",
                        "max_steps")), VALUES)
def test_fuzzed_options_are_accepted_exactly_when_valid(field, value):
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if field == "transient":
        valid = number and math.isfinite(value) and 0 <= value < 15000.0
    elif field == "max_steps":
        valid = isinstance(value, int) and not isinstance(value, bool) and value >= 1
    elif field == "t_end":
        valid = number and math.isfinite(value) and value > 10000.0
    else:
        valid = number and math.isfinite(value) and value > 0
    if valid:
        jc.SimulationOptions(**{field: value})
    else:
        # a t_end at or below the default transient is reported by the transient's
        # check, which names both: "transient must lie in [0, t_end = ...)"
        says = "t_end" if field == "t_end" else f"SimulationOptions.{field}"
        with pytest.raises((ValueError, TypeError), match=says):
            jc.SimulationOptions(**{field: value})


TOKENS = st.sampled_from(["abc", "-1", "0", "nan", "inf", "-inf", "1e-3", "", ",", "1.5,",
                          "2", "1:2:3", "1.0,2.0", "eq8", "eq10", "x,y", "1e400", "--",
                          "--bogus", "-q", "ros34pw2", "euler", "20", "2.5"])


def _command_argv(command):
    """argv for one command: its own options with values drawn from TOKENS, and
    unknown options."""
    from jaxchain._cli.main import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    options = [s for a in sub.choices[command]._actions for s in a.option_strings
               if s not in ("-h", "--help")]
    return st.lists(st.one_of(st.sampled_from(options), TOKENS), max_size=6)


@pytest.mark.parametrize("command", ["localized", "sweep", "figure", "crosscheck",
                                     "work-precision", "boundaries", "stress", "basin"])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_fuzzed_command_lines_parse_or_exit_2_with_one_line(command, data):
    """Every command's parsing: random options and values either parse, or end with
    status 2 and one line on stderr that names the command, never a traceback."""
    from jaxchain._cli.main import build_parser
    argv = [command, *data.draw(_command_argv(command))]
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit as exc:
        err = stderr.getvalue().strip().splitlines()
        assert exc.code == 2 and len(err) == 1 and "error" in err[0], (argv, err)
        assert "Traceback" not in err[0]
