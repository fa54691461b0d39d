"""Periodic orbits by any orbit method: `periodic_orbit` solves for one from a guess,
`cycle_problem` hands its branch to `continuation`, and `cycle_method` reads the
method back from a problem; `Shooting` on the smoothed engine is the default
method."""

import equinox as eqx
import jax.numpy as jnp

from .._checks import check_positive
from .._errors import ValidationError
from .._physics.custom_types import State
from .._physics.params import ChainParams
from .continuation import ContinuationProblem, describe_point
from .orbit_method import AbstractOrbitMethod, PeriodicOrbit
from .shooting import Shooting


class DescribeOrbit(eqx.Module):
    """The method's `describe`, as a `ContinuationProblem` record: equal methods
    give equal records, so continuation compiles once."""

    method: AbstractOrbitMethod

    def __call__(self, u, params):
        return self.method.describe(u, params)


class CycleResidual(eqx.Module):
    """The method's `residual`, as a `ContinuationProblem` residual."""

    method: AbstractOrbitMethod

    def __call__(self, u, params):
        return self.method.residual(u, params)


def _checked(method) -> AbstractOrbitMethod:
    """`method`, or `Shooting()` where None.

    **Raises:** `ValidationError` for anything else, with the form that replaced the
    previous release's `periodic_orbit(params, y0, period, options, eps=...)`."""
    if method is None:
        return Shooting()
    if not isinstance(method, AbstractOrbitMethod):
        raise ValidationError(
            f"method must be an orbit method such as jaxchain.Shooting, got "
            f"{type(method).__name__}; periodic_orbit(params, y0, period, options) is "
            "periodic_orbit(params, (y0, period), Shooting(...)) now")
    return method


def as_guess(guess) -> tuple[State, float]:
    """(y0, period) of a guess: a `PeriodicOrbit`, or a pair (state, period)."""
    if isinstance(guess, PeriodicOrbit):
        return guess.y0, guess.period
    try:
        y0, period = guess
    except (TypeError, ValueError):
        raise ValidationError("guess must be a pair (y0, period) or a PeriodicOrbit, got "
                              f"{type(guess).__name__}") from None
    check_positive("period", period)
    return jnp.asarray(y0, dtype=float), period


def periodic_orbit(params: ChainParams, guess, method: AbstractOrbitMethod | None = None, *,
                   throw: bool = True) -> PeriodicOrbit:
    """Solve for a periodic orbit of eq. (5) from a guess by an orbit method, and
    describe it: period, amplitudes, the oscillators on the HALC, Floquet
    multipliers and stability.

    **Arguments:**

    - `params`: the chain parameters.
    - `guess`: a pair (y0, period): a state on or near the orbit, shape (2, n_osc)
        (the end of a long simulation, for instance), and the period's guess (> 0);
        or a `PeriodicOrbit` (of other parameters, say).
    - `method`: an `AbstractOrbitMethod`; `Shooting()` (single shooting on the
        smoothed engine at eps = 1e-3) by default. `Shooting(Exact().for_orbits())`
        solves the exact stick/slip model.
    - `throw`: raise if the method does not converge (default); otherwise return
        the orbit with `converged=False`.

    **Returns:**

    A `PeriodicOrbit`.

    **Raises:**

    `ValidationError` for a guess of the wrong shape, a non-positive period or a
    phase oscillator outside the chain; `RuntimeError` if the method does not
    converge and `throw=True`.
    """
    method = _checked(method)
    y0, period = as_guess(guess)
    u, ok = method.solve(params, method.unknowns(params, y0, period))
    # the record by continuation's own program (`describe_point`), compiled once
    orbit = describe_point(DescribeOrbit(method), u, params, params.v_d, "v_d")
    orbit = eqx.tree_at(lambda o: o.converged, orbit, orbit.converged & ok)
    if throw and not bool(orbit.converged):
        raise RuntimeError(f"{type(method).__name__} did not converge: start from a state "
                           "closer to the orbit (after a longer simulation) or a better "
                           "period guess")
    return orbit


def cycle_problem(orbit: PeriodicOrbit, method: AbstractOrbitMethod | None = None,
                  where="v_d") -> ContinuationProblem:
    """The `ContinuationProblem` of the periodic orbits through `orbit`: the method's
    unknowns and residual, its records (`PeriodicOrbit`: Floquet multipliers,
    stability, n_HALC), to follow with `continuation` (pseudo-arclength, Keller
    1977) in any parameter.

    **Arguments:**

    - `orbit`: a converged `PeriodicOrbit`.
    - `method`: the method of every point (`Shooting()` by default); the one that
        found `orbit`.
    - `where`: the continued parameter, a name or a lens (default the belt speed).
    """
    method = _checked(method)
    return ContinuationProblem(
        residual=CycleResidual(method), u0=method.start(orbit),
        params=orbit.params, where=where, describe=DescribeOrbit(method))


def orbit_residual(problem: ContinuationProblem) -> CycleResidual | None:
    """The `CycleResidual` of a problem of periodic orbits (`cycle_problem`), or of
    the one whose folds a fold system follows (its `problem`); None for another
    problem."""
    residual = problem.residual
    while isinstance(getattr(residual, "problem", None), ContinuationProblem):
        residual = residual.problem.residual
    return residual if isinstance(residual, CycleResidual) else None


def cycle_method(problem: ContinuationProblem) -> AbstractOrbitMethod:
    """The orbit method of a problem of periodic orbits (`cycle_problem`), or of the
    one whose folds a fold system follows (its `problem`).

    **Raises:** `ValidationError` for a problem that is not one of periodic orbits."""
    residual = orbit_residual(problem)
    if residual is None:
        raise ValidationError("the problem is not one of periodic orbits (cycle_problem), "
                              f"got a residual {type(problem.residual).__name__}")
    return residual.method
