"""Through a sliding bifurcation: a branch of exact periodic orbits continued past
the point where one oscillator's stick phase vanishes, onto the orbits on which
that oscillator slips throughout.

Where a stick phase shrinks to nothing the branch of stick-slip orbits ends: the
continuation's corrector fails beyond it, and the orbits without that stick phase
often lie on the same side of the parameter (the branch turns there, a
non-smooth fold; di Bernardo, Budd, Champneys and Kowalczyk, *Piecewise-smooth
Dynamical Systems* (2008), Sect. 8.5). Both kinds of orbit meet at the sliding
point in one orbit whose slip arc touches the belt speed. The orbits without
the stick phase are those of the model with that oscillator held in its slip mode
(`NonsmoothOptions.held`): a smooth family through the sliding point, admissible
on the side where the held oscillator's relative velocity keeps its sign, virtual
(it would stick) on the other. Holding the mode fixes the sequence of segments,
as the multi-segment boundary-value problems of hybrid continuation do
(Dankowicz and Schilder, *Recipes for Continuation* (2013), Part IV).
"""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .continuation import (ContinuationOptions, ContinuationProblem, PseudoArclength, _correct,
                           continuation)
from .deflation import orbit_samples
from .periodic_orbit import CycleResidual, cycle_method
from .sliding import _phases, exact_problem
from .._errors import ValidationError


def held_problem(problem: ContinuationProblem, oscillators) -> ContinuationProblem:
    """The exact shooting problem `problem` with `oscillators` (0-based indices, or
    one index) held in their slip mode (`NonsmoothOptions.held`): they never stick
    or reverse.

    **Raises:** `ValidationError` for a problem that is not one of exact orbits
    (`cycle_problem` on the exact engine) or an oscillator outside the chain."""
    if not exact_problem(problem):
        raise ValidationError("held_problem needs a problem of exact orbits "
                              "(cycle_problem with Shooting(Exact().for_orbits()))")
    held = tuple(int(n) for n in np.atleast_1d(oscillators))
    if not all(0 <= n < problem.params.n_osc for n in held):
        raise ValidationError(f"oscillators must be in 0..{problem.params.n_osc - 1}, got "
                              f"{oscillators!r}")
    method = cycle_method(problem)
    held_method = eqx.tree_at(lambda m: m.engine, method, method.engine.holding(held))
    # the residual holds them; the records describe the orbits as they are
    return dataclasses.replace(problem, residual=CycleResidual(held_method))


def slip_margin(problem: ContinuationProblem, z: Float[Array, " n+1"], oscillators, *,
                n_samples: int = 512) -> float:
    """The least relative velocity s (x_n' - v_d) of `oscillators` (0-based indices,
    or one index) over the orbit z = (u, p), each with s the sign it has at t = 0,
    from `n_samples` samples of one period (`orbit_samples`, by the flow of
    `problem`): > 0 where each slips in one direction throughout (no stick, no
    reversal), <= 0 where one reaches the belt speed. Dimensionless (eq. (6))."""
    params = problem.at(z[-1])
    samples = np.asarray(orbit_samples(problem, z[:-1], n_samples, params))
    v_rel = samples[:, params.n_osc + np.atleast_1d(oscillators)] - float(params.v_d)
    return float(np.min(np.sign(v_rel[0]) * v_rel))


def past_sliding_start(problem: ContinuationProblem, z: Float[Array, " n+1"],
                       algorithm: PseudoArclength = PseudoArclength(), *,
                       oscillators=None, ds: float = 2e-3, steps: int = 5
                       ) -> tuple[ContinuationProblem, Float[Array, " n+1"]] | None:
    """A start on the orbits past a sliding bifurcation: those on which the
    oscillators whose stick phases vanished slip throughout.

    From an orbit z of the branch next to the sliding point (its last orbit, or
    `SlidingPoint.z`: the stick phase all but gone; the last orbit is safer, since
    other branches may pass through the same sliding point and the point's own
    orbit, solved near it, may lie on one of them), the model with those
    oscillators held in slip (`held_problem`) is corrected at z's p and continued
    `steps` points of arclength `ds` each way. The way along which their relative
    velocities keep their signs (`slip_margin` > 0) is the admissible one; its
    last point, an orbit of the switch model itself (the held oscillators never
    reach the belt speed), is the start, and the direction from the sliding point
    to it the tangent to go on along. The start must have the stick phases of z
    but the vanished ones (where another oscillator's stick phase appears or
    vanishes at the same point, the held family is not the continuation of this
    branch, and None is returned).

    **Arguments:**

    - `problem`: the branch's `ContinuationProblem` (`cycle_problem` on the exact engine).
    - `z`: the branch's orbit (u, p) next to the sliding point, shape (n + 1,).
    - `algorithm`: the corrector (`PseudoArclength`).
    - `oscillators`: those whose stick phases vanish there (0-based indices); by
        default those whose stick phase at z is the shortest, within 10 %
        (symmetric sites of a ring lose theirs together).
    - `ds`, `steps`: the arclength step and the number of points of the held
        continuation each way.

    **Returns:**

    (the problem at the start, its `u0` the start's shooting unknowns; the
    tangent in (u, p) to continue along, shape (n + 1,)), or None where the held
    orbit does not converge or neither way is admissible.

    **Raises:** `ValidationError` for a problem that is not one of exact orbits.
    """
    if not exact_problem(problem):
        raise ValidationError("past_sliding_start needs a problem of exact orbits "
                              "(cycle_problem with Shooting(Exact().for_orbits()))")
    z = jnp.asarray(z, dtype=float)
    phases = _phases(problem, z)
    sticking = np.isfinite(phases)
    if oscillators is None:
        if not sticking.any():
            return None
        oscillators = np.flatnonzero(phases <= 1.1 * np.min(phases))
    oscillators = np.atleast_1d(oscillators)
    # past the sliding point the same oscillators stick, but the held ones
    remaining = sticking & ~np.isin(np.arange(sticking.size), oscillators)
    held = held_problem(problem, oscillators)
    at_p = jnp.zeros(z.size).at[-1].set(1.0)
    z, ok, _, _ = _correct(held, algorithm, z, at_p)
    if not bool(ok):
        return None
    start = eqx.tree_at(lambda pr: pr.u0, held.with_params(held.at(z[-1])), z[:-1])
    for direction in (1, -1):
        try:
            branch = continuation(start, algorithm, ContinuationOptions(
                ds=ds, ds_min=ds / 8, ds_max=ds, max_points=steps + 1, direction=direction))
        except ValueError:
            return None
        points = [jnp.append(u, p) for u, p, c in zip(branch.u, branch.p, branch.converged)
                  if bool(c)][1:]
        if (points and all(slip_margin(held, w, oscillators) > 0 for w in points)
                and np.array_equal(np.isfinite(_phases(problem, points[-1])), remaining)):
            w = points[-1]
            out = eqx.tree_at(lambda pr: pr.u0, problem.with_params(problem.at(w[-1])), w[:-1])
            return out, (w - z) / jnp.linalg.norm(w - z)
    return None
