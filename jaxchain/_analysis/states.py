"""The one vocabulary of the chain's final states, shared by the cross-check, the
scenes of Figs. 5-10 and basin stability, and the tolerances that tell a periodic
state from an irregular one."""

import math

import equinox as eqx

from .._checks import check_count
from .._errors import ValidationError

#: The chain at rest on the belt: no oscillator on the HALC (n_HALC = 0).
STEADY_SLIDING = "steady sliding"
#: Some, not all, oscillators on the high-amplitude stick-slip limit cycle (HALC).
LOCALIZED = "localized"
#: Every oscillator on the HALC (the one oscillator, or the whole chain).
STICK_SLIP = "stick-slip"
#: A run that did not finish (its status is not 0).
FAILED = "failed"
#: How a vibrating state repeats: periodic, irregular, or undecided when two
#: criteria disagree (`classify`).
PERIODIC, IRREGULAR, UNDECIDED = "periodic", "irregular", "undecided"


def state_class(n_halc: int, n_osc: int, regularity: str | None = None) -> str:
    """The class of a final state from its n_HALC: `STEADY_SLIDING` (0), `LOCALIZED`
    (0 < n_HALC < N) or `STICK_SLIP` (N), followed by its regularity in brackets
    when given ("localized (periodic)"); `FAILED` for a failed run (n_HALC = -1).

    **Arguments:**

    - `n_halc`: oscillators on the HALC, -1 for a failed run.
    - `n_osc`: oscillators of the chain.
    - `regularity`: `PERIODIC`, `IRREGULAR`, `UNDECIDED` or None.
    """
    if n_halc < 0:
        return FAILED
    if n_halc == 0:
        return STEADY_SLIDING
    kind = STICK_SLIP if n_halc == n_osc else LOCALIZED
    return kind if regularity is None else f"{kind} ({regularity})"


class ClassTolerances(eqx.Module):
    """When a vibrating state counts as periodic, by each criterion that jaxchain
    uses.

    **Arguments:**

    - `delay`: largest delay spread of a periodic state (`delay_spread`, the time
        delays of the scenes of Figs. 5-10), dimensionless time. The peak times are
        interpolated to about 1e-5 and the solver's tolerances move them by less
        than 1e-3 (measured at rtol 1e-5; the classification of the figure
        tests is the same at the default 3e-5), while an irregular state's delays wander by a
        sizeable part of its period (~6).
    - `max_period`: longest repetition of the delays, in reference peaks, that
        still counts as periodic.
    - `halves`: largest change of an extremum of the smoothed model between the
        two halves of the observed window, relative to max(1, largest amplitude)
        (the cross-check): its extrema are sampled every `sample_dt`, a relative
        error of up to 3e-4, hence 1e-3.
    - `halves_reference`: the same for the non-smooth reference, whose extrema are
        exact: 1e-6 leaves a margin over its ~1e-9 accuracy.

    **Raises:**

    `ValidationError` naming the field for a tolerance that is not a finite number > 0,
    or max_period < 1.
    """

    delay: float = 1e-2
    max_period: int = 8
    halves: float = 1e-3
    halves_reference: float = 1e-6

    def __check_init__(self):
        for name in ("delay", "halves", "halves_reference"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value) and value > 0):
                raise ValidationError(f"ClassTolerances.{name} must be a finite number > 0, "
                                      f"got {value!r}")
        check_count("ClassTolerances.max_period", self.max_period)
