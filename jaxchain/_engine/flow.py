"""The smoothed engine's flow map over a given time, with its sensitivities: what
shooting integrates (`Smoothed.flow`), and, beside the states over one period, the
integral of the Jacobian's trace that gives the monodromy's determinant by
Liouville's formula (`Smoothed.orbit_samples`)."""

import diffrax
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .compat import errors_as_nan
from .smoothed import terms
from .._physics.custom_types import State
from .._physics.model import Model, model_field, vector_field


def smoothed_flow(model: Model, solver: diffrax.AbstractSolver,
                  controller: diffrax.AbstractStepSizeController, max_steps: int,
                  y0: State, t1, saveat: diffrax.SaveAt) -> Array:
    """eq. (5) smoothed as `model` says, from `y0` at t = 0 over [0, t1], saved as
    `saveat`, by `solver` under the step-size `controller`;
    forward-mode differentiable (`diffrax.ForwardMode`), NaN where the solve
    failed (no host callback: `errors_as_nan`)."""
    with errors_as_nan():  # diffrax's checks of its arguments: no host callback
        sol = diffrax.diffeqsolve(
            terms(solver), solver, 0.0, t1, None, y0, model, saveat=saveat,
            max_steps=max_steps, adjoint=diffrax.ForwardMode(),
            stepsize_controller=controller, throw=False)
    return jnp.where(sol.result == diffrax.RESULTS.successful, sol.ys, jnp.nan)


def jacobian_trace(model: Model, y: State) -> Float[Array, ""]:
    """The trace of the Jacobian of eq. (5), smoothed as `model` says, at the state
    `y` (shape (2, n_osc)): the sum over the oscillators of d x_n'' / d x_n'. The
    positions' rows add nothing (x' = v), and each acceleration depends on its own
    velocity only (damping and friction act on each oscillator, the coupling on
    positions), so the velocity block is diagonal and its diagonal is one
    Jacobian-vector product along all-ones velocities:
    sum_n (-2 xi_n + dF_n/dv_n) / m_n."""
    x, v = y[0], y[1]

    def acceleration(v):
        return vector_field(0.0, jnp.stack([x, v]), model.params, model.eps)[1]

    _, diagonal = jax.jvp(acceleration, (v,), (jnp.ones_like(v),))
    return jnp.sum(diagonal)


def _liouville_field(t, z, model: Model):
    """Eq. (5) and, beside it, the trace of its Jacobian (`jacobian_trace`), whose
    integral over a period is the logarithm of the monodromy's determinant."""
    y, _ = z
    return model_field(t, y, model), jacobian_trace(model, y)


def smoothed_orbit_samples(model: Model, solver: diffrax.AbstractSolver,
                           controller: diffrax.AbstractStepSizeController, max_steps: int, y0: State, period, n_samples: int
                           ) -> tuple[Float[Array, "m 2 n"], Float[Array, ""]]:
    """`n_samples` states over [0, period] (both ends included) from `y0`, and the
    integral of the Jacobian's trace over the period (`jacobian_trace`; the
    logarithm of det M by Liouville's formula), integrated alongside as one more
    state under the same controller. The Jacobian's trace is that of eq. (5) itself, so
    the sum runs on `model_field` whatever `solver`'s terms."""
    ts = period * jnp.linspace(0.0, 1.0, n_samples)
    with errors_as_nan():  # as `smoothed_flow`
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(_liouville_field), solver, 0.0, period, None,
            (y0, jnp.zeros(())), model, saveat=diffrax.SaveAt(ts=ts),
            max_steps=max_steps, adjoint=diffrax.ForwardMode(),
            stepsize_controller=controller, throw=False)
    ys, log_det = sol.ys
    return ys, log_det[-1]
