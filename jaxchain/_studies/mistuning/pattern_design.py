"""Intentional mistuning by gradient: a periodic pattern of stiffness deviations,
within a budget, that lowers the belt speed above which no single-site localized
state survives (the highest of their folds), through implicit differentiation of
the folds' extended systems."""

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from ..._engine.compat import checks_as_nan
from ..._bifurcation.fold import solve_fold
from ..._bifurcation.periodic_orbit import cycle_method
from ..._engine.engines import AbstractEngine, Smoothed
from ..._physics.initial import excited_block
from ..._physics.params import chain_or_default, ChainParams
from .edges import localized_fold
from ..._checks import check_count, check_positive
from ..._errors import ValidationError


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


def _solve_at(problem, start, theta, shift, budget, zero_mean):
    """The fold of the state at the problem's site on the ring mistuned by the
    pattern theta rolled by `shift` oscillators: by the ring's symmetry, the fold
    of the state `shift` sites before it on the unrolled pattern."""
    n = problem.params.n_osc
    delta = jnp.roll(pattern_deviations(theta, budget, n, zero_mean), shift)
    return solve_fold(problem.with_params(_with_stiffness(problem.params, delta)), start)


@checks_as_nan
@eqx.filter_jit
def _solve(problem, start, theta, shift, budget, zero_mean):
    """Newton's method on the fold's extended system at the pattern theta."""
    return _solve_at(problem, start, theta, shift, budget, zero_mean)


@checks_as_nan
@eqx.filter_jit
def _tangent(problem, solution, theta, shift, step, budget, zero_mean):
    """d solution / d theta along `step` (forward mode through optimistix's
    ImplicitAdjoint): the predictor of `_track_fold`."""
    return jax.jvp(lambda th: _solve_at(problem, solution, th, shift, budget, zero_mean)[0],
                   (theta,), (step,))[1]


@checks_as_nan
@eqx.filter_jit
def _gradient(problem, solution, theta, shift, budget, zero_mean):
    """d fold / d theta, shape (period,): one forward-mode pass per variable
    through the implicit function (optimistix's ImplicitAdjoint)."""
    n = problem.params.n_osc
    return jax.jacfwd(lambda th: _solve_at(problem, solution, th, shift, budget,
                                           zero_mean)[0][2 * n + 1])(theta)


def _track_fold(problem, solution, theta_from, theta_to, shift, budget: float,
                zero_mean: bool, *, min_step: float = 2.0**-14, max_jump: float = 2e-3):
    """Follow a fold's extended-system solution from the pattern `theta_from` to
    `theta_to` along the straight path: a tangent predictor (`_tangent`) and
    Newton's corrector, the step halved where Newton's method fails and doubled
    after a success. The fold of a stick-slip orbit is a smoothed grazing of the
    stick phase (its non-smooth limit is the existence limit of stick-slip), so
    Newton's method converges only within about eps of it. A corrected fold
    further than `max_jump` in v_d from its prediction has jumped to another fold
    and counts as a failure.

    **Returns:**

    (solution at `theta_to`, whether it was reached).
    """
    theta_from, theta_to = jnp.asarray(theta_from, float), jnp.asarray(theta_to, float)
    p_index = 2 * problem.params.n_osc + 1
    s, h = 0.0, 1.0
    while s < 1.0:
        h = min(h, 1.0 - s)
        here = theta_from + s * (theta_to - theta_from)
        step = (theta_to - theta_from) * h
        try:
            guess = solution + _tangent(problem, solution, here, shift, step, budget,
                                        zero_mean)
            new, ok = _solve(problem, guess, here + step, shift, budget, zero_mean)
            # a corrector that lands far from its prediction jumped to another fold
            ok = bool(ok) and abs(float(new[p_index] - guess[p_index])) < max_jump
        except eqx.EquinoxRuntimeError:  # a singular extended system: shorter steps
            ok = False
        if ok:
            solution, s, h = new, s + h, 2.0 * h
        else:
            h *= 0.5
            if h < min_step:
                return solution, False
    return solution, True


class MistuningDesign(eqx.Module):
    """The answer of `intentional_mistuning`.

    **Fields:**

    - `pattern`: the deviations d of one period, shape (period,); delta_n =
        d_(n mod period).
    - `folds`: the fold of the single-site state at each site of one period,
        shape (period,); the edge is their maximum.
    - `edge`: max(folds); `homogeneous_edge`: the same on the homogeneous ring.
    - `theta`: the design variables; `gradient`: d objective / d theta there.
    - `history`: (smooth maximum, highest fold) at each iteration, shape
        (iterations, 2).
    - `solutions`: the folds' extended-system solutions, shape (period, m).
    - `sense`: "lower" or "raise".
    """

    pattern: Float[Array, " period"]
    folds: Float[Array, " period"]
    edge: float = eqx.field(static=True)
    homogeneous_edge: float = eqx.field(static=True)
    theta: Float[Array, " period"]
    gradient: Float[Array, " period"]
    history: Float[Array, "iterations 2"]
    solutions: Float[Array, "period m"]
    sense: str = eqx.field(static=True)


