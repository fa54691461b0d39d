"""What to do about a failed trajectory: a hint specific to its status, its
parameters, its solver and its options."""

import diffrax
import numpy as np

from ._options import SimulationOptions
from ._params import ChainParams
from ._solvers import DEFAULT_SOLVER, SOLVERS

#: Stability bound of an explicit Runge-Kutta step on a decaying mode, h |lambda| <~
#: 3 (Tsit5, Dopri5: 3.3 and 3.3 on the negative real axis; Hairer & Wanner,
#: Solving ODEs II, IV.2).
EXPLICIT_STABILITY = 3.0


def _name(solver) -> str:
    for name, make in SOLVERS.items():
        made = make() if callable(make) else make
        if type(made) is type(solver):
            return name
    return type(solver).__name__


def _explicit(solver) -> bool:
    return not isinstance(solver, (diffrax.AbstractImplicitSolver,
                                   SOLVERS[DEFAULT_SOLVER]))


def stick_stiffness(params: ChainParams) -> float:
    """The stiffness of the stick phase, |dF/dv_rel| at v_rel = 0: mu_st / eps (the
    smoothed force of eq. (2), -mu tanh(v_rel/eps)), in units of omega_n."""
    return float(np.max(np.asarray(params.mu_st) / np.asarray(params.eps)))


def explicit_steps(params: ChainParams, options: SimulationOptions) -> float:
    """A lower bound on the steps an explicit method takes over the run when it sticks
    for a fraction of the time near 1/2: t_end * stiffness / (2 * 3)."""
    return options.t_end * stick_stiffness(params) / (2 * EXPLICIT_STABILITY)


def failure_hint(status: int, params: ChainParams, solver: diffrax.AbstractSolver,
                 options: SimulationOptions) -> str:
    """A hint for a trajectory of `status` (`STATUS`), naming the setting to change.

    **Arguments:**

    - `status`: the status code of the run, 1-4 (0 gives "").
    - `params`, `solver`, `options`: those of the run.

    **Returns:**

    One sentence, or "" for status 0.
    """
    eps = float(np.max(np.asarray(params.eps)))
    name = _name(solver)
    stiff = (f"eps = {eps:g} makes the stick phase stiff (stiffness mu_st/eps = "
             f"{stick_stiffness(params):.3g})")
    if status == 0:
        return ""
    if status == 1:
        if _explicit(solver):
            need = explicit_steps(params, options)
            return (f"{stiff}: an explicit solver ({name}) needs about {need:.2g} steps "
                    f"over t_end = {options.t_end:g}; use solver='{DEFAULT_SOLVER}' "
                    f"(or 'auto'), or eps >= {10 * eps:g}")
        return (f"{name} ran out of its {options.max_steps} steps in one chunk of "
                f"length {options.chunk_length:g} ({stiff}); raise max_steps, shorten "
                f"chunk_length or use eps >= {10 * eps:g}")
    if status == 2:
        return (f"{name}'s implicit stage solve failed ({stiff}); use "
                f"solver='{DEFAULT_SOLVER}', whose linearly implicit steps need no "
                f"Newton iteration, or tighter tolerances")
    if status == 3:
        return ("the state became non-finite: check that the initial state is finite, "
                "and that the parameters are within the ranges of ChainParams")
    return (f"{stiff}, and the step size fell below dtmin = {options.dtmin:g} at a stick "
            f"transition; use solver='{DEFAULT_SOLVER}', eps >= {10 * eps:g} or looser "
            f"rtol (now {float(np.max(np.asarray(options.rtol))):g})")
