"""Periodic or irregular: each state classified from two independent signals, the
spread of its time delays and its largest Lyapunov exponent."""

import math

import numpy as np

from .states import (FAILED, IRREGULAR, PERIODIC, STEADY_SLIDING, UNDECIDED,
                       ClassTolerances)
from .delays import delay_spread, reference_oscillator, time_delays
from .._engine.status import Status


def _lyapunov_class(exponent: float, error: float) -> str:
    """"irregular" when the largest Lyapunov exponent is positive beyond its stated
    error (a chaotic state), "periodic" when it is not (a regular one: 0 within
    the error on a limit cycle or a torus, negative on an equilibrium), and
    "undecided" when the error is unknown (fewer than two chunks in the window)."""
    if not math.isfinite(error):
        return UNDECIDED
    return IRREGULAR if exponent > error else PERIODIC


def classify(peak_times, on_halc, n_halc: int, status: int, lyapunov: float,
             lyapunov_error: float, t_from: float,
             tolerances: ClassTolerances = ClassTolerances(), boundary="ring") -> dict:
    """Classify one state as periodic or irregular from two independent signals.

    - **The time delays** (the paper's criterion, Section 3.3): `delay_spread` of
        the HALC oscillators' delays to the reference (`reference_oscillator`)
        and of the reference's own periods, over the peaks after `t_from`.
    - **The largest Lyapunov exponent** against its stated error: irregular when
        it is positive beyond the error, undecided when the error is unknown.

    When they agree, that is the class; when they disagree, "undecided" (both
    verdicts are returned). A chain at rest (n_halc = 0) is "steady sliding"; a
    failed run, "failed".

    **Arguments:**

    - `peak_times`: shape (n_osc, peaks), all oscillators (`PeakTimes`).
    - `on_halc`: shape (n_osc,); `n_halc`, `status`: of the run (`Extrema`).
    - `lyapunov`, `lyapunov_error`: from `LargestLyapunov`.
    - `t_from`: start of the window for the delays (dimensionless time).
    - `tolerances`: `ClassTolerances`; `boundary`: the chain's (for the reference
        oscillator, `reference_oscillator`).

    **Returns:**

    dict with `class`, `class_delays`, `class_lyapunov`, `delay_spread`,
    `delay_period` (the m of `delay_spread`) and `ref` (0-based).
    """
    out = {"class_delays": FAILED, "class_lyapunov": FAILED,
           "delay_spread": math.nan, "delay_period": 0, "ref": -1}
    if status != Status.ok:
        return out | {"class": FAILED}
    on_halc = np.asarray(on_halc, dtype=bool)
    ref = reference_oscillator(on_halc, boundary)
    tau_ref, phi = time_delays(np.asarray(peak_times), ref)
    others = on_halc.copy()
    others[ref] = False
    spread, period = delay_spread(tau_ref, phi[others], t_from, tolerances.max_period)
    by_delays = PERIODIC if spread <= tolerances.delay else IRREGULAR
    by_lyapunov = _lyapunov_class(lyapunov, lyapunov_error)
    if n_halc == 0:
        verdict = STEADY_SLIDING
    else:
        verdict = by_delays if by_delays == by_lyapunov else UNDECIDED
    return {"class": verdict, "class_delays": by_delays, "class_lyapunov": by_lyapunov,
            "delay_spread": spread, "delay_period": period, "ref": ref}
