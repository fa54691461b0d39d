"""What a run of either engine observes (`Observables`), and the check of a list of
observers."""

from collections.abc import Sequence

import equinox as eqx
from jaxtyping import Array, Bool, Float, Int

from .observers.base import AbstractObserver
from .._errors import ValidationError


class Observables(eqx.Module):
    """What one run observes over [transient, t_end]. Under `ensemble` every field
    gains the leading batch axes (n_vd, n_ic).

    **Fields:**

    - `amplitudes`: half of peak-to-peak of each x_n, shape (n_osc,).
    - `energy`: E = 1/2 sum_n A_n^2, eq. (9) of the paper, shape ().
    - `on_halc`: whether each oscillator is on the high-amplitude limit cycle: it
        sticks, `min_slip_speed` <= 3 eps (`sticks`), shape (n_osc,).
    - `n_halc`: number of oscillators on the HALC, shape ().
    - `min_slip_speed`: smallest |x_n' - v_d| over the samples, shape (n_osc,).
    - `n_halc_halves`: n_halc over the first and over the second half of the
        observed window, shape (2,): they differ when stick-slip invades the
        sliding oscillators, or recedes from them, during the window (a
        propagating front).
    - `x_max`, `x_min`, `v_max`: extrema of x_n and x_n', shape (n_osc,).
    - `y_initial`, `y_final`: state at t = 0 and at t_end (where the run stopped, if
        it failed), shape (2, n_osc).
    - `num_steps`: accepted plus rejected steps of the whole run, shape ().
    - `status`: the `Status` of the run (its integer value; `Status.ok` is
        success), shape ().

    The exact engine's own fields (`Exact`; None from the smoothed engine, and not
    written by `to_dataset`):

    - `x_max_halves`, `x_min_halves`: extrema of x_n over each half of the window,
        shape (2, n_osc).
    - `half_difference`: largest difference between the two halves' extrema, over
        the oscillators, relative to max(1, max amplitude), shape (). It is at the
        integration tolerance for a periodic state.
    - `stick_fraction`: fraction of the window each oscillator spends in stick,
        shape (n_osc,).
    - `modes_final`: modes at t_end (+1/-1 slip, 0 stick), shape (n_osc,).
    - `friction_work`, `viscous_dissipation`: int sum_n F_n x_n' dt and
        int sum_n 2 xi x_n'^2 dt over [0, t_end], shape (). Their difference equals
        the change of `mechanical_energy` (the energy balance).
    - `log_time`, `log_osc`, `log_kind`: the last `NonsmoothOptions.log_size`
        switches (time, oscillator index from 0, index into `SWITCH_KINDS`), oldest
        first, shape (log_size,); unused entries have time NaN and oscillator and
        kind -1.
    - `num_events`: switch instants of the whole run, shape ().

    With the exact engine, an oscillator is on the HALC when it sticks during the
    window (`min_slip_speed` = 0: stick is exact, x_n' = v_d); its extrema are
    taken at turning points located on the dense output, exact to the integration
    tolerance.

    A failed run (status not `Status.ok`) gives no partial answers: amplitudes, energy and the
    extrema are NaN, `on_halc` is False and `n_halc` is -1.

    All quantities are dimensionless (eqs. (4)-(6)).
    """

    amplitudes: Float[Array, "*batch n_osc"]
    energy: Float[Array, "*batch"]
    on_halc: Bool[Array, "*batch n_osc"]
    n_halc: Int[Array, "*batch"]
    n_halc_halves: Int[Array, "*batch 2"]
    min_slip_speed: Float[Array, "*batch n_osc"]
    x_max: Float[Array, "*batch n_osc"]
    x_min: Float[Array, "*batch n_osc"]
    v_max: Float[Array, "*batch n_osc"]
    y_initial: Float[Array, "*batch 2 n_osc"]
    y_final: Float[Array, "*batch 2 n_osc"]
    num_steps: Int[Array, "*batch"]
    status: Int[Array, "*batch"]
    x_max_halves: Float[Array, "*batch 2 n_osc"] | None = None
    x_min_halves: Float[Array, "*batch 2 n_osc"] | None = None
    half_difference: Float[Array, "*batch"] | None = None
    stick_fraction: Float[Array, "*batch n_osc"] | None = None
    modes_final: Float[Array, "*batch n_osc"] | None = None
    friction_work: Float[Array, "*batch"] | None = None
    viscous_dissipation: Float[Array, "*batch"] | None = None
    log_time: Float[Array, "*batch log"] | None = None
    log_osc: Int[Array, "*batch log"] | None = None
    log_kind: Int[Array, "*batch log"] | None = None
    num_events: Int[Array, "*batch"] | None = None


#: The fields of `Observables` that the exact engine alone fills in.
EXACT_FIELDS = ("x_max_halves", "x_min_halves", "half_difference", "stick_fraction",
                "modes_final", "friction_work", "viscous_dissipation", "log_time",
                "log_osc", "log_kind", "num_events")


def check_observers(observers: Sequence[AbstractObserver]) -> tuple:
    """`observers` as a tuple, checked.

    **Raises:**

    `TypeError` for an entry that is not an `AbstractObserver`; `ValidationError` when
    two observers give a result of the same name (observe each thing once).
    """
    observers = tuple(observers)
    for o in observers:
        if not isinstance(o, AbstractObserver):
            raise TypeError(f"observers must be AbstractObserver instances, got {o!r}")
    names = [type(o).__name__ for o in observers]
    if len(set(names)) != len(names):
        raise ValidationError(f"observers must be of distinct kinds, got {names}")
    return observers
