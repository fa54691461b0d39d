"""Design with gradients: the smallest damping ratio whose bistable window of belt
speeds is narrower than a target width, by optax."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from .._physics.params import with_parameter
from .._engine.engines import AbstractEngine
from .continuation import ContinuationProblem
from .periodic_orbit import cycle_method
from .two_parameter import fold_curve, hopf_vd_and_derivative
from .._checks import check_positive
from .._printing import values_repr


class DampingDesign(eqx.Module):
    """The answer of `smallest_damping`.

    **Fields:**

    - `xi`: the damping ratio at which the window reaches the target width.
    - `window`: fold minus Hopf belt speed there.
    - `hopf_vd`, `fold_vd`: the window's edges there.
    - `d_window`: d window / d xi there (implicit differentiation).
    - `history`: (xi, window) at each optax iteration, shape (n_iterations, 2).
    - `converged`: whether |window - target| fell below the tolerance.
    """

    xi: float
    window: float
    hopf_vd: float
    fold_vd: float
    d_window: float
    history: Float[Array, "n_iterations 2"]
    converged: bool

    __repr__ = values_repr


def smallest_damping(problem: ContinuationProblem, fold_solution: Float[Array, " 2n+1"],
                     target: float, *, learning_rate: float = 1.0, steps: int = 60,
                     tol: float = 1e-8, engine: AbstractEngine | None = None
                     ) -> DampingDesign:
    """The smallest damping ratio xi at which the bistable window of belt speeds,
    fold_vd(xi) - hopf_vd(xi), is narrower than `target`.

    The window narrows monotonically as xi grows (`boundary_curves`: d window / d xi
    < 0), so the answer is the xi at which it equals the target. It is found by
    minimising 1/2 (window(xi) - target)^2 over log xi with optax's L-BFGS, the
    gradient coming from implicit differentiation of the Hopf point and of the
    fold's extended system (optimistix's `ImplicitAdjoint`), each fold continued
    from the previous one (`fold_curve`).

    **Arguments:**

    - `problem`: the limit cycles' `ContinuationProblem`, at the parameters of
        `fold_solution`.
    - `fold_solution`: a solution (u, p, w) of the fold's extended system there.
    - `target`: the window width, > 0.
    - `learning_rate`, `steps`: optax L-BFGS's step scale and iteration budget.
    - `tol`: tolerance on |window - target|.
    - `engine`: the engine whose model's Hopf point it is (`hopf_point`); None
        (the default) takes the problem's limit cycles' (its method's engine,
        `AbstractEngine.as_smoothed`).

    **Returns:**

    A `DampingDesign`.

    **Raises:**

    `ValidationError` if target <= 0, or `engine` is None for a problem that does
    not smooth;
    `RuntimeError` if a fold along the way is lost or the Hopf point is not found.
    """
    check_positive("target", target)
    engine = (cycle_method(problem).engine.as_smoothed("smallest_damping") if engine is None
              else engine)
    n = problem.u0.size
    state = {"problem": problem, "solution": fold_solution}

    def evaluate(xi):
        solutions, derivatives, ok, _ = fold_curve(state["problem"], state["solution"], "xi",
                                                   [xi])
        if not ok[0]:
            raise RuntimeError(f"the fold was lost at xi = {xi:.6g}: lower learning_rate "
                               "or the target")
        solution, derivative = jnp.asarray(solutions[0]), derivatives[0]
        state.update(solution=solution,
                     problem=problem.with_params(with_parameter(problem.params, "xi", xi)))
        hopf, d_hopf = hopf_vd_and_derivative(problem.params, "xi", xi, engine=engine)
        if not bool(jnp.isfinite(hopf)):
            raise RuntimeError(f"Newton's method did not find the Hopf point at xi = {xi:.6g}")
        return float(solution[n] - hopf), float(derivative[n] - d_hopf), float(hopf)

    optimiser = optax.lbfgs(learning_rate=learning_rate, linesearch=None)
    theta = jnp.log(jnp.asarray(problem.params.xi))
    opt_state = optimiser.init(theta)
    history, converged = [], False
    for _ in range(steps):
        xi = float(jnp.exp(theta))
        window, d_window, hopf = evaluate(xi)
        history.append((xi, window))
        if abs(window - target) < tol:
            converged = True
            break
        grad = jnp.asarray((window - target) * d_window * xi)
        updates, opt_state = optimiser.update(grad, opt_state, theta)
        theta = optax.apply_updates(theta, updates)
    return DampingDesign(xi=xi, window=window, hopf_vd=hopf, fold_vd=hopf + window,
                         d_window=d_window, history=jnp.asarray(np.array(history)),
                         converged=converged)
