"""The Hopf and fold belt speeds as functions of a second parameter, with their
derivatives by implicit differentiation. The fold is followed by the one
continuation loop (`continuation`), applied to its extended system."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._engine.compat import checks_as_nan
from .._engine.engines import AbstractEngine, Smoothed
from .._physics.params import ChainParams, parameter_value, with_parameter
from .continuation import (Branch, ContinuationOptions, ContinuationProblem, PseudoArclength,
                           continuation)
from .fold import FoldSystem, solve_fold
from .hopf import check_engine, hopf_vd
from .periodic_orbit import cycle_method
from .._errors import ValidationError
from .._printing import values_repr


def hopf_vd_and_derivative(params: ChainParams, where: Callable | str, value, *,
                           engine: AbstractEngine = Smoothed()):
    """`hopf_vd` at `where(params) = value` and its derivative in `value` (forward
    mode through the implicit function); both NaN where Newton's method failed.
    Compiled once for every value of `value` and of the engine's eps (`where` is
    static).

    **Arguments:**

    - `params`, `where`, `value`: the chain, the parameter (a name or a lens) and
        its value.
    - `engine`: the engine whose model's Hopf point it is (`hopf_point`);
        `Smoothed()` (eps = 1e-3) by default.

    **Raises:**

    `TypeError` for an `engine` that is not one.
    """
    return _hopf_vd_and_derivative(params, where, jnp.asarray(value, dtype=float),
                                   check_engine(engine))


@checks_as_nan
@eqx.filter_jit
def _hopf_vd_and_derivative(params, where, value, engine):
    hopf, derivative = jax.jvp(lambda x: hopf_vd(with_parameter(params, where, x),
                                                 engine=engine),
                               (value,), (jnp.ones_like(value),))
    return hopf, jnp.where(jnp.isnan(hopf), jnp.nan, derivative)


@checks_as_nan
@eqx.filter_jit
def _derivative(problem: ContinuationProblem, where, value, solution):
    def solve(v):
        return solve_fold(problem.with_params(with_parameter(problem.params, where, v)),
                          solution)[0]
    return jax.jvp(solve, (value,), (jnp.ones_like(value),))[1]


def fold_and_derivative(problem: ContinuationProblem, where: Callable | str, value,
                        start: Float[Array, " 2n+1"]):
    """Newton's method on the fold's extended system (`solve_fold`) at
    `where(params) = value`, from `start` = (u, p, w).

    **Returns:**

    (solution (u, p, w); its derivative in `value`, a forward-mode pass through
    optimistix's `ImplicitAdjoint` at the solution, NaN if Newton's method
    failed; whether Newton's method converged).
    """
    value = jnp.asarray(value, dtype=float)
    solution, ok = solve_fold(problem.with_params(with_parameter(problem.params, where, value)),
                              start)
    if not bool(ok):
        return solution, jnp.full_like(solution, jnp.nan), ok
    return solution, _derivative(problem, where, value, solution), ok


def fold_curve_problem(problem: ContinuationProblem, fold_solution: Float[Array, " 2n+1"],
                       where: Callable | str) -> ContinuationProblem:
    """The `ContinuationProblem` of a fold in a second parameter: unknowns
    (u, p, w) of the Moore-Spence extended system (`FoldSystem`), the continued
    parameter `where` (Kuznetsov, *Elements of Applied Bifurcation Theory*,
    Sect. 10.2.2: two-parameter continuation of folds).

    **Arguments:**

    - `problem`: the one-parameter problem whose fold is followed (for example
        `cycle_problem`), at the parameters of `fold_solution`.
    - `fold_solution`: a solution (u, p, w) of its extended system, shape (2n + 1,).
    - `where`: the second parameter, a name (`"xi"`) or a lens.
    """
    return ContinuationProblem(residual=FoldSystem(problem),
                               u0=jnp.asarray(fold_solution, dtype=float),
                               params=problem.params, where=where)


def _hermite(branch: Branch, value: float) -> list[np.ndarray]:
    """Points z = (u, p, w, value) on the branch where its parameter crosses `value`:
    cubic Hermite interpolation in arclength between two converged neighbours,
    from their positions and unit tangents (error O(ds^4))."""
    ok = np.asarray(branch.converged)
    z = np.concatenate([np.asarray(branch.u), np.asarray(branch.p)[:, None]], axis=1)[ok]
    t = np.asarray(branch.tangent)[ok]
    out = []
    for a in range(len(z) - 1):
        b = a + 1
        if (z[a, -1] - value) * (z[b, -1] - value) > 0:
            continue
        h = np.linalg.norm(z[b] - z[a])
        # p(s) = c3 s^3 + c2 s^2 + c1 s + c0 on s in [0, 1]
        pa, pb, ma, mb = z[a, -1], z[b, -1], h * t[a, -1], h * t[b, -1]
        coeffs = [2 * pa + ma - 2 * pb + mb, -3 * pa - 2 * ma + 3 * pb - mb, ma, pa - value]
        roots = [r.real for r in np.roots(coeffs) if abs(r.imag) < 1e-12 and
                 -1e-12 <= r.real <= 1 + 1e-12]
        if not roots:
            continue
        s = roots[0]
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        out.append(h00 * z[a] + h10 * h * t[a] + h01 * z[b] + h11 * h * t[b])
    return out


class BoundaryCurves(eqx.Module):
    """The edges of the bistable range of belt speeds against a second parameter.

    **Fields:**

    - `values`: the second parameter, shape (n_values,).
    - `hopf_vd`: Hopf belt speed of steady sliding, shape (n_values,); NaN where
        Newton's method did not find it (`hopf_vd`).
    - `fold_vd`: fold belt speed of the limit cycle, shape (n_values,); NaN where
        the fold was not found.
    - `d_hopf`, `d_fold`: their derivatives in the second parameter (implicit
        differentiation), shape (n_values,).
    - `converged`: whether the fold was found, shape (n_values,).
    - `solutions`: the fold's extended-system solution (u, p, w) at each value,
        shape (n_values, 2n + 1); NaN where not found.
    - `branches`: the fold curve as continued (`Branch`es of
        `fold_curve_problem`), one for each direction from the start.

    Between `hopf_vd` and `fold_vd` steady sliding and stick-slip are both stable.
    """

    values: Float[Array, " n_values"]
    hopf_vd: Float[Array, " n_values"]
    fold_vd: Float[Array, " n_values"]
    d_hopf: Float[Array, " n_values"]
    d_fold: Float[Array, " n_values"]
    converged: Bool[Array, " n_values"]
    solutions: Float[Array, "n_values 2n+1"]
    branches: tuple[Branch, ...]

    __repr__ = values_repr


#: Steps of the fold curve in (u, p, w, second parameter).
FOLD_CURVE_OPTIONS = ContinuationOptions(ds=0.02, ds_min=1e-6, ds_max=0.1, max_points=200)


def fold_curve(problem: ContinuationProblem, fold_solution: Float[Array, " 2n+1"],
               where: Callable | str, values, *,
               options: ContinuationOptions = FOLD_CURVE_OPTIONS,
               algorithm: PseudoArclength = PseudoArclength(),
               progress: bool = False):
    """The fold of `problem` at each of `values` of a second parameter.

    The fold's extended system is continued in (u, p, w, value) by the one
    pseudo-arclength loop (`continuation` of `fold_curve_problem`), both ways from
    the start until the parameter leaves the range of `values`; its step control
    keeps every corrector inside Newton's basin, which at small eps is narrow.
    At each requested value the branch is interpolated (cubic Hermite, from the
    two neighbouring points and tangents) and Newton's method on the extended
    system at that value polishes it (`fold_and_derivative`).

    **Arguments:**

    - `problem`: the one-parameter problem, at the parameters of `fold_solution`.
    - `fold_solution`: a solution (u, p, w) of its extended system, or a point
        within Newton's basin of one (it is polished first).
    - `where`: the second parameter, a name or a lens.
    - `values`: the values wanted.
    - `options`: steps of the continuation; `p_min`, `p_max` and `direction` are
        set here.
    - `algorithm`: `PseudoArclength`.
    - `progress`: show tqdm bars.

    **Returns:**

    (solutions of shape (n_values, 2n + 1), derivatives in the value of the same
    shape, converged of shape (n_values,), the two `Branch`es). NaN where a value
    was not reached.

    **Raises:**

    `ValidationError` if `values` is empty; `ValueError` (a failed computation, not a
    `ValidationError`) if Newton's method does not converge from `fold_solution`.
    """
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        raise ValidationError("values must not be empty")
    fold_solution, ok = solve_fold(problem, jnp.asarray(fold_solution, dtype=float))
    if not bool(ok):
        raise ValueError("fold_solution is not near a fold of problem: Newton's method on "
                         "the extended system did not converge from it")
    curve = fold_curve_problem(problem, fold_solution, where)
    base = float(parameter_value(problem.params, where))
    span = max(values.max() - values.min(), 1e-3 * max(abs(base), 1.0))
    lo, hi = min(values.min(), base) - 0.05 * span, max(values.max(), base) + 0.05 * span
    branches = []
    for direction, needed in ((1, values.max() > base), (-1, values.min() < base)):
        if needed:
            branches.append(continuation(curve, algorithm, eqx.tree_at(
                lambda o: (o.p_min, o.p_max, o.direction), options, (lo, hi, direction)),
                progress=progress))
    n = fold_solution.size
    solutions = np.full((values.size, n), np.nan)
    derivatives = np.full((values.size, n), np.nan)
    converged = np.zeros(values.size, dtype=bool)
    for i, value in enumerate(values):
        starts = [np.asarray(fold_solution)] if value == base else []
        for branch in branches:
            starts += [z[:-1] for z in _hermite(branch, value)]
        for start in starts:
            solution, derivative, ok = fold_and_derivative(problem, where, value,
                                                           jnp.asarray(start))
            if bool(ok):
                solutions[i], derivatives[i], converged[i] = solution, derivative, True
                break
    return solutions, derivatives, converged, branches


def boundary_curves(problem: ContinuationProblem, fold_solution: Float[Array, " 2n+1"],
                    where: Callable | str, values, *,
                    options: ContinuationOptions = FOLD_CURVE_OPTIONS,
                    engine: AbstractEngine | None = None,
                    progress: bool = False) -> BoundaryCurves:
    """Continue the Hopf point of steady sliding and the fold of limit cycles in a
    second parameter: the fold by `fold_curve` (pseudo-arclength continuation of
    its extended system, polished at each value), the Hopf point by Newton's
    method at each value (`hopf_vd`); both derivatives by implicit
    differentiation.

    **Arguments:**

    - `problem`: the limit cycles' `ContinuationProblem` (`cycle_problem`),
        at the parameters of `fold_solution`.
    - `fold_solution`: a solution (u, p, w) of the extended system there (from
        `solve_fold` or `fold_point`).
    - `where`: the second parameter, a name (`"xi"`, `"mu_st"`) or a lens.
    - `values`: the values to visit, on either side of the current one.
    - `options`: steps of the fold curve's continuation.
    - `engine`: the engine whose model's Hopf point it is (`hopf_point`); None
        (the default) takes the problem's limit cycles' (its method's engine,
        `AbstractEngine.as_smoothed`), so that both edges belong to one smoothed
        model.
    - `progress`: show tqdm bars.

    **Returns:**

    `BoundaryCurves` at `values` (sorted).

    **Raises:**

    `ValidationError` if `values` is empty, or `engine` is None for a problem
    that does not smooth; `ValueError` (a failed computation, not a
    `ValidationError`) if Newton's method does not converge from `fold_solution`.
    """
    values = np.sort(np.asarray(values, dtype=float))
    engine = (cycle_method(problem).engine.as_smoothed("boundary_curves") if engine is None
              else engine)
    solutions, derivatives, converged, branches = fold_curve(
        problem, fold_solution, where, values, options=options, progress=progress)
    hopf = [hopf_vd_and_derivative(problem.params, where, v, engine=engine) for v in values]
    n = problem.u0.size
    return BoundaryCurves(
        values=jnp.asarray(values), hopf_vd=jnp.stack([h for h, _ in hopf]),
        d_hopf=jnp.stack([d for _, d in hopf]), fold_vd=jnp.asarray(solutions[:, n]),
        d_fold=jnp.asarray(derivatives[:, n]), converged=jnp.asarray(converged),
        solutions=jnp.asarray(solutions), branches=tuple(branches))
