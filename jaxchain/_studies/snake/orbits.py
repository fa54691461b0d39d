"""The snake's periodic orbits on either engine: the flow sampled, shooting, the
continuation problem, the Floquet multipliers and the simulations of the checks, of
the smoothed model (tanh(v_rel/eps)) or of the exact stick/slip switch model."""

from __future__ import annotations

import dataclasses

import diffrax
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._bifurcation.continuation import ContinuationProblem
from ..._bifurcation.exact_orbit import (
    ExactShooting,
    exact_cycle_problem,
    exact_floquet_multipliers,
    exact_periodic_orbit,
)
from ..._bifurcation.limit_cycles import limit_cycle_problem
from ..._bifurcation.shooting import (
    ShootingOptions,
    floquet_multipliers,
    flow,
    periodic_orbit,
    unpack,
)
from ..._engine.compat import checks_as_nan
from ..._engine.engines import AbstractEngine, as_engine
from ..._engine.exact.solve import nonsmooth_flow
from ..._engine.options import SimulationOptions
from ..._errors import ValidationError
from ..._physics.params import ChainParams

#: Shooting on a chain: Levenberg-Marquardt converges from a simulated state.
SNAKE_SHOOTING = ShootingOptions(root_finder="levenberg-marquardt")

#: Shooting on the exact engine: Newton's method, forward mode through every switch.
EXACT_SNAKE_SHOOTING = ExactShooting()

_multipliers = checks_as_nan(eqx.filter_jit(floquet_multipliers))
_exact_multipliers = checks_as_nan(eqx.filter_jit(exact_floquet_multipliers))


class SmoothedOrbits:
    """Periodic orbits of eq. (5) with the friction smoothed at `eps`: shooting with
    `ShootingOptions`, simulations on the smoothed engine with `solver`."""

    engine = "smoothed"

    def __init__(self, shooting: ShootingOptions, eps, solver):
        self.shooting, self.eps, self.solver = shooting, eps, solver

    def options(self, phase_oscillator: int) -> ShootingOptions:
        return dataclasses.replace(self.shooting, phase_oscillator=phase_oscillator)

    def samples(self, params: ChainParams, y, ts) -> np.ndarray:
        """The flow from y at the times ts (from 0), shape (m, 2, n_osc)."""
        return np.asarray(flow(params, jnp.asarray(y), float(ts[-1]), self.shooting,
                               diffrax.SaveAt(ts=jnp.asarray(ts)), eps=self.eps).ys)

    def shoot(self, params: ChainParams, y0, period, phase_oscillator: int):
        return periodic_orbit(params, y0, period, self.options(phase_oscillator), eps=self.eps,
                              throw=False)

    def problem(self, orbit, phase_oscillator: int) -> ContinuationProblem:
        return limit_cycle_problem(orbit, self.options(phase_oscillator))

    def multipliers(self, params: ChainParams, u, factor: float = 1.0):
        """(multipliers, trivial index) of the orbit u, the flow's tolerances
        divided by `factor`."""
        options = dataclasses.replace(self.shooting, rtol=self.shooting.rtol / factor,
                                      atol=self.shooting.atol / factor)
        y0, period = unpack(jnp.asarray(u))
        values, index = _multipliers(params, y0, period, options, self.eps)
        return np.asarray(values), int(index)

    #: how much tighter the check of the multipliers' accuracy integrates
    check_factor = 100.0

    def rtol(self, factor: float = 1.0) -> float:
        return self.shooting.rtol / factor

    def simulation(self, options: SimulationOptions, params: ChainParams) -> AbstractEngine:
        return as_engine("smoothed", self.solver, options, params, eps=self.eps)

    def settings(self) -> dict:
        return {"engine": "smoothed", "eps": float(self.eps), "shooting": self.shooting,
                "solver": self.solver if isinstance(self.solver, str)
                else type(self.solver).__name__}


class ExactOrbits:
    """Periodic orbits of the exact stick/slip switch model: shooting with
    `ExactShooting`, simulations on the exact engine at its tolerances."""

    engine = "exact"
    eps = None

    def __init__(self, shooting: ExactShooting):
        self.shooting = shooting

    def options(self, phase_oscillator: int) -> ExactShooting:
        return dataclasses.replace(self.shooting, phase_oscillator=phase_oscillator)

    def samples(self, params: ChainParams, y, ts) -> np.ndarray:
        later, _ = nonsmooth_flow(params, jnp.asarray(y), jnp.asarray(ts[1:]),
                                  self.shooting.flow)
        return np.concatenate([np.asarray(y)[None], np.asarray(later)])

    def shoot(self, params: ChainParams, y0, period, phase_oscillator: int):
        return exact_periodic_orbit(params, y0, period, self.options(phase_oscillator),
                                    throw=False)

    def problem(self, orbit, phase_oscillator: int) -> ContinuationProblem:
        return exact_cycle_problem(orbit, self.options(phase_oscillator))

    def multipliers(self, params: ChainParams, u, factor: float = 1.0):
        """(multipliers, trivial index) of the orbit u, the flow's tolerances
        divided by `factor`."""
        flow_options = dataclasses.replace(self.shooting.flow,
                                           rtol=self.shooting.flow.rtol / factor,
                                           atol=self.shooting.flow.atol / factor)
        options = dataclasses.replace(self.shooting, flow=flow_options)
        y0, period = unpack(jnp.asarray(u))
        values, index = _exact_multipliers(params, y0, period, options)
        return np.asarray(values), int(index)

    #: the exact engine's tolerances are near rounding already (1e-12): the check
    #: integrates 100 times looser, which bounds the error of the tighter run
    check_factor = 0.01

    def rtol(self, factor: float = 1.0) -> float:
        return self.shooting.flow.rtol / factor

    def simulation(self, options: SimulationOptions, params: ChainParams) -> AbstractEngine:
        return as_engine("exact", options=options)

    def settings(self) -> dict:
        return {"engine": "exact", "shooting": self.shooting}


def snake_orbits(engine: str = "smoothed", shooting=None, eps=None, solver=None,
                 params: ChainParams | None = None):
    """The orbits of the snake on the engine named `engine` ("smoothed" or
    "exact"), with its shooting options (`SNAKE_SHOOTING`, `EXACT_SNAKE_SHOOTING` by
    default); eps and the solver of the simulations belong to the smoothed engine
    (`params` resolves solver "auto").

    **Raises:** `ValidationError` for another engine, shooting options of the other
    engine, or eps given to the exact engine."""
    if engine == "smoothed":
        shooting = SNAKE_SHOOTING if shooting is None else shooting
        if not isinstance(shooting, ShootingOptions):
            raise ValidationError("the smoothed engine's shooting takes ShootingOptions")
        checked = as_engine("smoothed", solver, None, params, eps=eps)
        return SmoothedOrbits(shooting, checked.eps, solver)
    if engine == "exact":
        shooting = EXACT_SNAKE_SHOOTING if shooting is None else shooting
        if not isinstance(shooting, ExactShooting):
            raise ValidationError("the exact engine's shooting takes ExactShooting")
        as_engine("exact", eps=eps)  # eps given to the exact engine is an error
        return ExactOrbits(shooting)
    raise ValidationError(f"engine must be 'smoothed' or 'exact', got {engine!r}")
