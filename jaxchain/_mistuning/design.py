"""Intentional mistuning by gradient: a periodic pattern of stiffness deviations,
within a budget, that lowers the belt speed above which no single-site localized
state survives (the highest of their folds), through implicit differentiation of
the folds' extended systems."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from .._bifurcation.continuation import ContinuationProblem
from .._bifurcation.fold import solve_fold
from .._bifurcation.limit_cycles import DescribeOrbit, ShootingResidual
from .._physics.initial import excited_block
from .._physics.params import ChainParams, with_parameter
from .edges import localized_fold


def pattern_deviations(theta: Float[Array, " period"], budget: float, n_osc: int,
                       zero_mean: bool = True) -> Float[Array, " n_osc"]:
    """delta_n = d_(n mod p) of the design variables theta (shape (p,)): d =
    budget tanh(theta), with zero_mean its mean removed and the whole scaled back
    into |d| <= budget (the chain keeps its nominal mean stiffness: mistuning, not
    retuning). Differentiable."""
    d = budget * jnp.tanh(theta)
    if zero_mean:
        d = d - jnp.mean(d)
        d = d * (budget / jnp.maximum(jnp.max(jnp.abs(d)), budget))
    return jnp.tile(d, n_osc // theta.size)


def _with_stiffness(params: ChainParams, delta) -> ChainParams:
    """`params` with stiffness 1 + delta (traceable: no re-validation)."""
    return eqx.tree_at(lambda p: p.stiffness, params, 1.0 + delta)


def _site_problem(problem: ContinuationProblem, fold_solution, shift: int, site: int):
    """The fold problem and solution of the single-site state moved by `shift`
    oscillators along the ring (a symmetry of the homogeneous ring), with the phase
    condition on its new site."""
    n = problem.params.n_osc
    u, p, w = (fold_solution[: 2 * n + 1], fold_solution[2 * n + 1],
               fold_solution[2 * n + 2:])

    def roll(z):
        return jnp.concatenate([jnp.roll(z[: 2 * n].reshape(2, n), shift, axis=1).ravel(),
                                z[2 * n:]])

    opts = dataclasses.replace(problem.residual.options, phase_oscillator=int(site))
    moved = ContinuationProblem(residual=ShootingResidual(opts), u0=roll(u),
                                params=problem.params, where=problem.where,
                                describe=DescribeOrbit(opts))
    return moved, jnp.concatenate([roll(u), p[None], roll(w)])


@eqx.filter_jit
def _fold_and_gradient(problem, start, theta, budget, zero_mean):
    """The fold belt speed at the pattern theta, and its gradient in theta
    (forward mode through optimistix's ImplicitAdjoint)."""
    n = problem.params.n_osc

    def fold(th):
        params = _with_stiffness(problem.params,
                                 pattern_deviations(th, budget, n, zero_mean))
        solution, ok = solve_fold(problem.with_params(params), start)
        return solution[2 * n + 1], (solution, ok)

    value, aux = fold(theta)
    grad = jax.jacfwd(lambda th: fold(th)[0])(theta)
    return value, grad, aux[0], aux[1]


class MistuningDesign(eqx.Module):
    """The answer of `intentional_mistuning`.

    **Fields:**

    - `deviations`: delta_n of the design, shape (n_osc,).
    - `pattern`: its period, shape (period,).
    - `folds`: the fold of the single-site state at each site of one period
        (ring sites `sites`), shape (period,); the chain's edge is their maximum.
    - `sites`: those oscillators (0-based), shape (period,).
    - `edge`: max(folds); `homogeneous_edge`: the same on the homogeneous ring.
    - `gradient`: d smooth-max / d theta at the design, shape (period,).
    - `history`: (smooth max, max fold) at each iteration, shape (iterations, 2).
    - `solutions`: the folds' extended-system solutions, shape (period, 2(2n+1)+1).
    """

    deviations: Float[Array, " n_osc"]
    pattern: Float[Array, " period"]
    folds: Float[Array, " period"]
    sites: np.ndarray = eqx.field(static=True)
    edge: float = eqx.field(static=True)
    homogeneous_edge: float = eqx.field(static=True)
    theta: Float[Array, " period"]
    gradient: Float[Array, " period"]
    history: Float[Array, "iterations 2"]
    solutions: Float[Array, "period m"]


def _smooth_max(values, temperature):
    return temperature * jax.nn.logsumexp(values / temperature)


def pattern_folds(problems, solutions, theta, budget, zero_mean):
    """The fold of each site's single-site state at the pattern theta, each from
    its previous solution, with their gradients in theta: (folds (p,), gradients
    (p, p), solutions, converged (p,))."""
    out = [_fold_and_gradient(pr, s, jnp.asarray(theta), budget, zero_mean)
           for pr, s in zip(problems, solutions)]
    return (np.array([float(o[0]) for o in out]), np.stack([np.asarray(o[1]) for o in out]),
            [o[2] for o in out], np.array([bool(o[3]) for o in out]))


def intentional_mistuning(params: ChainParams = ChainParams(), *, budget: float = 0.05,
                          period: int = 4, zero_mean: bool = True, steps: int = 12,
                          learning_rate: float = 0.3, temperature: float = 2e-3,
                          seed: int = 0, progress: bool = True):
    """A periodic stiffness mistuning delta_n = d_(n mod period), |d| <= `budget`,
    that lowers the highest fold of the single-site localized states (eq. (8),
    k = 1; the upper edge of the bistable range of the ring, README "The snake"):
    the belt speed above which no localized vibration survives.

    With period p the ring has p kinds of site; the fold of the state at each is
    located by Newton's method on its Moore-Spence extended system (`solve_fold`),
    continued from the previous iteration's, and differentiated in the design
    variables by implicit differentiation (optimistix's `ImplicitAdjoint`, forward
    mode: one linear solve per variable, never through Newton's iterations). The
    objective, a smooth maximum t log sum exp(fold_j / t) of the p folds, is
    minimised by optax's Adam over theta, d = budget tanh(theta)
    (`pattern_deviations`).

    **Arguments:**

    - `params`: a homogeneous ring (v_d is the belt speed of the starting orbit,
        1.5 is good for eq. (7)); n_osc a multiple of `period`.
    - `budget`: the largest |delta_n|, > 0; `zero_mean`: keep the mean stiffness.
    - `period`: p >= 2.
    - `steps`, `learning_rate`: Adam's iterations and step size in theta.
    - `temperature`: t of the smooth maximum (belt-speed units).
    - `seed`: the random start of theta (small, so that the symmetric start is
        left).
    - `progress`: print each iteration.

    **Returns:**

    A `MistuningDesign`; `pattern_folds` and `design_problems` evaluate other
    patterns the same way.

    **Raises:**

    `ValueError` for a chain that is not a homogeneous ring, n_osc not a multiple
    of `period`, or a bad budget or count; `RuntimeError` when a fold is lost
    (lower `learning_rate`).
    """
    problems, solutions, sites, homogeneous = design_problems(params, period, budget)
    key = np.random.default_rng(seed)
    theta = jnp.asarray(0.1 * key.standard_normal(period))
    opt = optax.adam(learning_rate)
    state = opt.init(theta)
    history = []
    for i in range(steps + 1):
        folds, grads, new, ok = pattern_folds(problems, solutions, theta, budget, zero_mean)
        if not ok.all():
            raise RuntimeError(f"the fold of a site was lost at iteration {i}: lower "
                               "learning_rate")
        solutions = new
        weights = np.asarray(jax.nn.softmax(jnp.asarray(folds) / temperature))
        value = float(_smooth_max(jnp.asarray(folds), temperature))
        gradient = weights @ grads
        history.append((value, float(folds.max())))
        if progress:
            print(f"design {i}: highest fold {folds.max():.5f}, folds "
                  f"{np.round(folds, 5).tolist()}", flush=True)
        if i == steps:
            break
        updates, state = opt.update(jnp.asarray(gradient), state, theta)
        theta = optax.apply_updates(theta, updates)
    deviations = pattern_deviations(theta, budget, params.n_osc, zero_mean)
    return MistuningDesign(deviations=deviations, pattern=deviations[:period],
                           folds=jnp.asarray(folds), sites=np.asarray(sites),
                           edge=float(folds.max()), homogeneous_edge=homogeneous,
                           theta=theta, gradient=jnp.asarray(gradient),
                           history=jnp.asarray(history), solutions=jnp.stack(solutions))


def design_problems(params: ChainParams, period: int, budget: float):
    """The fold problems of the p kinds of site of a pattern of period p, from the
    fold of the homogeneous ring's single-site state (`localized_fold`) moved along
    the ring: (problems, solutions, sites, the homogeneous fold)."""
    n = params.n_osc
    if params.boundary != "ring" or np.ndim(params.stiffness) or np.ndim(params.xi) \
            or np.ndim(params.load):
        raise ValueError("params: the design starts from a homogeneous ring")
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or period < 2 \
            or n % period:
        raise ValueError(f"period must be an integer >= 2 dividing n_osc = {n}, got "
                         f"{period!r}")
    if not (isinstance(budget, (int, float)) and 0 < budget < 1):
        raise ValueError(f"budget must lie in (0, 1), got {budget!r}")
    centre = int(np.flatnonzero(excited_block(n, 1, "ring"))[0])
    fold, problem = localized_fold(params, centre)
    if fold is None:
        raise RuntimeError("no fold of the single-site state was found from "
                           f"v_d = {float(params.v_d):g}")
    solution = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    sites = [(centre + j) % n for j in range(period)]
    moved = [_site_problem(problem, solution, s - centre, s) for s in sites]
    return [m[0] for m in moved], [m[1] for m in moved], sites, float(fold.p)
