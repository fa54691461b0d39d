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
