"""The diffrax solvers jaxchain offers by name (command line, work-precision study)."""

import diffrax
import numpy as np
import optimistix as optx

from ..._physics.forces import static_friction
from .rosenbrock import Ros34PW2


def _imex(cls):
    """An IMEX KenCarp solver with the friction force implicit (see `terms`). Its
    stage equations are solved by Newton's method at the step-size controller's
    tolerances: diffrax's default VeryChord iteration fails to converge on the
    friction term and the step size collapses to about 1e-5."""
    def make():
        return cls(root_finder=diffrax.with_stepsize_controller_tols(optx.Newton)())
    return make


#: Solver name -> constructor.
SOLVERS = {
    "tsit5": diffrax.Tsit5,
    "dopri5": diffrax.Dopri5,
    "dopri8": diffrax.Dopri8,
    "bosh3": diffrax.Bosh3,
    "kvaerno3": diffrax.Kvaerno3,
    "kvaerno5": diffrax.Kvaerno5,
    "kencarp3": _imex(diffrax.KenCarp3),
    "kencarp4": _imex(diffrax.KenCarp4),
    "kencarp5": _imex(diffrax.KenCarp5),
    "ros34pw2": Ros34PW2,
}

#: The solver of `simulate`, `ensemble`, `crosscheck` and the commands when none is
#: given. At the default eps = 1e-3 an explicit method's step size is bounded by the
#: stiff stick phases rather than by accuracy (Bosh3 takes 44M steps on the Fig. 4
#: scene at rtol 1e-5, 50M at 1e-6). ROS34PW2, linearly implicit in the diagonal
#: friction Jacobian, is not: 10.8M steps at the default rtol 3e-5 with
#: `PIController` (15M at the previous rtol 1e-5 with diffrax's controller), with
#: the error of the eps floor (0.24 % on the work-precision chain scene), at about
#: twice the cost per step (documentation, "Choice of eps and solver").
DEFAULT_SOLVER = "ros34pw2"

#: The name that picks a solver from the parameters (`auto_solver`).
AUTO = "auto"

#: Stick stiffness mu_st/eps up to which `auto_solver` takes an explicit method.
#: There an explicit step is bounded by accuracy, not by the stick phase's
#: stability (h <~ 3 eps/mu_st): on the stress matrix's default case Tsit5 takes
#: 967 and 3411 steps at eps = 1e-1 and 1e-2 (mu_st/eps = 10 and 100) against
#: ROS34PW2's 8517 and 10311, each step costing about half; at eps = 1e-3 Tsit5
#: takes 20279 against 11226 (docs/stress.md).
AUTO_STIFFNESS = 100.0


def stick_stiffness(params, eps) -> float:
    """The stiffness of the stick phase, |dF/dv_rel| at v_rel = 0: (P_n/P) mu(0) /
    eps (the smoothed force of eq. (2), -(P_n/P) mu tanh(v_rel/eps); mu_st / eps
    for eq. (1)), its largest over the oscillators and lanes, in units of
    omega_n."""
    return float(np.max(np.asarray(static_friction(params)) / np.asarray(eps)))


def auto_solver(params, eps) -> diffrax.AbstractSolver:
    """The solver for `params` smoothed at `eps`: Tsit5 where the stick phase is not stiff
    (`stick_stiffness`, (P_n/P) mu(0)/eps, <= `AUTO_STIFFNESS` for every
    oscillator and lane), else the stiffness-aware `DEFAULT_SOLVER`, ROS34PW2."""
    stiffness = stick_stiffness(params, eps)
    return SOLVERS["tsit5" if stiffness <= AUTO_STIFFNESS else DEFAULT_SOLVER]()
