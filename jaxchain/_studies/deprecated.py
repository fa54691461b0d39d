"""The names of the orbit layer that the documentation and notebooks of the previous
release used, kept for one release as deprecated aliases of the method as a value
(`Shooting` on either engine) and of the engine as a value (`simulate` with
`engine=Exact(...)`, `Exact.run`): each works as before and warns once where it is
called. They are not public names (`jaxchain.__all__`); `jaxchain.__getattr__`
finds them."""

import warnings

import diffrax

from .._bifurcation.periodic_orbit import cycle_problem, periodic_orbit
from .._bifurcation.shooting import Shooting, pack
from .._engine.engines import Exact, Smoothed
from .._engine.exact.options import NonsmoothOptions
from .._engine.options import SimulationOptions
from .._engine.simulate import simulate
from .._physics.forces import DEFAULT_EPS


def _warn(old: str, new: str) -> None:
    warnings.warn(f"jaxchain.{old} is deprecated and goes in the next release: use {new}",
                  DeprecationWarning, stacklevel=3)


def ShootingOptions(solver=None, rtol=1e-10, atol=1e-12, max_steps=200_000, newton_tol=1e-9,
                    newton_steps=40, n_samples=4096, phase_oscillator=0,
                    root_finder="newton") -> Shooting:
    """Deprecated: `Shooting(Smoothed(eps=...).for_orbits(rtol, atol), ...)`; the
    smoothing velocity is that of `Smoothed` (`DEFAULT_EPS`)."""
    _warn("ShootingOptions", "jaxchain.Shooting(jaxchain.Smoothed(eps=...).for_orbits())")
    engine = Smoothed(diffrax.Tsit5() if solver is None else solver, SimulationOptions(
        rtol=rtol, atol=atol, max_steps=max_steps, controller="diffrax"))
    return Shooting(engine, newton_tol=newton_tol, newton_steps=newton_steps,
                    root_finder=root_finder, damped_steps=0, n_samples=n_samples,
                    phase_oscillator=phase_oscillator)


def ExactShooting(flow: NonsmoothOptions | None = None, newton_tol=1e-9, newton_steps=40,
                  damped_steps=120, n_samples=4096, phase_oscillator=0) -> Shooting:
    """Deprecated: `Shooting(Exact().for_orbits(), ...)`."""
    _warn("ExactShooting", "jaxchain.Shooting(jaxchain.Exact().for_orbits())")
    flow = NonsmoothOptions.reference(t_end=1.0, transient=0.0) if flow is None else flow
    return Shooting(Exact(flow), newton_tol=newton_tol, newton_steps=newton_steps,
                    damped_steps=damped_steps, n_samples=n_samples,
                    phase_oscillator=phase_oscillator)


def exact_periodic_orbit(params, y0, period, options: Shooting | None = None, *,
                         throw: bool = True):
    """Deprecated: `periodic_orbit(params, (y0, period), Shooting(Exact().for_orbits()))`."""
    _warn("exact_periodic_orbit", "jaxchain.periodic_orbit(params, (y0, period), "
          "jaxchain.Shooting(jaxchain.Exact().for_orbits()))")
    method = Shooting(Exact().for_orbits()) if options is None else options
    return periodic_orbit(params, (y0, period), method, throw=throw)


def exact_cycle_problem(orbit, options: Shooting | None = None, where="v_d"):
    """Deprecated: `cycle_problem(orbit, Shooting(Exact().for_orbits()), where)`."""
    _warn("exact_cycle_problem", "jaxchain.cycle_problem(orbit, method)")
    return cycle_problem(orbit, Shooting(Exact().for_orbits()) if options is None
                         else options, where)


def limit_cycle_problem(orbit, options: Shooting | None = None, where="v_d"):
    """Deprecated: `cycle_problem(orbit, Shooting(...), where)`."""
    _warn("limit_cycle_problem", "jaxchain.cycle_problem(orbit, method)")
    return cycle_problem(orbit, options, where)


def floquet_multipliers(params, y0, period, options: Shooting | None = None,
                        eps=DEFAULT_EPS):
    """Deprecated: `Shooting(...).multipliers(params, u)`."""
    _warn("floquet_multipliers", "jaxchain.Shooting(...).multipliers(params, u)")
    method = Shooting() if options is None else options
    engine = method.engine
    if engine.smooths:
        method = Shooting(Smoothed(engine.solver, engine.options, eps), **{
            name: getattr(method, name) for name in (
                "newton_tol", "newton_steps", "root_finder", "damped_steps", "n_samples",
                "phase_oscillator")})
    return method.multipliers(params, pack(y0, period))


def exact_bistable_range(params=None, *, xi_values=None, ratio_values=None):
    """Deprecated: `bistable_range(params, method=Shooting(Exact().for_orbits()))`;
    returns (summary, (curves in xi, curves in mu_st)) as before."""
    _warn("exact_bistable_range", "jaxchain.bistable_range(params, "
          "method=jaxchain.Shooting(jaxchain.Exact().for_orbits()))")
    from .bistable_range import BISTABLE_RATIO_VALUES, BISTABLE_XI_VALUES
    from .grazing_range import grazing_range

    return grazing_range(params, xi_values=BISTABLE_XI_VALUES if xi_values is None else
                         xi_values, ratio_values=BISTABLE_RATIO_VALUES
                         if ratio_values is None else ratio_values)


def simulate_nonsmooth(params, y0, options: NonsmoothOptions | None = None, *,
                       throw: bool = True, progress: bool = False):
    """Deprecated: `simulate(params, y0, engine=Exact(NonsmoothOptions.reference()))`;
    returns its `Observables` (the exact engine's fields filled in)."""
    _warn("simulate_nonsmooth", "jaxchain.simulate(params, y0, engine=jaxchain.Exact("
          "jaxchain.NonsmoothOptions.reference()))")
    options = NonsmoothOptions.reference() if options is None else options
    return simulate(params, y0, engine=Exact(options), throw=throw, progress=progress)


def run_nonsmooth(params, y0, options: NonsmoothOptions, progress: bool = False):
    """Deprecated: `Exact(options).run(params, y0)`, pure and traceable."""
    _warn("run_nonsmooth", "jaxchain.Exact(options).run(params, y0)")
    return Exact(options).run(params, y0, progress)


#: The deprecated names, for `jaxchain.__getattr__`.
DEPRECATED = {f.__name__: f for f in (ShootingOptions, ExactShooting, exact_periodic_orbit,
                                      exact_cycle_problem, limit_cycle_problem,
                                      floquet_multipliers, exact_bistable_range,
                                      simulate_nonsmooth, run_nonsmooth)}