def pattern_folds(problem, solutions, theta_from, theta_to, budget, zero_mean):
    """The fold of the single-site state at each oscillator j of the ring at the
    pattern `theta_to`, followed from its solution at `theta_from` (`_track_fold`;
    the state at j is the problem's state at its site c on the pattern rolled by
    c - j), and their gradients in theta: (folds (n,), gradients (n, n),
    solutions, reached (n,))."""
    n = problem.params.n_osc
    centre = int(cycle_method(problem).phase_oscillator)
    folds, grads, sols, ok = [], [], [], []
    for j, solution in enumerate(solutions):
        shift = jnp.asarray(centre - j)
        sol, reached = _track_fold(problem, solution, theta_from, theta_to, shift, budget,
                                   zero_mean)
        sols.append(sol)
        ok.append(reached)
        folds.append(float(sol[2 * n + 1]))
        try:
            grads.append(np.asarray(_gradient(problem, sol, jnp.asarray(theta_to, float),
                                              shift, budget, zero_mean)))
        except eqx.EquinoxRuntimeError:  # the fold is degenerate there
            grads.append(np.full(len(theta_to), np.nan))
            ok[-1] = False
    return np.array(folds), np.stack(grads), sols, np.array(ok)


def intentional_mistuning(params: ChainParams | None = None, *, budget: float = 0.05,
                          sense: str = "lower", zero_mean: bool = True, steps: int = 15,
                          learning_rate: float = 0.2, temperature: float = 2e-3,
                          seed: int = 0, start=None, engine: AbstractEngine = Smoothed(),
                          progress: bool = True) -> MistuningDesign:
    """A stiffness mistuning pattern of period n_osc, |delta_n| <= `budget`, that
    lowers (or raises) the highest fold of the single-site localized states
    (eq. (8), k = 1): the upper edge of the bistable range of the ring (documentation,
    "The snake"), the belt speed above which no localized vibration survives.
    Tiled along a longer ring (`pattern_deviations`) it mistunes that ring.

    The fold of the state at each site is located by Newton's method on its
    Moore-Spence extended system (`solve_fold`), followed from the previous
    pattern, and differentiated in the design variables by implicit differentiation
    (optimistix's `ImplicitAdjoint`, forward mode: never through Newton's
    iterations). The objective, the smooth maximum t log sum
    exp(fold_j / t) of the folds, is minimised (maximised to raise) by optax's Adam
    over theta, d = budget tanh(theta), with the mean removed (`zero_mean`); the
    best iterate is returned.

    **Arguments:**

    - `params`: a homogeneous ring, one period of the pattern (v_d: the belt speed
        of the starting orbit, 1.5 for eq. (7)).
    - `budget`: the largest |delta_n|, in (0, 1).
    - `sense`: "lower" (a quieter chain) or "raise".
    - `zero_mean`: keep the mean stiffness (mistuning, not retuning).
    - `steps`, `learning_rate`: Adam's iterations and step size in theta.
    - `temperature`: t of the smooth maximum (belt-speed units).
    - `seed`: the small random start of theta, off the symmetric point.
    - `start`: the output of `design_problems(params, budget)`, to reuse it (its
        problem carries its own engine).
    - `engine`: the engine of the folds' orbits (`Smoothed()` by default: eq. (5)
        smoothed at eps = 1e-3). Used where `start` is None (`design_problems`).
    - `progress`: print each iteration.

    **Returns:**

    A `MistuningDesign`.

    **Raises:**

    `ValidationError` for a chain that is not a homogeneous ring of at least 2, a bad
    budget or sense, a negative or non-integer `steps` or `seed`, a `learning_rate`
    or `temperature` that is not > 0; `RuntimeError` when a fold cannot
    be followed.
    """
    params, sign = _check_design(params, sense, steps, learning_rate, temperature, seed)
    best, history, homogeneous = _run_design(params, start, sign, budget, zero_mean, steps,
                                             learning_rate, temperature, seed, engine, progress)
    return _design(best, history, homogeneous, budget, zero_mean, sense)


def _check_design(params: ChainParams | None, sense: str, steps, learning_rate,
                  temperature, seed) -> tuple[ChainParams, float]:
    """The chain (a ring of 4 by default) and the sign of the objective of `sense`
    (+1 to lower, -1 to raise), with Adam's settings checked; the ring and the
    budget are checked by `design_problems`."""
    params = chain_or_default(params, n_osc=4)
    if sense not in ("lower", "raise"):
        raise ValidationError(f"sense must be 'lower' or 'raise', got {sense!r}")
    check_count("steps", steps, least=0)
    check_count("seed", seed, least=0)
    check_positive("learning_rate", learning_rate)
    check_positive("temperature", temperature)
    return params, 1.0 if sense == "lower" else -1.0


