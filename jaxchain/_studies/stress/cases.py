"""The stress matrix: the paper's defaults with one thing varied at a time, to the
edges of the model (tiny eps, long rings, a belt that nearly stops or races, strong
coupling, no damping, large initial states)."""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._engine.engines import Smoothed
from ..._physics.custom_types import State
from ..._physics.forces import DEFAULT_EPS
from ..._physics.initial import OutOfPhaseExcitation, excited_block
from ..._physics.model import steady_sliding
from ..._engine.options import SimulationOptions
from ..._physics.params import ChainParams, with_parameter
from ..._errors import ValidationError

#: What varies, and its values. "mu_st/mu_d" varies mu_st at mu_d = 0.5; "ics" the
#: initial state: exactly steady sliding, or steady sliding plus an out-of-phase
#: pattern (-1)^n of displacements 1e3 or of velocities 50. 1.1513 is the Hopf point
#: of eq. (7) at eta_c = 0.01 and 1.8366 the fold of the single oscillator's
#: stick-slip cycle (Fig. 3(a)).
MATRIX = {
    "eps": (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6),
    "n_osc": (1, 2, 3, 20, 200, 1000),
    "v_d": (1e-3, 0.1, 1.0, 1.1513, 1.5, 1.8366, 3.0, 10.0, 100.0),
    "eta_c": (0.0, 1e-4, 0.01, 1.0, 100.0),
    "xi": (0.0, 1e-4, 0.05, 1.0),
    "mu_st/mu_d": (1.0, 2.0, 10.0),
    "v0": (1e-3, 0.5, 100.0),
    "ics": ("steady sliding", "x ± 1e3", "x' ± 50"),
}

#: The reduced matrix of `jaxchain stress --quick` and of the test suite: the edges
#: (one ring size besides the default's, since each size compiles anew).
QUICK_MATRIX = {
    "eps": (1e-1, 1e-5),
    "n_osc": (1,),
    "v_d": (1e-3, 1.1513, 10.0),
    "eta_c": (100.0,),
    "xi": (0.0, 1.0),
    "mu_st/mu_d": (1.0,),
    "v0": (1e-3,),
    "ics": ("steady sliding", "x ± 1e3", "x' ± 50"),
}

#: The horizon of every case: long enough for a few stick-slip cycles and for a
#: damped mode to decay by exp(-xi t_end) = 3e-7 at xi = 0.05.
OPTIONS = SimulationOptions(t_end=300.0, transient=200.0, chunk_length=25.0)
QUICK_OPTIONS = SimulationOptions(t_end=150.0, transient=100.0, chunk_length=25.0)


class StressCase(eqx.Module):
    """One case of the stress matrix: the paper's defaults (`ChainParams()`, eq. (7)
    at v_d = 1.5, smoothed at `DEFAULT_EPS`, the localized start of eq. (8) on a
    quarter of the ring) with `what` set to `value`.

    **Fields:** `what`, `value` (as in `MATRIX`), `params`, `eps` (the smoothing
    velocity the case runs the smoothed engine at, `Smoothed.eps`: a float > 0,
    dimensionless), `y0` (shape (2, n_osc), dimensionless) and `options`.
    """

    what: str = eqx.field(static=True)
    value: float | str = eqx.field(static=True)
    params: ChainParams
    eps: float = eqx.field(static=True)
    y0: State
    options: SimulationOptions = eqx.field(static=True)


def _pattern(n_osc: int) -> np.ndarray:
    return (-1.0) ** np.arange(1, n_osc + 1)


def make_case(what: str, value, options: SimulationOptions = OPTIONS) -> StressCase:
    """The case of `MATRIX` with `what` = `value`.

    **Raises:**

    `ValidationError` for a `what` not in `MATRIX`, or an "ics" value not listed there.
    """
    if what not in MATRIX:
        raise ValidationError(f"what must be one of {', '.join(MATRIX)}, got {what!r}")
    params, eps = ChainParams(), DEFAULT_EPS
    if what == "eps":  # the engine's, not the chain's: validated as Smoothed does
        eps = float(Smoothed(eps=float(value)).eps)
    elif what == "n_osc":
        params = ChainParams(n_osc=int(value))
    elif what == "mu_st/mu_d":
        params = with_parameter(params, "mu_st", float(value) * float(params.friction.mu_d))
    elif what != "ics":
        params = with_parameter(params, what, float(value))
    n = params.n_osc
    base = steady_sliding(params, eps)  # the smoothed engine's fixed point
    if what != "ics":
        y0 = OutOfPhaseExcitation.eq8(excited_block(n, max(1, n // 4), params.graph))(params)
    elif value == "steady sliding":
        y0 = base
    elif value == "x ± 1e3":
        y0 = base.at[0].add(1e3 * _pattern(n))
    elif value == "x' ± 50":
        y0 = base.at[1].add(50.0 * _pattern(n))
    else:
        raise ValidationError(f"ics must be one of {MATRIX['ics']}, got {value!r}")
    return StressCase(what=what, value=value, params=params, eps=eps, y0=jnp.asarray(y0),
                      options=options)


def stress_cases(quick: bool = False, **tolerances) -> list[StressCase]:
    """Every case of `MATRIX` (or of `QUICK_MATRIX`, with `QUICK_OPTIONS`), in
    order. A value equal to the default appears once per row, as in the table.
    `tolerances` replace fields of the cases' `SimulationOptions` (rtol, atol,
    controller, max_steps).

    **Raises:**

    `ValidationError` for a field `SimulationOptions` refuses, naming it.
    """
    matrix, options = (QUICK_MATRIX, QUICK_OPTIONS) if quick else (MATRIX, OPTIONS)
    if tolerances:
        options = dataclasses.replace(options, **tolerances)
    return [make_case(what, value, options) for what, values in matrix.items()
            for value in values]
