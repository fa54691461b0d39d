"""The step-size controller of the simulations: a PI controller for the stick-slip
switches of the smoothed friction law."""

import diffrax
import jax.numpy as jnp
from jax import lax

from ..compat import error_order, pid_state, unpack_pid_state


class PIController(diffrax.PIDController):
    """diffrax's `PIDController` with two changes for the stick-slip switches of the
    smoothed model, where the error of a step does not fall as h^(p+1) until h is
    below the time scale of the kink of tanh(v_rel/eps).

    - **After an accepted step** the step may also shrink (by at most `factormin`),
        as in the PI controllers of Gustafsson (1991, BIT 31, 492-502) and Hairer &
        Wanner, "Solving ODEs II", Section IV.8. diffrax never shrinks after an
        accepted step, so an accepted step with an error just below 1 is followed by a
        rejected one.
    - **After a second rejection at the same t0** the next step is chosen with the
        order the error showed between the two attempts, q = log(err_1/err_2) /
        log(h_1/h_2), clipped to [`min_order`, the solver's error order], rather than
        the asymptotic order. At a switch q falls well below 3, and the asymptotic
        order shrinks the step by only 0.65-0.8 per attempt (`docs/benchmarks/steps.md`
        shows chains of six rejections).

    Accepted steps follow the PI rule h_new = h safety err_n^-(icoeff + pcoeff)/k
    err_{n-1}^(pcoeff/k), k the error order; the defaults pcoeff = 0.2, icoeff = 0.5
    were chosen on the work-precision diagram of the Fig. 4 scene
    (`benchmarks/candidates.py`). The state carries diffrax's PID state and the
    error and step size of the last rejected attempt (0 after an accepted step).
    The step-size factor is not differentiated (`lax.stop_gradient`), as in diffrax.
    The parts of diffrax's controller that are private (its state, its error order)
    are reached through `_compat`.

    At the default rtol 3e-5 it takes 10 % fewer steps than diffrax's controller on
    the Fig. 4 scene; at tight tolerances (rtol 1e-7 to 1e-10, a ring of 6) it
    takes 4-12 % more, as it shrinks after accepted steps that diffrax would keep.
    """

    pcoeff: float = 0.2
    icoeff: float = 0.5
    min_order: float = 0.5

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1, state = super().init(terms, t0, t1, y0, dt0, args, func, error_order)
        zero = jnp.zeros_like(unpack_pid_state(state)[0])
        return t1, (state, zero, zero)

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, solver_order,
                        controller_state):
        del args
        state, rejected_err, rejected_dt = controller_state
        prev_inv, prev_prev_inv, at_dtmin = unpack_pid_state(state)
        order = error_order(self, solver_order)
        dt = t1 - t0
        y1 = jnp.where(jnp.isnan(y1_candidate), y0, y1_candidate)
        scale = self.atol + self.rtol * jnp.maximum(jnp.abs(y0), jnp.abs(y1))
        err = self.norm(y_error / scale)
        err = jnp.where(jnp.isnan(err), jnp.inf, err)
        keep = err < 1
        inv = 1.0 / jnp.clip(err, 1e-10, 1e30)
        accepted = self.safety * inv ** ((self.icoeff + self.pcoeff) / order) \
            * prev_inv ** (-self.pcoeff / order)
        accepted = jnp.clip(accepted, self.factormin, self.factormax)
        observed = jnp.log(err / rejected_err) / jnp.log(dt / rejected_dt)
        q = jnp.where((rejected_err > 0) & jnp.isfinite(observed),
                      jnp.clip(observed, self.min_order, order), order)
        rejected = jnp.clip(self.safety * inv ** (1.0 / q), self.factormin, self.safety)
        factor = lax.stop_gradient(jnp.where(keep, accepted, rejected))
        next_t0 = jnp.where(keep, t1, t0)
        next_t1 = next_t0 + dt * factor
        if self.dtmax is not None:
            next_t1 = jnp.minimum(next_t1, next_t0 + self.dtmax)
        state = (pid_state(jnp.where(keep, lax.stop_gradient(jnp.minimum(inv, 1e10)), prev_inv),
                           jnp.where(keep, prev_inv, prev_prev_inv), at_dtmin),
                 jnp.where(keep, 0.0, err), jnp.where(keep, 0.0, dt))
        return keep, next_t0, next_t1, False, state, diffrax.RESULTS.successful


#: Step-size controllers by name (`SimulationOptions.controller`): the package's
#: `PIController`, and diffrax's `PIDController` as an integral controller (its
#: defaults; jaxchain's earlier controller).
CONTROLLERS = {"pi": PIController, "diffrax": diffrax.PIDController}


def step_size_controller(options) -> diffrax.AbstractStepSizeController:
    """The controller of `options` (`SimulationOptions`) at its rtol and atol."""
    return CONTROLLERS[options.controller](rtol=options.rtol, atol=options.atol)
