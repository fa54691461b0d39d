"""Pseudo-arclength continuation, in the manner of BifurcationKit.jl: a problem, an
algorithm, options, and the branch it returns."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._engine.compat import checks_as_nan
from .._engine.progress import tqdm
from .._physics.params import ChainParams, parameter_value, with_parameter
from .._errors import ValidationError
from .._engine.status import Status
from .._printing import values_repr


class ContinuationProblem(eqx.Module):
    """A family of equations G(u, p) = 0 to follow in one parameter p.

    **Fields:**

    - `residual`: G(u, params) -> shape (n,), for unknowns u of shape (n,). A
        module-level function or an `eqx.Module` with `__call__` compiles once for
        all problems of its kind; a new lambda compiles anew.
    - `u0`: a solution at `params`, shape (n,).
    - `params`: the parameters of `u0`.
    - `where`: the continued parameter: its name (`"v_d"`, the default) or a lens
        such as `lambda p: p.xi` (`with_parameter`).
    - `describe`: (u, params) -> a record of the point (an `eqx.Module` with a
        boolean field `stable`), for example `DescribeOrbit`; or None, for no
        records (every point then counts as stable).
    """

    residual: Callable
    u0: Float[Array, " n"]
    params: ChainParams
    where: Callable | str = eqx.field(static=True, default="v_d")
    describe: Callable | None = None

    def at(self, value) -> ChainParams:
        """`params` with the continued parameter set to `value` (`with_parameter`)."""
        return with_parameter(self.params, self.where, value)

    def with_params(self, params: ChainParams) -> "ContinuationProblem":
        """The same problem at other parameters."""
        return eqx.tree_at(lambda pr: pr.params, self, params)

    def value(self) -> Float[Array, ""]:
        """The continued parameter's value in `params`."""
        return parameter_value(self.params, self.where)

    def __call__(self, z: Float[Array, " n+1"]) -> Float[Array, " n"]:
        """G at z = (u, p)."""
        return self.residual(z[:-1], self.at(z[-1]))


class PseudoArclength(eqx.Module):
    """Keller's pseudo-arclength continuation (H. B. Keller, *Numerical solution of
    bifurcation and nonlinear eigenvalue problems* (1977)): predict along the
    tangent of the branch in (u, p), then correct with Newton's method (optimistix)
    on G(u, p) = 0 together with <t, z - z_predicted> = 0, which passes folds in p.

    **Arguments:**

    - `newton_tol`: Newton's tolerance (rtol = atol) on z = (u, p).
    - `newton_steps`: Newton's iteration budget per point.
    """

    newton_tol: float = eqx.field(static=True, default=1e-9)
    newton_steps: int = eqx.field(static=True, default=12)


class ContinuationOptions(eqx.Module):
    """Step sizes and bounds of a continuation.

    **Arguments:**

    - `ds`: first arclength step in (u, p).
    - `ds_min`, `ds_max`: bounds of the adapted step; the run stops when a failed
        step would go below `ds_min`.
    - `p_min`, `p_max`: the run stops when p leaves [p_min, p_max].
    - `max_points`: the most points (failed ones included).
    - `direction`: +1 or -1, the sign of dp/ds at the start.
    - `fast_steps`: a point corrected within this many Newton steps lets ds grow
        by 1.5 (to at most `ds_max`); a failed point halves it.
    - `max_correction`: a corrected point further than `max_correction * ds` from
        its prediction counts as failed: Newton's method jumped to another branch
        (the correction of a good step is O(ds^2)).

    **Raises:**

    `ValueError` naming the field for a bad value.
    """

    ds: float = 0.02
    ds_min: float = 1e-5
    ds_max: float = 0.2
    p_min: float = -np.inf
    p_max: float = np.inf
    max_points: int = 200
    direction: int = 1
    fast_steps: int = 4
    max_correction: float = 1.0

    def __check_init__(self):
        if not 0 < self.ds_min <= self.ds <= self.ds_max:
            raise ValidationError(f"ContinuationOptions needs 0 < ds_min <= ds <= ds_max, got "
                                  f"ds_min = {self.ds_min}, ds = {self.ds}, ds_max = {self.ds_max}")
        if not self.p_min < self.p_max:
            raise ValidationError(f"ContinuationOptions.p_min must be < p_max, got "
                                  f"{self.p_min} and {self.p_max}")
        if self.max_points < 1:
            raise ValidationError(f"ContinuationOptions.max_points must be >= 1, got "
                                  f"{self.max_points}")
        if not self.max_correction > 0:
            raise ValidationError(f"ContinuationOptions.max_correction must be > 0, got "
                                  f"{self.max_correction!r}")
        if self.direction not in (1, -1):
            raise ValidationError(f"ContinuationOptions.direction must be +1 or -1, got "
                                  f"{self.direction!r}")


