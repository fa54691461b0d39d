"""Deflation: further periodic orbits at one parameter value from one start, each
known orbit removed from the shooting problem with all its phases and symmetric
copies (Farrell, Birkisson and Funke, *Deflation techniques for finding distinct
solutions of nonlinear partial differential equations*, SIAM J. Sci. Comput. 37
(2015) A2026)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._engine.compat import checks_as_nan
from .._errors import ValidationError
from .._physics.params import ChainParams, is_homogeneous_ring
from .continuation import ContinuationProblem
from .periodic_orbit import cycle_method
from .._printing import values_repr


def chain_symmetries(params: ChainParams) -> Int[Array, "g n_osc"]:
    """The permutations of the oscillators that map the chain onto itself: on the
    homogeneous ring (`is_homogeneous_ring`) its N rotations and N reflections
    (the dihedral group; eq. (5) is unchanged when the oscillators are renumbered
    n -> n + r or n -> r - n, mod N), otherwise the identity alone. Row g is the
    copy y[:, perm[g]] of a state y, shape (g, n_osc)."""
    n = np.arange(params.n_osc)
    if not is_homogeneous_ring(params):
        return jnp.asarray(n[None])
    rotations = [np.roll(n, r) for r in range(params.n_osc)]
    return jnp.asarray(np.unique(np.stack(rotations + [r[::-1] for r in rotations]), axis=0))


def orbit_samples(problem: ContinuationProblem, u: Float[Array, " 2n+1"], n_samples: int,
                  params: ChainParams | None = None) -> Float[Array, "s 2n"]:
    """The states of the periodic orbit `u` (the unknowns of the problem's orbit
    method) at `n_samples` equal steps of one period, the start included, each
    flattened as (x_1..x_N, x_1'..x_N'), shape (n_samples, 2 n_osc): by the
    problem's own method (`AbstractOrbitMethod.samples`).

    **Raises:** `ValidationError` for a problem that is not one of periodic orbits
    (`cycle_problem`)."""
    params = problem.params if params is None else params
    method = cycle_method(problem)
    y0, period = method.orbit(u)
    ts = period * jnp.arange(n_samples) / n_samples
    ys = jnp.concatenate([y0[None], method.samples(params, u, ts[1:])])
    return jnp.reshape(ys, (n_samples, -1))


def _curve_distance2(point, curve, perms):
    """Squared distance from `point` (2n,) to the closed polyline through `curve`
    (s, 2n) and to its symmetric copies (the states y[:, perm] for each row of
    `perms`, shape (g, n)): the smallest over the copies and the s segments.

    A permutation is an isometry and the rows of `perms` form a group, so the copies
    of the point, y[:, perm], are measured against the one curve. The nearest copy
    and segment are chosen without derivatives and the distance to that segment is
    differentiated: the derivative of a minimum is that of its minimiser (almost
    everywhere), and the forward-mode Jacobian then costs one segment, not g s. The
    nearest is found by matrix products (|y - a|^2 expanded, exact to rounding
    relative to |y|^2, enough to choose it)."""
    n = perms.shape[1]

    def copies(y):
        return jnp.reshape(jnp.moveaxis(jnp.reshape(y, (2, n))[:, perms], 1, 0), (-1, 2 * n))

    edges = jnp.roll(curve, -1, axis=0) - curve
    lengths2 = jnp.maximum(jnp.sum(edges**2, -1), 1e-300)
    # the nearest copy and segment, by products with the whole curve at once
    ys = copies(jax.lax.stop_gradient(point))
    along = ys @ edges.T - jnp.sum(curve * edges, -1)[None]  # (y - a) . edge, shape (g, s)
    t = jnp.clip(along / lengths2[None], 0.0, 1.0)
    squared = (jnp.sum(ys**2, -1)[:, None] - 2 * ys @ curve.T + jnp.sum(curve**2, -1)[None]
               - 2 * t * along + t**2 * lengths2[None])
    g, k = jnp.divmod(jnp.argmin(squared), curve.shape[0])
    # the distance to it, differentiable
    offset = copies(point)[g] - curve[k]
    t = jnp.clip(jnp.dot(offset, edges[k]) / lengths2[k], 0.0, 1.0)
    return jnp.sum((offset - t * edges[k]) ** 2)


class Deflation(eqx.Module):
    """The deflation operator M(u) = prod_k (1 / d_k(u)^p + sigma) of Farrell,
    Birkisson and Funke (2015), eq. (2.3), for shooting unknowns u = (y0, T): the
    deflated residual M(u) F(u) has the roots of F except the known ones, where it
    tends to infinity, so Newton's method from the same start goes elsewhere.

    A periodic orbit is a curve, not a point: the phase condition of shooting
    meets it wherever the phase oscillator turns, and every symmetric copy of it
    (`chain_symmetries`) solves the same problem. d_k is therefore the distance of
    y0 from the whole closed curve of orbit k (a polyline through dense samples,
    exact to the chord error, about (T / s)^2 |y''| / 8) and its copies (measured
    as the copies of y0 against the one curve), with the
    period's difference: d_k^2 = min dist(y0, curve)^2 + (T - T_k)^2. Steady sliding
    solves shooting with any T, so it is deflated by the state alone, d^2 = |y0 -
    y_eq|^2.

    **Fields:**

    - `curves`: samples of the known orbits, shape (k, s, 2 n_osc).
    - `perms`: the chain's symmetries (`chain_symmetries`), shape (g, n_osc).
    - `periods`: their periods, shape (k,).
    - `active`: which of the k slots hold an orbit (an unused slot deflates
        nothing: a fixed capacity keeps one compiled solve for every round),
        shape (k,).
    - `equilibria`: deflated equilibria, shape (e, 2 n_osc).
    - `power`: p (> 0), `shift`: sigma (>= 0); Farrell et al. use p = 2, sigma = 1.
    """

    curves: Float[Array, "k s 2n"]
    perms: Int[Array, "g n"]
    periods: Float[Array, " k"]
    active: Bool[Array, " k"]
    equilibria: Float[Array, "e 2n"]
    power: float = eqx.field(static=True, default=2.0)
    shift: float = eqx.field(static=True, default=1.0)

    def distances(self, u: Float[Array, " 2n+1"]) -> Float[Array, " k+e"]:
        """d_k(u) for each known orbit (infinite for an unused slot), then each
        equilibrium, shape (k + e,)."""
        point, period = u[:-1], u[-1]
        on_curves = jax.vmap(lambda c: _curve_distance2(point, c, self.perms))(self.curves)
        orbits = on_curves + (period[None] - self.periods) ** 2
        orbits = jnp.where(self.active, orbits, jnp.inf)
        rest = jnp.sum((point[None] - self.equilibria) ** 2, -1)
        return jnp.sqrt(jnp.concatenate([orbits, rest]))

    def __call__(self, u: Float[Array, " 2n+1"]) -> Float[Array, ""]:
        d = self.distances(u)
        factors = jnp.where(jnp.isinf(d), 1.0, d ** -self.power + self.shift)
        return jnp.prod(factors)


def deflation(problem: ContinuationProblem, known=(), *, n_samples: int = 2048,
              params: ChainParams | None = None, capacity: int | None = None,
              power: float = 2.0, shift: float = 1.0) -> Deflation:
    """The `Deflation` of the periodic orbits `known` of a shooting problem and of
    steady sliding, at `params` (the problem's by default).

    **Arguments:**

    - `problem`: a shooting `ContinuationProblem` (`cycle_problem`).
    - `known`: the known orbits, each as shooting unknowns `pack(y0, T)`, shape
        (2 n_osc + 1,).
    - `n_samples`: samples of each orbit's curve.
    - `capacity`: slots for orbits (at least len(known); len(known) by default).
    - `power`, `shift`: p and sigma of the operator.

    **Raises:** `ValidationError` for n_samples < 8, a capacity below len(known),
    power <= 0 or shift < 0.
    """
    capacity = len(known) if capacity is None else capacity
    if n_samples < 8 or capacity < len(known) or not power > 0 or not shift >= 0:
        raise ValidationError(f"deflation needs n_samples >= 8, capacity >= {len(known)} "
                              f"orbits, power > 0 and shift >= 0, got {n_samples}, "
                              f"{capacity}, {power}, {shift}")
    params = problem.params if params is None else params
    n = params.n_osc
    perms = chain_symmetries(params)
    curves, periods = [], []
    for u in known:
        u = jnp.asarray(u, dtype=float)
        curves.append(orbit_samples(problem, u, n_samples, params))
        periods.append(u[-1])
    unused = capacity - len(known)
    curves += [jnp.zeros((n_samples, 2 * n))] * unused
    periods += [jnp.zeros(())] * unused
    equilibria = jnp.reshape(cycle_method(problem).engine.steady_sliding(params), (1, -1))
    return Deflation(curves=jnp.stack(curves) if curves else jnp.zeros((0, n_samples, 2 * n)),
                     perms=perms,
                     periods=jnp.asarray(periods, dtype=float).reshape(-1),
                     active=jnp.arange(capacity) < len(known), equilibria=equilibria,
                     power=power, shift=shift)


class DeflatedOrbit(eqx.Module):
    """The result of `deflated_orbit`.

    **Fields:**

    - `u`: the shooting unknowns reached, `pack(y0, T)`, shape (2 n_osc + 1,).
    - `residual`: max-norm of the undeflated shooting residual there, shape ().
    - `distance`: the smallest d_k of the `Deflation` there (how far from every known
        orbit, its copies and steady sliding), shape ().
    - `found`: a new periodic orbit: the residual within 1e3 times Newton's
        tolerance and the distance above 1e-4, shape ().
    """

    u: Float[Array, " 2n+1"]
    residual: Float[Array, ""]
    distance: Float[Array, ""]
    found: Bool[Array, ""]

    __repr__ = values_repr


@checks_as_nan
@eqx.filter_jit
def _deflated_solve(problem: ContinuationProblem, params, operator: Deflation, u0):
    method = cycle_method(problem)
    tol = method.newton_tol

    def deflated(u, p):
        return operator(u) * problem.residual(u, p)

    sol = optx.least_squares(deflated, optx.LevenbergMarquardt(rtol=tol, atol=tol), u0, params,
                             options={"jac": "fwd"}, max_steps=5 * method.newton_steps,
                             throw=False)
    residual = jnp.max(jnp.abs(problem.residual(sol.value, params)))
    distance = jnp.min(operator.distances(sol.value))
    found = (residual <= 1e3 * tol) & (distance > 1e-4) & jnp.all(jnp.isfinite(sol.value))
    return DeflatedOrbit(u=sol.value, residual=residual, distance=distance, found=found)


def deflated_orbit(problem: ContinuationProblem, start: Float[Array, " 2n+1"],
                   operator: Deflation, params: ChainParams | None = None) -> DeflatedOrbit:
    """Solve the deflated shooting problem M(u) F(u) = 0 from `start` with
    optimistix's Levenberg-Marquardt method (forward-mode Jacobian, the shooting
    problem's tolerance and five times its Newton budget): a periodic orbit that
    is none of those `operator` deflates, if the iteration finds one.

    **Arguments:**

    - `problem`: a shooting `ContinuationProblem`; its residual is F.
    - `start`: shooting unknowns `pack(y0, T)` to start from, shape (2 n_osc + 1,).
    - `operator`: the `Deflation` (`deflation`).
    - `params`: the parameters (the problem's by default).

    **Returns:** a `DeflatedOrbit` (check `found`).
    """
    params = problem.params if params is None else params
    return _deflated_solve(problem, params, operator, jnp.asarray(start, dtype=float))


def distinct_orbits(problem: ContinuationProblem, start: Float[Array, " 2n+1"], known=(), *,
                    count: int = 4, params: ChainParams | None = None,
                    n_samples: int = 2048, capacity: int | None = None
                    ) -> list[Float[Array, " 2n+1"]]:
    """Further periodic orbits from one start by repeated deflation (Farrell et al.
    2015, Algorithm 1): solve from `start` with the known orbits (and steady
    sliding, and every symmetric copy) deflated, add the orbit found, and solve
    again from the same start, until `count` new orbits or a failure.

    **Arguments:**

    - `problem`: a shooting `ContinuationProblem` (`cycle_problem`).
    - `start`: the start, shooting unknowns `pack(y0, T)` with the phase
        oscillator's velocity 0, shape (2 n_osc + 1,).
    - `known`: orbits already known, each `pack(y0, T)`.
    - `count`: most new orbits to find (>= 1).
    - `params`: the parameters (the problem's by default).
    - `n_samples`: samples of each orbit's curve (`Deflation`).
    - `capacity`: the operator's slots for orbits, at least len(known) + count - 1
        (the default): calls with equal capacity share one compiled solve.

    **Returns:** the new orbits, each `pack(y0, T)`, in the order found.

    **Raises:** `ValidationError` for count < 1 or a capacity below len(known) +
    count - 1.
    """
    if count < 1:
        raise ValidationError(f"count must be >= 1, got {count!r}")
    params = problem.params if params is None else params
    known, found = [jnp.asarray(u, dtype=float) for u in known], []
    least = len(known) + count - 1
    capacity = least if capacity is None else capacity
    if capacity < least:
        raise ValidationError(f"capacity must be >= {least} (the known orbits and "
                              f"count - 1), got {capacity!r}")
    for _ in range(count):
        operator = deflation(problem, known, n_samples=n_samples, params=params,
                             capacity=capacity)
        result = deflated_orbit(problem, start, operator, params)
        if not bool(result.found):
            break
        known.append(result.u)
        found.append(result.u)
    return found
