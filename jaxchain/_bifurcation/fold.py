"""Folds (saddle-nodes) located precisely, by the standard extended system."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._engine.compat import checks_as_nan
from .._physics.params import ChainParams
from .continuation import Branch, ContinuationProblem, describe_point
from .implicit import implicit_root
from .._printing import values_repr


class FoldPoint(eqx.Module):
    """A fold of a branch of `ContinuationProblem`.

    **Fields:**

    - `p`: the parameter at the fold (for limit cycles: the fold's belt speed).
    - `u`: the solution there, shape (n,).
    - `null_vector`: w with G_u w = 0, |w| = 1, shape (n,).
    - `record`: `problem.describe` at the fold (for limit cycles a
        `PeriodicOrbit`, whose critical Floquet multiplier is +1).
    - `converged`: whether Newton's method converged.
    """

    p: Float[Array, ""]
    u: Float[Array, " n"]
    null_vector: Float[Array, " n"]
    record: eqx.Module
    converged: Bool[Array, ""]

    __repr__ = values_repr


def _extended(unknowns, problem: ContinuationProblem):
    """Moore-Spence system: G(u, p) = 0, G_u(u, p) w = 0, <w, w> = 1 (unknowns
    (u, p, w))."""
    n = problem.u0.size
    z, w = unknowns[: n + 1], unknowns[n + 1:]
    g, gw = jax.jvp(lambda u: problem(jnp.concatenate([u, z[-1:]])), (z[:-1],), (w,))
    return jnp.concatenate([g, gw, jnp.atleast_1d(w @ w - 1)])


class FoldSystem(eqx.Module):
    """The extended system of the folds of `problem`, as a residual of unknowns
    (u, p, w) and parameters: a `ContinuationProblem` whose residual is a
    `FoldSystem` follows the fold in a second parameter (`fold_curve`)."""

    problem: ContinuationProblem

    def __call__(self, unknowns, params: ChainParams):
        return _extended(unknowns, self.problem.with_params(params))


def _null_vector(problem: ContinuationProblem, z):
    """The right singular vector of G_u for the smallest singular value."""
    jac = jax.jacfwd(lambda u: problem(jnp.concatenate([u, z[-1:]])))(z[:-1])
    return jnp.linalg.svd(jac)[2][-1]


def _fold_start(problem: ContinuationProblem, z: Float[Array, " n+1"]) -> Float[Array, " 2n+1"]:
    """Starting unknowns (u, p, w) of `solve_fold` from a point z = (u, p) near the
    fold: w is the right singular vector of G_u for its smallest singular value."""
    return jnp.concatenate([z, _null_vector(problem, z)])


class _Newton(eqx.Module):
    """Newton's method (optimistix) on a fold's extended system, as
    `implicit_root` takes it: (root, converged)."""

    tol: float
    max_steps: int

    def __call__(self, fn, start, args):
        sol = optx.root_find(fn, optx.Newton(rtol=self.tol, atol=self.tol), start, args,
                             max_steps=self.max_steps, throw=False)
        return sol.value, (sol.result == optx.RESULTS.successful) & jnp.all(
            jnp.isfinite(sol.value))


@checks_as_nan
@eqx.filter_jit
def solve_fold(problem: ContinuationProblem, start: Float[Array, " 2n+1"],
               tol: float = 1e-9, max_steps: int = 30):
    """Newton's method on the extended system from `start` = (u, p, w); returns
    the solution (u, p, w) and whether it converged. Traceable and differentiable
    in `problem.params` (and the problem's eps), in forward and reverse mode
    (`jax.jvp`, `jax.grad`), by the implicit function theorem on the extended
    system (`implicit_root`: one linear solve with its Jacobian, not a derivative
    through Newton's iterations); NaN derivatives where Newton's method failed."""
    return implicit_root(_extended, _Newton(tol, max_steps), start, problem)


def fold_point(problem: ContinuationProblem, near: Branch | Float[Array, " n+1"], *,
               tol: float = 1e-9, throw: bool = True) -> FoldPoint:
    """Locate a fold of the branch of `problem` precisely: Newton's method
    (optimistix) on the standard extended (Moore-Spence) system

        G(u, p) = 0,   G_u(u, p) w = 0,   <w, w> = 1

    (Moore & Spence, SIAM J. Numer. Anal. 17 (1980) 567; Kuznetsov, *Elements of
    Applied Bifurcation Theory*, Sect. 10.2), whose G_u w is a forward-mode
    derivative and whose Jacobian takes second derivatives by JAX. For limit
    cycles G is the method's residual (`Shooting.residual`) and G_u is singular where a Floquet multiplier
    crosses +1: the fold (saddle-node) of limit cycles.

    **Arguments:**

    - `problem`: the `ContinuationProblem` of the branch.
    - `near`: a `Branch` with a detected fold (its first fold is refined), or a
        point z = (u, p) near the fold, shape (n + 1,).
    - `tol`: Newton's tolerance.
    - `throw`: raise if Newton's method fails (default).

    **Returns:**

    A `FoldPoint`.

    **Raises:**

    `ValueError` (a computed condition, not a `ValidationError`) if `near` is a
    branch without a fold; `RuntimeError` if Newton's method fails and `throw=True`.
    """
    if isinstance(near, Branch):
        if not near.folds:
            raise ValueError("the branch has no fold: continue it further (raise "
                             "max_points, p_max or p_min)")
        i = np.flatnonzero(np.asarray(near.converged))[near.folds[0]]
        z = jnp.asarray(np.append(np.asarray(near.u)[i], np.asarray(near.p)[i]))
    else:
        z = jnp.asarray(near, dtype=float)
    solution, ok = solve_fold(problem, _fold_start(problem, z), tol)
    n = problem.u0.size
    u, p, w = solution[:n], solution[n], solution[n + 1:]
    if throw and not bool(ok):
        raise RuntimeError("the fold's extended system did not converge: start nearer "
                           "the fold (a smaller continuation step)")
    record = describe_point(problem.describe, u, problem.params, p, problem.where)
    return FoldPoint(p=p, u=u, null_vector=w, record=record, converged=ok)