class Branch(eqx.Module):
    """The result of a continuation.

    **Fields:**

    - `p`: the continued parameter at each point, shape (n_points,).
    - `u`: the unknowns, shape (n_points, n).
    - `tangent`: the unit tangent in (u, p), shape (n_points, n + 1).
    - `converged`: whether Newton's method converged, shape (n_points,). A failed
        point keeps its prediction; the run halves ds and goes on from the last good
        point.
    - `records`: `problem.describe` of every converged point, fields with a leading
        axis (n_converged,); None without `describe`.
    - `stable`: the records' stability, shape (n_converged,).
    - `folds`: indices into the converged points after which dp/ds changes sign.
    - `stability_changes`: indices into the converged points after which `stable`
        changes.
    - `branch_points`: indices into the converged points after which the sign of
        det [[G_u, G_p], [t^T]] changes (t the tangent, oriented along the branch):
        it changes at a simple branch point, where another branch crosses, and
        not at a fold (Allgower and Georg, *Numerical Continuation Methods* (1990),
        Sect. 8.1), whether or not the orbits' stability changes there.
    - `stop`: why the run ended, a `Status`: `max_points_reached`,
        `left_parameter_range` or `newton_failed`.
    """

    p: Float[Array, " n_points"]
    u: Float[Array, "n_points n"]
    tangent: Float[Array, "n_points n+1"]
    converged: Bool[Array, " n_points"]
    records: eqx.Module | None
    stable: Bool[Array, " n_converged"]
    folds: tuple[int, ...] = eqx.field(static=True)
    stability_changes: tuple[int, ...] = eqx.field(static=True)
    stop: Status = eqx.field(static=True)
    branch_points: tuple[int, ...] = eqx.field(static=True, default=())

    __repr__ = values_repr

    @property
    def tangent_p(self) -> Float[Array, " n_points"]:
        """dp/ds of the unit tangent; it changes sign at a fold."""
        return self.tangent[:, -1]


def _stacked(arrays) -> np.ndarray:
    """Arrays of one shape stacked on a new leading axis, in NumPy."""
    return np.stack([np.asarray(a) for a in arrays])


@checks_as_nan
@eqx.filter_jit
def _tangent(problem: ContinuationProblem, z, previous):
    """(Unit tangent of the branch at z: the null vector of [G_u, G_p], oriented
    along `previous`, from the bordered system [[G_u, G_p], [previous^T]] t = e;
    the sign of det [[G_u, G_p], [t^T]], which changes at a branch point)."""
    jac = jax.jacfwd(problem)(z)
    bordered = jnp.concatenate([jac, previous[None]], axis=0)
    rhs = jnp.zeros(z.size).at[-1].set(1.0)
    # throw=False: a singular system gives NaN either way, and lineax's check
    # (built at lowering) would be a host callback wherever this is compiled
    # outside checks_as_nan (inside a user's own jax.jit)
    t = lx.linear_solve(lx.MatrixLinearOperator(bordered), rhs, lx.LU(), throw=False).value
    t = t / jnp.linalg.norm(t)
    return t, jnp.linalg.slogdet(jnp.concatenate([jac, t[None]], axis=0))[0]


@checks_as_nan
@eqx.filter_jit
def _correct(problem: ContinuationProblem, algorithm: PseudoArclength, predicted, tangent):
    def equations(z, _):
        return jnp.concatenate([problem(z), jnp.atleast_1d(tangent @ (z - predicted))])

    sol = optx.root_find(equations, optx.Newton(rtol=algorithm.newton_tol,
                                                atol=algorithm.newton_tol),
                         predicted, max_steps=algorithm.newton_steps, throw=False)
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(sol.value))
    return sol.value, ok, sol.stats["num_steps"], jnp.linalg.norm(sol.value - predicted)


@checks_as_nan
@eqx.filter_jit
def describe_point(describe: Callable, u, params: ChainParams, p, where):
    """`describe(u, params with the parameter `where` set to p)`, compiled once for
    each describe module (its static options), shape of u, kind of params and
    `where`: the records of continuation and the results of shooting
    (`periodic_orbit`) share one program, the largest of a
    periodic orbit's (multipliers, samples). Every caller passes all five arguments,
    in this order: the program's key is the arguments as given, and a `where` left
    to a default would key a second copy of the same program."""
    return describe(u, with_parameter(params, where, p))


class _Stable(eqx.Module):
    stable: Bool[Array, ""]


def _record(problem: ContinuationProblem, z):
    if problem.describe is None:
        return _Stable(stable=jnp.asarray(True))
    return describe_point(problem.describe, z[:-1], problem.params, z[-1], problem.where)


