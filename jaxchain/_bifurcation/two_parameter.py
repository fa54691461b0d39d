"""The Hopf and fold belt speeds as functions of a second parameter, with their
derivatives by implicit differentiation."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float
from tqdm.auto import tqdm

from .._params import ChainParams
from .continuation import ContinuationProblem
from .fold import solve_fold
from .hopf import _hopf_modes


def hopf_vd(params: ChainParams, guess: float = 1.0) -> Float[Array, ""]:
    """The Hopf belt speed of steady sliding (the largest over the Fourier modes),
    traceable and differentiable in `params` by implicit differentiation through
    optimistix's Newton method (`hopf_point`)."""
    return _hopf_modes(params, jnp.asarray(guess, dtype=float), 1e-12, 1e-12)[0].max()


def with_parameter(problem: ContinuationProblem, where: Callable, value) -> ContinuationProblem:
    """`problem` with the parameter `where(params)` set to `value`."""
    return eqx.tree_at(lambda pr: where(pr.params), problem, value)


@eqx.filter_jit
def _derivative(problem: ContinuationProblem, where: Callable, value, solution):
    def solve(v):
        return solve_fold(with_parameter(problem, where, v), solution)[0]
    return jax.jvp(solve, (value,), (jnp.ones_like(value),))[1]


def fold_and_derivative(problem: ContinuationProblem, where: Callable, value,
                        start: Float[Array, " 2n+1"]):
    """The fold's extended-system solution (u, p, w) at `where(params) = value`,
    from `start`, its derivative in `value` (a forward-mode pass through
    optimistix's `ImplicitAdjoint` at the converged solution; NaN if Newton's
    method failed), and whether Newton's method converged."""
    value = jnp.asarray(value, dtype=float)
    solution, ok = solve_fold(with_parameter(problem, where, value), start)
    if not bool(ok):
        return solution, jnp.full_like(solution, jnp.nan), ok
    return solution, _derivative(problem, where, value, solution), ok


class BoundaryCurves(eqx.Module):
    """The edges of the bistable range of belt speeds against a second parameter.

    **Fields:**

    - `values`: the second parameter, shape (n_values,).
    - `hopf_vd`: Hopf belt speed of steady sliding, shape (n_values,).
    - `fold_vd`: fold belt speed of the limit cycle, shape (n_values,); NaN where
        the fold was not found.
    - `d_hopf`, `d_fold`: their derivatives in the second parameter (implicit
        differentiation), shape (n_values,).
    - `converged`: whether the fold was found, shape (n_values,).

    Between `hopf_vd` and `fold_vd` steady sliding and stick-slip are both stable.
    """

    values: Float[Array, " n_values"]
    hopf_vd: Float[Array, " n_values"]
    fold_vd: Float[Array, " n_values"]
    d_hopf: Float[Array, " n_values"]
    d_fold: Float[Array, " n_values"]
    converged: Bool[Array, " n_values"]


def follow_fold(problem: ContinuationProblem, where: Callable, value: float,
                solution: Float[Array, " 2n+1"], derivative: Float[Array, " 2n+1"],
                target: float, max_halvings: int = 6):
    """Walk the fold's extended-system solution from `where(params) = value` to
    `target` with the tangent predictor solution + step * derivative; a failed step
    is halved, at most `max_halvings` times. Returns (solution, derivative, ok) at
    `target`, or at the last value reached with ok False."""
    step, halvings = target - value, 0
    while abs(target - value) > 1e-14:
        step = np.sign(step) * min(abs(step), abs(target - value))
        new, new_derivative, ok = fold_and_derivative(
            problem, where, value + step, solution + step * derivative)
        if bool(ok):
            value, solution, derivative = value + step, new, new_derivative
        else:
            step, halvings = step / 2, halvings + 1
            if halvings > max_halvings:
                return solution, derivative, False
    return solution, derivative, True


def _walk(problem, where, start, base, targets, max_halvings, bar):
    """`follow_fold` from `base` through `targets` (sorted away from base); stops at
    the first target it cannot reach."""
    out = {}
    value = base
    solution, derivative, _ = fold_and_derivative(problem, where, base, start)
    for target in targets:
        solution, derivative, ok = follow_fold(problem, where, value, solution, derivative,
                                               target, max_halvings)
        if not ok:
            break
        value = target
        out[target] = (solution, derivative)
        bar.update()
    return out


def boundary_curves(problem: ContinuationProblem, fold_solution: Float[Array, " 2n+1"],
                    where: Callable, values, *, max_halvings: int = 6,
                    progress: bool = False) -> BoundaryCurves:
    """Continue the Hopf point of steady sliding and the fold of limit cycles in a
    second parameter: the fold by its extended system (`solve_fold`), step by step
    with the tangent predictor that implicit differentiation gives
    (d(u, p, w)/d value from optimistix's `ImplicitAdjoint`), the Hopf point by
    Newton's method at each value (`hopf_vd`).

    **Arguments:**

    - `problem`: the limit cycles' `ContinuationProblem` (`limit_cycle_problem`),
        at the parameters of `fold_solution`.
    - `fold_solution`: a solution (u, p, w) of the extended system there (from
        `solve_fold`).
    - `where`: lens of the second parameter, e.g. `lambda p: p.xi`.
    - `values`: the values to visit; the walk starts at the current value and goes
        both ways.
    - `max_halvings`: how often a failed step is halved before the walk stops.
    - `progress`: show a tqdm bar.

    **Returns:**

    `BoundaryCurves` at `values` (sorted).

    **Raises:**

    `ValueError` if `values` is empty.
    """
    values = np.sort(np.asarray(values, dtype=float))
    if values.size == 0:
        raise ValueError("values must not be empty")
    base = float(where(problem.params))
    n = problem.u0.size
    with tqdm(total=values.size, desc="fold vs parameter", disable=not progress,
              leave=False) as bar:
        found = _walk(problem, where, fold_solution, base, list(values[values >= base]),
                      max_halvings, bar)
        found |= _walk(problem, where, fold_solution, base,
                       list(values[values < base][::-1]), max_halvings, bar)
    hopf, d_hopf = [], []
    for v in values:
        h, dh = jax.jvp(lambda x: hopf_vd(where_set(problem.params, where, x)),
                        (jnp.asarray(v),), (jnp.asarray(1.0),))
        hopf.append(h)
        d_hopf.append(dh)
    nan = jnp.full(2 * n + 1, jnp.nan)
    fold = [found.get(v, (nan, nan)) for v in values]
    return BoundaryCurves(
        values=jnp.asarray(values), hopf_vd=jnp.stack(hopf), d_hopf=jnp.stack(d_hopf),
        fold_vd=jnp.stack([s[n] for s, _ in fold]), d_fold=jnp.stack([d[n] for _, d in fold]),
        converged=jnp.asarray([v in found for v in values]))


def where_set(params: ChainParams, where: Callable, value) -> ChainParams:
    """`params` with `where(params)` set to `value`."""
    return eqx.tree_at(where, params, value)
