"""Bad input to the Python API raises at once, naming the argument and what it
accepts: nothing is traced, run or written first. The library's own checks raise
`jaxchain.ValidationError` (a `ValueError`), a value of the wrong type `TypeError`.
Hypothesis fuzzes the validation of the parameters and the options; the command
line's is fuzzed in test_exit_status.py."""

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxchain as jc

P = jc.ChainParams(n_osc=3)
OPTS = jc.SimulationOptions(t_end=20.0, transient=10.0)
Y0 = np.zeros((2, 3))
FAMILY = jc.localized_family(3)
ONE = jc.ChainParams(n_osc=1)
#: A CSV in a folder that must never be created: work_precision checks every
#: argument before it opens its file.
NOWHERE = Path(tempfile.gettempdir()) / f"jaxchain-bad-input-{os.getpid()}" / "wp.csv"

CASES = {
    "y0 of the wrong shape": (lambda: jc.simulate(P, np.zeros((3, 3)), options=OPTS),
                              jc.ValidationError, "y0 must have shape"),
    "y0 of strings": (lambda: jc.simulate(P, [["a"] * 3] * 2, options=OPTS), TypeError, "y0"),
    "y0 of booleans": (lambda: jc.simulate(P, np.ones((2, 3), dtype=bool), options=OPTS),
                       TypeError, "y0"),
    "y0 ragged": (lambda: jc.simulate(P, [[0.0, 1.0], [0.0]], options=OPTS), TypeError, "y0"),
    "y0 complex": (lambda: jc.simulate(P, np.zeros((2, 3), complex), options=OPTS),
                   TypeError, "y0"),
    "an unknown solver name": (lambda: jc.simulate(P, Y0, "euler", options=OPTS),
                               jc.ValidationError, "solver must be one of"),
    "a solver that is not one": (lambda: jc.simulate(P, Y0, object(), options=OPTS),
                                 TypeError, "solver must be a diffrax solver"),
    "options that are not options": (lambda: jc.simulate(P, Y0, options="fast"),
                                     TypeError, "options must be"),
    "params that are not ChainParams": (lambda: jc.simulate({"v_d": 1.5}, Y0, options=OPTS),
                                        TypeError, "params must be"),
    "an empty list of belt speeds": (lambda: jc.ensemble(P, [], FAMILY, options=OPTS),
                                     jc.ValidationError, "v_d must be a 1-d list of at least one"),
    "a negative belt speed": (lambda: jc.ensemble(P, [1.5, -1.0], FAMILY, options=OPTS),
                              jc.ValidationError, "v_d must hold finite belt speeds > 0"),
    "a NaN belt speed": (lambda: jc.ensemble(P, [np.nan], FAMILY, options=OPTS),
                         jc.ValidationError, "v_d must hold"),
    "belt speeds of strings": (lambda: jc.ensemble(P, ["fast"], FAMILY, options=OPTS),
                               TypeError, "v_d must be an array of real numbers"),
    "an empty ensemble": (lambda: jc.ensemble(P, [1.5], jc.GivenState(np.zeros((0, 2, 3))),
                                              options=OPTS),
                          jc.ValidationError, "at least one initial condition"),
    "ics that are not ics": (lambda: jc.ensemble(P, [1.5], [Y0], options=OPTS),
                             TypeError, "ics must be initial conditions"),
    "ics for another ring": (lambda: jc.ensemble(P, [1.5], jc.localized_family(4), options=OPTS),
                             jc.ValidationError, "excited must have shape"),
    "an empty sweep grid": (lambda: jc.sweep(P, [], {"eq8": FAMILY}, options=OPTS),
                            jc.ValidationError, "at least one value"),
    "a sweep with no families": (lambda: jc.sweep(P, [1.5], {}, options=OPTS),
                                 jc.ValidationError, "at least one family"),
    "an empty cross-check": (lambda: jc.crosscheck(P, [1.5], [], options=OPTS),
                             jc.ValidationError, "ics must list at least one"),
    "solutions outside the ring": (lambda: jc.observe_solutions(P, [0], [jc.Extrema()],
                                                                options=OPTS),
                                   jc.ValidationError, "solutions must be numbers"),
    "an observer that is not one": (lambda: jc.observe(P, Y0, ["amplitudes"], options=OPTS),
                                    TypeError, "AbstractObserver"),
    "t_end <= transient": (lambda: jc.SimulationOptions(t_end=5.0, transient=10.0),
                           jc.ValidationError, "SimulationOptions.transient must lie in"),
    "a fractional max_steps": (lambda: jc.SimulationOptions(max_steps=2.5),
                               jc.ValidationError,
                               "SimulationOptions.max_steps must be an integer"),
    "a string transient": (lambda: jc.SimulationOptions(transient="a"),
                           jc.ValidationError, "SimulationOptions.transient"),
    "a string parameter": (lambda: jc.ChainParams(xi="a"), TypeError, "ChainParams.xi"),
    "a boolean parameter": (lambda: jc.ChainParams(v_d=True), TypeError, "ChainParams.v_d"),
    "a NaN parameter": (lambda: jc.ChainParams(xi=np.nan), jc.ValidationError, "ChainParams.xi"),
    "a NaN eps of the engine": (lambda: jc.Smoothed(eps=np.nan), jc.ValidationError,
                                "Smoothed.eps"),
    "eps given to the chain": (lambda: jc.ChainParams(eps=1e-3), jc.ValidationError,
                               r"ChainParams.eps: eps is a setting of the smoothed engine"),
    "eps given to the exact engine": (lambda: jc.simulate(P, Y0, engine=jc.Exact().with_parameter(
        "eps", 1e-3)), jc.ValidationError, "the exact engine has no eps"),
    "mu_st below mu_d": (lambda: jc.ChainParams(mu_st=0.2), jc.ValidationError,
                         "ExponentialDecay.mu_st"),
    "a time series with dt <= 0": (lambda: jc.observe(P, Y0, [jc.TimeSeries(dt=0.0)],
                                                      options=OPTS),
                                   jc.ValidationError, "TimeSeries.dt"),
    # wilson_interval: a proportion k/n needs whole counts 0 <= k <= n, n >= 1
    "an interval of no trials": (lambda: jc.wilson_interval(0, 0), jc.ValidationError,
                                 "n must be a number of trials >= 1"),
    "more successes than trials": (lambda: jc.wilson_interval([1, 4], 3), jc.ValidationError,
                                   r"k must lie in \[0, n\], got k = 4 with n = 3"),
    "negative successes": (lambda: jc.wilson_interval(-1, 3), jc.ValidationError,
                           r"k must lie in \[0, n\]"),
    "fractional successes": (lambda: jc.wilson_interval(1.5, 3), jc.ValidationError,
                             "k must be whole numbers"),
    "NaN trials": (lambda: jc.wilson_interval(1, np.nan), jc.ValidationError,
                   "n must be whole numbers"),
    "counts of other shapes": (lambda: jc.wilson_interval([1, 2], [3, 3, 3]),
                               jc.ValidationError, "k and n must have shapes that broadcast"),
    "a quantile z <= 0": (lambda: jc.wilson_interval(1, 3, z=0.0), jc.ValidationError,
                          "z must be a finite number > 0"),
    "counts of strings": (lambda: jc.wilson_interval("a", 3), TypeError, "k must be"),
    # hopf_point: the chain and Newton's start, checked before anything is traced
    "a Hopf point of no chain": (lambda: jc.hopf_point({"v_d": 1.5}), TypeError,
                                 "params must be a jaxchain.ChainParams"),
    "a NaN Hopf guess": (lambda: jc.hopf_point(ONE, np.nan), jc.ValidationError,
                         "guess must be a finite belt speed > 0"),
    "an infinite Hopf guess": (lambda: jc.hopf_point(ONE, np.inf), jc.ValidationError,
                               "guess must be"),
    "a negative Hopf guess": (lambda: jc.hopf_point(ONE, -1.0), jc.ValidationError,
                              "guess must be"),
    "a Hopf guess of strings": (lambda: jc.hopf_point(ONE, "1.2"), TypeError, "guess must be"),
    "a Hopf rtol of 0": (lambda: jc.hopf_point(ONE, rtol=0.0), jc.ValidationError,
                         "rtol must be a finite number > 0"),
    # work_precision: every argument, before the CSV is opened or anything runs
    "no rtols": (lambda: jc.work_precision(NOWHERE, rtols=[]), jc.ValidationError,
                 "rtols must be a list of at least one number"),
    "no eps": (lambda: jc.work_precision(NOWHERE, eps_values=[]), jc.ValidationError,
               "eps_values must be a list of at least one number"),
    "a bad eps after good ones": (lambda: jc.work_precision(NOWHERE, eps_values=[1e-2, 1e-3, -1.0]),
                                  jc.ValidationError, "eps_values must hold finite numbers > 0"),
    "a NaN eps": (lambda: jc.work_precision(NOWHERE, eps_values=[np.nan]), jc.ValidationError,
                  "eps_values must hold"),
    "an rtol of 1": (lambda: jc.work_precision(NOWHERE, rtols=[1e-3, 1.0]),
                     jc.ValidationError, r"rtols must hold numbers in \(0, 1\)"),
    "rtols of strings": (lambda: jc.work_precision(NOWHERE, rtols=["1e-3"]), TypeError,
                         "rtols must be"),
    "no scenes": (lambda: jc.work_precision(NOWHERE, scenes=[]), jc.ValidationError,
                  "scenes must name at least one"),
    "no solvers": (lambda: jc.work_precision(NOWHERE, solvers=[]), jc.ValidationError,
                   "solvers must name at least one"),
    "an unknown step-size controller": (lambda: jc.work_precision(NOWHERE,
                                                                  solvers=["tsit5/fast"]),
                                        jc.ValidationError, "solver must be one of"),
    "a fractional step budget": (lambda: jc.work_precision(NOWHERE, max_steps=2.5),
                                 jc.ValidationError, "max_steps must be an integer >= 1"),
    "a scipy budget of 0 s": (lambda: jc.work_precision(NOWHERE, scipy_budget_s=0),
                              jc.ValidationError, "scipy_budget_s must be"),
    "a design of -1 steps": (lambda: jc.intentional_mistuning(steps=-1), jc.ValidationError,
                             "steps must be an integer >= 0"),
    "a fractional design seed": (lambda: jc.intentional_mistuning(seed=0.5),
                                 jc.ValidationError, "seed must be an integer >= 0"),
    "a learning rate of 0": (lambda: jc.intentional_mistuning(learning_rate=0.0),
                             jc.ValidationError, "learning_rate must be > 0"),
    "a NaN temperature": (lambda: jc.intentional_mistuning(temperature=np.nan),
                          jc.ValidationError, "temperature must be > 0"),
    "a target given as text": (lambda: jc.bistable_range(target="0.5"), jc.ValidationError,
                               "target must be > 0"),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_input_raises_naming_the_argument(case):
    call, error, says = CASES[case]
    with pytest.raises(error, match=says):
        call()
    assert not NOWHERE.parent.exists()  # nothing was written first


def test_integer_states_are_taken_as_numbers():
    obs = jc.simulate(P, np.asarray(jc.Exact().steady_sliding(P)).round().astype(int), options=OPTS,
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
    for the 20 oscillators of eq. (7)); otherwise ValidationError or TypeError names the
    field (a mu_d above mu_st is reported as "ExponentialDecay.mu_st must be >=
    mu_d")."""
    numbers = (not isinstance(value, (str, bool)) and value is not None)
    a = np.asarray(value, dtype=float) if numbers else None
    valid = (numbers and np.all(np.isfinite(a)) and np.all(RULES[field](a))
             and np.ndim(a) == 0)
    def build(v):  # eps is the smoothed engine's, the other fields the chain's
        return jc.Smoothed(eps=v) if field == "eps" else jc.ChainParams(**{field: v})

    if valid:
        build(value)
    else:
        owner = {"mu_st": "ExponentialDecay", "mu_d": "ExponentialDecay",
                 "v0": "ExponentialDecay", "eps": "Smoothed"}.get(field, "ChainParams")
        says = "mu_d" if field == "mu_d" else f"{owner}.{field}"
        with pytest.raises((jc.ValidationError, TypeError), match=says):
            build(value)


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
    elif field in ("rtol", "atol"):  # in (0, 1), or None: following eps
        valid = value is None or (number and math.isfinite(value) and 0 < value < 1)
    else:
        valid = number and math.isfinite(value) and value > 0
    if valid:
        jc.SimulationOptions(**{field: value})
    else:
        # a t_end at or below the default transient is reported by the transient's
        # check, which names both: "transient must lie in [0, t_end = ...)"
        says = "t_end" if field == "t_end" else f"SimulationOptions.{field}"
        with pytest.raises((jc.ValidationError, TypeError), match=says):
            jc.SimulationOptions(**{field: value})
