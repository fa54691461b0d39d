"""The snake's periodic orbits: an orbit method (shooting on either engine) and the
engine of its simulations, with what the study asks of them: the flow sampled,
orbits, their continuation problem, the Floquet multipliers at another accuracy and
the simulations of the starts and checks."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._bifurcation.continuation import ContinuationProblem
from ..._bifurcation.orbit_method import AbstractOrbitMethod
from ..._bifurcation.periodic_orbit import cycle_problem, periodic_orbit
from ..._bifurcation.shooting import Shooting
from ..._engine.compat import checks_as_nan
from ..._engine.engines import AbstractEngine, Smoothed
from ..._engine.hashes import canonical
from ..._engine.horizon import AbstractHorizon
from ..._engine.solver.registry import SOLVERS
from ..._errors import ValidationError
from ..._physics.params import ChainParams

#: The finest relative tolerance a check of the multipliers tightens the flow to:
#: below it the flow is at rounding, and the check loosens the flow instead (100
#: times), which bounds the error of the tighter run.
FINEST_RTOL = 1e-13


@checks_as_nan
@eqx.filter_jit
def _multipliers(method: AbstractOrbitMethod, params: ChainParams, u):
    return method.multipliers(params, u)


class SnakeOrbits:
    """The periodic orbits of the snake by `method`, and the simulations of its
    starts and checks by `engine` (the same model)."""

    def __init__(self, method: AbstractOrbitMethod, engine: AbstractEngine):
        self.method, self.engine = method, engine
        rtol = method.engine.options.rtol
        #: how much tighter the check of the multipliers' accuracy integrates
        self.check_factor = 100.0 if rtol / 100 >= FINEST_RTOL else 0.01

    def samples(self, params: ChainParams, y, ts) -> np.ndarray:
        """The flow from y at the times ts (from 0), shape (m, 2, n_osc)."""
        later = self.method.engine.flow(params, jnp.asarray(y), jnp.asarray(ts[1:]))
        return np.concatenate([np.asarray(y)[None], np.asarray(later)])

    def shoot(self, params: ChainParams, y0, period, phase_oscillator: int):
        return periodic_orbit(params, (y0, period),
                              self.method.with_phase_oscillator(phase_oscillator), throw=False)

    def problem(self, orbit, phase_oscillator: int) -> ContinuationProblem:
        return cycle_problem(orbit, self.method.with_phase_oscillator(phase_oscillator))

    def multipliers(self, params: ChainParams, u, factor: float = 1.0):
        """(multipliers, trivial index) of the orbit u, the flow's tolerances
        divided by `factor`."""
        values, index = _multipliers(self.method.refine(factor), params, jnp.asarray(u))
        return np.asarray(values), int(index)

    def rtol(self, factor: float = 1.0) -> float:
        return self.method.engine.options.rtol / factor

    def simulation(self, options: AbstractHorizon, params: ChainParams) -> AbstractEngine:
        """The engine of the simulations over the horizon of `options`."""
        return self.engine.with_horizon(options)

    def settings(self) -> dict:
        """What keys a stored branch: in the previous release's form for the two
        methods it had (`_previous_settings`), so that its stores read back;
        otherwise the method and the simulations' engine themselves."""
        previous = _previous_settings(self.method, self.engine)
        return {"method": self.method, "simulations": self.engine} if previous is None \
            else previous


def _solver_name(solver) -> str:
    """The registry's name of a solver (`SOLVERS`), or its class's name."""
    return next((name for name, make in SOLVERS.items() if type(solver) is make),
                type(solver).__name__)


def _previous_settings(method, engine: AbstractEngine) -> dict | None:
    """The settings of a branch in the previous release's words, where its method
    had them: shooting on the smoothed engine's orbit flow (Tsit5, diffrax's PID
    controller) without the damped fallback, or on the exact engine by Newton's
    method; None otherwise. The key is then the one the previous release stored its
    branches under (the previous options' class names and fields)."""
    if not isinstance(method, Shooting):
        return None
    flow = method.engine
    common = {"n_samples": method.n_samples, "newton_steps": method.newton_steps,
              "newton_tol": method.newton_tol, "phase_oscillator": method.phase_oscillator}
    if flow.has_stick_phases and method.root_finder == "newton":
        return {"engine": "exact", "shooting": {
            "class": "jaxchain._bifurcation.exact_orbit.ExactShooting",
            "fields": common | {"damped_steps": method.damped_steps,
                                "flow": canonical(flow.options)}}}
    undamped = method.root_finder != "newton" or method.damped_steps == 0
    if (flow.smooths and engine.smooths and undamped and flow.options.controller == "diffrax"
            and float(flow.eps) == float(engine.eps)):
        return {"engine": "smoothed", "eps": float(flow.eps), "shooting": {
            "class": "jaxchain._bifurcation.shooting.ShootingOptions",
            "fields": common | {"solver": canonical(flow.solver), "rtol": flow.options.rtol,
                                "atol": flow.options.atol,
                                "max_steps": flow.options.max_steps,
                                "root_finder": method.root_finder}},
            "solver": _solver_name(engine.solver)}
    return None


def snake_orbits(method: AbstractOrbitMethod | None = None,
                 engine: AbstractEngine | None = None) -> SnakeOrbits:
    """The orbits of the snake by `method` (`Shooting.from_simulations(Smoothed())`
    by default: Levenberg-Marquardt at eps = 1e-3) with simulations by `engine`
    (the method's model with its default simulation settings,
    `AbstractEngine.simulating`, by default).

    **Raises:** `ValidationError` for a method or engine of another kind."""
    method = Shooting.from_simulations(Smoothed()) if method is None else method
    if not isinstance(method, AbstractOrbitMethod):
        raise ValidationError(f"method must be an orbit method (Shooting), got "
                              f"{type(method).__name__}")
    engine = method.engine.simulating() if engine is None else engine
    if not isinstance(engine, AbstractEngine):
        raise ValidationError(f"engine must be an engine (Smoothed or Exact), got "
                              f"{type(engine).__name__}")
    return SnakeOrbits(method, engine)
