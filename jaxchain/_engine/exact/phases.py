"""The stick phases of a periodic orbit of the exact switch model, from the exact
engine's switch log: what tells a sliding bifurcation (a stick phase that shrinks to
nothing) on a branch of exact orbits."""

import numpy as np
from jaxtyping import Float

from ..status import Status
from ..._errors import ValidationError
from .solve import nonsmooth_switches
from .switching import SWITCH_KINDS

_STICK = SWITCH_KINDS.index("slip to stick")
_SLIP = SWITCH_KINDS.index("stick to slip")


def stick_phases(params, y0, period, options) -> Float[np.ndarray, " n_osc"]:
    """The duration of the shortest stick phase of each oscillator on the periodic
    orbit of the exact switch model through `y0` with period `period`: every stick
    phase that ends (stick to slip) in the second of two periods, from the switch
    that began it (slip to stick), by the exact engine's switch log
    (`nonsmooth_switches`).

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: a state on the orbit, shape (2, n_osc).
    - `period`: its period T (> 0), dimensionless (eq. (4)).
    - `options`: `NonsmoothOptions` of the run (the exact engine's, `Exact.options`).

    **Returns:**

    Shape (n_osc,), dimensionless time (eq. (4)): inf for an oscillator without a
    complete stick phase there (it never sticks, or never leaves stick); NaN
    everywhere if the run failed or its log is too short for two periods.

    **Raises:**

    `ValidationError` (a `ValueError`) naming `period` if it is not a finite number
    > 0.
    """
    if not np.isfinite(float(period)) or float(period) <= 0:
        raise ValidationError(f"period must be a finite number > 0, got {float(period)!r}")
    time, osc, kind, status = (np.asarray(a) for a in
                               nonsmooth_switches(params, y0, 2.0 * period, options))
    n = params.n_osc
    if int(status) != Status.ok or kind[0] >= 0 and time[0] > float(period):
        return np.full(n, np.nan)  # failed, or the log has lost the first period
    out = np.full(n, np.inf)
    start = np.full(n, np.nan)  # the latest slip-to-stick switch of each oscillator
    for t, i, k in zip(time, osc, kind):
        if k == _STICK:
            start[i] = t
        elif k == _SLIP:
            if t > period and np.isfinite(start[i]):
                out[i] = min(out[i], t - start[i])
            start[i] = np.nan
    return out