def _run_design(params: ChainParams, start, sign: float, budget, zero_mean, steps,
                learning_rate, temperature, seed, engine, progress) -> tuple[tuple, list, float]:
    """The fold problems (`start`, or `design_problems`), then Adam's iterations of
    `intentional_mistuning` from a small random theta: the folds followed to each new
    pattern (`pattern_folds`), a step they cannot follow halved. Returns the best
    iterate (objective, theta, folds, solutions, gradient), the history of (smooth
    maximum, highest fold) and the homogeneous ring's fold.

    **Raises:** `RuntimeError` when the folds cannot be followed."""
    problem, solutions, homogeneous = start or design_problems(params, budget, engine=engine)
    period = params.n_osc
    theta = jnp.asarray(0.05 * np.random.default_rng(seed).standard_normal(period))
    folds, grads, solutions, ok = pattern_folds(problem, solutions, jnp.zeros(period), theta,
                                                budget, zero_mean)
    if not ok.all():
        raise RuntimeError("the folds could not be followed to the starting pattern")
    opt = optax.adam(learning_rate)
    state = opt.init(theta)
    history, best = [], None
    for i in range(steps + 1):
        weights = np.asarray(jax.nn.softmax(jnp.asarray(folds) / temperature))
        smooth_max = float(temperature * jax.nn.logsumexp(jnp.asarray(folds) / temperature))
        objective, gradient = sign * smooth_max, sign * (weights @ grads)
        history.append((smooth_max, float(folds.max())))
        if best is None or objective < best[0]:
            best = (objective, theta, folds, solutions, gradient)
        if progress:
            pattern = np.asarray(pattern_deviations(theta, budget, period, zero_mean))
            print(f"design {i}: highest fold {folds.max():.6f}, pattern "
                  f"{np.round(pattern, 4).tolist()}", file=sys.stderr, flush=True)
        if i == steps:
            break
        updates, new_state = opt.update(jnp.asarray(gradient), state, theta)
        for _ in range(6):  # a step the folds cannot follow is halved
            target = optax.apply_updates(theta, updates)
            out = pattern_folds(problem, solutions, theta, target, budget, zero_mean)
            if out[3].all():
                break
            updates = jax.tree_util.tree_map(lambda u: 0.5 * u, updates)
        else:
            raise RuntimeError(f"the folds could not be followed at iteration {i}: lower "
                               "learning_rate")
        theta, state = target, new_state
        folds, grads, solutions, _ = out
    return best, history, homogeneous


def _design(best: tuple, history: list, homogeneous: float, budget, zero_mean,
            sense: str) -> MistuningDesign:
    """The `MistuningDesign` of the best iterate (not the last)."""
    _, theta, folds, solutions, gradient = best
    return MistuningDesign(pattern=pattern_deviations(theta, budget, theta.size, zero_mean),
                           folds=jnp.asarray(folds), edge=float(folds.max()),
                           homogeneous_edge=homogeneous, theta=theta,
                           gradient=jnp.asarray(gradient), history=jnp.asarray(history),
                           solutions=jnp.stack(solutions), sense=sense)


def design_problems(params: ChainParams, budget: float, *,
                    engine: AbstractEngine = Smoothed()):
    """The fold problem of the single-site state at the ring's centre oscillator
    (`localized_fold`, of `engine`'s model: `Smoothed()` by default), and a
    starting solution for the state at each
    oscillator (on the homogeneous ring they are one state): (problem, solutions,
    the homogeneous fold).

    **Raises:**

    `ValidationError` for a chain that is not a homogeneous ring of at least 2, a
    budget outside (0, 1); `RuntimeError` when no fold is found.
    """
    n = params.n_osc
    if params.boundary != "ring" or n < 2 or np.ndim(params.stiffness) \
            or np.ndim(params.xi) or np.ndim(params.load):
        raise ValidationError("params: the design starts from a homogeneous ring of at least "
                              "2 oscillators")
    if not (isinstance(budget, (int, float)) and 0 < budget < 1):
        raise ValidationError(f"budget must lie in (0, 1), got {budget!r}")
    centre = int(np.flatnonzero(excited_block(n, 1, "ring"))[0])
    # (`localized_orbit` gives the ring one stiffness per oscillator, as the patterns
    # give it: the fold's programs are those of every mistuned ring of its size)
    fold, problem = localized_fold(params, centre, engine=engine)
    if fold is None:
        raise RuntimeError("no fold of the single-site state was found from "
                           f"v_d = {float(params.v_d):g}")
    solution = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    return problem, [solution] * n, float(fold.p)