def _first_point(problem: ContinuationProblem,
                 algorithm: PseudoArclength) -> Float[Array, " n+1"]:
    """The first point z = (u0, p) of a continuation, checked to be a solution
    (`continuation`'s `ValueError` otherwise)."""
    z = jnp.concatenate([jnp.asarray(problem.u0, dtype=float),
                         jnp.atleast_1d(jnp.asarray(problem.value(), dtype=float))])
    residual = float(jnp.max(jnp.abs(problem(z))))
    if not residual <= 1e3 * algorithm.newton_tol:
        raise ValueError(f"problem.u0 is not a solution at the given parameters (residual "
                         f"{residual:.3g}); solve for it first")
    return z


def _branch(problem: ContinuationProblem, zs: list, tangents: list, converged: list,
            records: list, signs: list, stop: Status) -> Branch:
    """The `Branch` of a continuation's points (each z = (u, p), failed ones
    included), their tangents, whether each converged, the records and the
    bordered determinants' signs of the converged ones, and why it stopped: the
    folds, changes of stability and branch points found between the converged
    points."""
    # Stacked on the host: on the device every operation would compile for each
    # number of points.
    zs, tangents = _stacked(zs), _stacked(tangents)
    ok = np.asarray(converged)
    records = jax.tree.map(lambda *xs: jnp.asarray(_stacked(xs)), *records)
    stable = np.asarray(records.stable)
    tp = tangents[ok, -1]
    signs = np.asarray(_stacked(signs))
    return Branch(
        p=jnp.asarray(zs[:, -1]), u=jnp.asarray(zs[:, :-1]), tangent=jnp.asarray(tangents),
        converged=jnp.asarray(ok),
        records=records if problem.describe is not None else None,
        stable=jnp.asarray(stable),
        folds=tuple(int(i) for i in np.nonzero(np.sign(tp[1:]) != np.sign(tp[:-1]))[0]),
        stability_changes=tuple(int(i) for i in np.nonzero(stable[1:] != stable[:-1])[0]),
        stop=stop,
        branch_points=tuple(int(i) for i in np.nonzero(signs[1:] * signs[:-1] < 0)[0]))


def continuation(problem: ContinuationProblem, algorithm: PseudoArclength = PseudoArclength(),
                 options: ContinuationOptions = ContinuationOptions(), *,
                 tangent: Float[Array, " n+1"] | None = None,
                 progress: bool = False) -> Branch:
    """Follow the branch of solutions of `problem` from `problem.u0` by
    pseudo-arclength continuation (`PseudoArclength`), detecting folds (dp/ds
    changes sign) and changes of stability (`problem.describe(...).stable`).

    Points where Newton's method fails, or where its correction exceeds
    `options.max_correction * ds` (a jump to another branch), are recorded as
    failed, with their prediction, and the step is halved; what was found is kept.

    **Arguments:**

    - `problem`: a `ContinuationProblem`.
    - `algorithm`: `PseudoArclength`.
    - `options`: `ContinuationOptions`.
    - `tangent`: the direction in (u, p) to start along, shape (n + 1,) (a switched
        branch's, `switch_branch`); by default along p, signed by
        `options.direction`.
    - `progress`: show a tqdm bar, one tick per point.

    **Returns:**

    A `Branch`.

    **Raises:**

    `ValueError` (a computed condition, not a `ValidationError`) if `problem.u0` is
    not a solution (residual above 1e3 x the Newton tolerance).
    """
    z = _first_point(problem, algorithm)
    start = (jnp.zeros(z.size).at[-1].set(float(options.direction)) if tangent is None
             else jnp.asarray(tangent, dtype=float))
    tangent, sign = _tangent(problem, z, start)
    zs, tangents, converged, records = [z], [tangent], [True], [_record(problem, z)]
    signs = [sign]
    ds, stop = options.ds, Status.max_points_reached
    bar = tqdm(total=options.max_points, desc="continuation", unit="point",
               disable=not progress, leave=False)
    for _ in range(options.max_points - 1):
        bar.update()
        predicted = z + ds * tangent
        new, ok, steps, correction = _correct(problem, algorithm, predicted, tangent)
        if not (bool(ok) and float(correction) <= options.max_correction * ds):
            zs.append(predicted)
            tangents.append(tangent)
            converged.append(False)
            ds /= 2
            if ds < options.ds_min:
                stop = Status.newton_failed
                break
            continue
        (z, (tangent, sign)) = new, _tangent(problem, new, tangent)
        signs.append(sign)
        zs.append(z)
        tangents.append(tangent)
        converged.append(True)
        records.append(_record(problem, z))
        if int(steps) <= options.fast_steps:
            ds = min(1.5 * ds, options.ds_max)
        if not options.p_min <= float(z[-1]) <= options.p_max:
            stop = Status.left_parameter_range
            break
    bar.close()
    return _branch(problem, zs, tangents, converged, records, signs, stop)
