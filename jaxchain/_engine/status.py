"""What to do about a failed trajectory: a hint specific to its status, its
parameters, its solver and its options."""

import diffrax
import numpy as np

from .options import SimulationOptions
from .._physics.params import ChainParams
from .solver.registry import DEFAULT_SOLVER, SOLVERS, stick_stiffness

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
            step = EXPLICIT_STABILITY / stick_stiffness(params)
            return (f"{stiff}: an explicit solver ({name}) may need steps as small as "
                    f"3 eps/mu_st = {step:.1g} while it sticks; use "
                    f"solver='{DEFAULT_SOLVER}' (or 'auto'), or eps >= {10 * eps:g}")
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
    other = "" if name == DEFAULT_SOLVER else f"solver='{DEFAULT_SOLVER}', "
    return (f"{stiff}, and the steps fell below dtmin = {options.dtmin:g} on average "
            f"until max_steps ran out; use {other}eps >= {10 * eps:g}, looser rtol (now "
            f"{float(np.max(np.asarray(options.rtol))):g}) or a smaller dtmin")
