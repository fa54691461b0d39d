"""The existence limit of the single oscillator's stick-slip cycle in the non-smooth
model: the belt speed at which the slip arc that leaves stick just grazes v_rel = 0."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._engine.compat import checks_as_nan, errors_as_nan
from .._physics.forces import friction_coefficient, static_friction
from .._physics.model import stick_force
from .._physics.params import chain_or_default, ChainParams, with_parameter
from .._errors import ValidationError


def stick_exit_state(params: ChainParams):
    """Where the single oscillator leaves stick: x' = v_d and the force needed to
    stick, k x + 2 xi v_d, at the static friction (eq. (2)), shape (2, 1)."""
    exit_x = (static_friction(params) - 2 * params.xi * params.v_d) / params.stiffness
    return jnp.stack([jnp.atleast_1d(exit_x), jnp.atleast_1d(params.v_d)])


def _slip_arc_peak(v_d, args):
    """max (x' - v_d) on the slip arc that leaves stick, before it would cross the
    belt speed: positive where the arc returns to stick, zero at grazing. `args` is
    (params, rtol)."""
    params, rtol = args
    p = with_parameter(params, "v_d", v_d)
    exit_state = stick_exit_state(p)

    def field(t, y, p):
        """Slip behind the belt, F = +(P_n/P) mu(|v_rel|), continued past v_rel = 0 as
        the same physical law (the arc's peak is a smooth function of v_d on both
        sides of the limit); not the exact engine's slip mode, whose law is
        continued analytically past its switch (`of_slip_speed`)."""
        x, v = y
        a = (-stick_force(p, x) - 2 * p.xi * (v - p.v_d)
             + p.load * friction_coefficient(p, v - p.v_d))
        return jnp.stack([v, a / (1.0 if p.mass is None else p.mass)])

    def acceleration(t, y, args, **kwargs):
        # -1 over the first EXIT_GUARD time units: x'' is 0 at the exit and falls (its
        # rate is -k v_d there), but rounding may start it at +1e-17, a down-crossing
        # that would end the arc at once with a peak of 0 (seen under SSE4.2 code at
        # mu_st/mu_d = 1.8)
        return jnp.where(t < EXIT_GUARD, -1.0, field(t, y, args)[1, 0])

    # The first down-crossing of x'' is the first maximum of x'.
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field), diffrax.Dopri8(), 0.0, 100.0, None, exit_state, p,
        saveat=diffrax.SaveAt(t1=True),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol),
        event=diffrax.Event(acceleration, optx.Bisection(rtol=0.0, atol=1e-14),
                            direction=False),
        adjoint=diffrax.ForwardMode(),  # forward-differentiable: `existence_limit_tangent`
    )
    return sol.ys[-1, 1, 0] - v_d


_peak = checks_as_nan(eqx.filter_jit(_slip_arc_peak))

#: The time after the stick exit before which the slip arc's peak is not looked for
#: (`_slip_arc_peak`): x'' there is about -k v_d EXIT_GUARD, far above rounding, and
#: the peak comes a large fraction of a period later.
EXIT_GUARD = 1e-3


#: Bisection steps: the bracket [lower, upper] shrinks by 2^-BISECTION_STEPS.
BISECTION_STEPS = 80


def stick_slip_existence_limit(params: ChainParams | None = None,
                               lower: float | None = None, upper: float = 3.0, *,
                               tol: float = 1e-10, rtol: float = 1e-12) -> float:
    """Largest belt speed at which the single oscillator's stick-slip cycle of the
    non-smooth model (eqs. (1)-(2) and (5) with eta_c irrelevant) exists.

    A cycle of one oscillator leaves stick at x = mu_st - 2 xi v_d, x' = v_d
    (`stick_force` = mu_st), slips behind the belt and must come back to x' = v_d
    to stick again. Above the limit the slip arc spirals into steady sliding
    instead. At the limit it grazes: the first maximum of x' on the arc equals v_d.
    That maximum minus v_d is a smooth function of v_d, located with diffrax (an
    event at x'' = 0 on the slip vector field of the reference) and its root with
    optimistix's bisection. This is where the unstable cycle born at the Hopf point
    meets the stick-slip cycle in the non-smooth limit.

    **Arguments:**

    - `params`: one oscillator (n_osc = 1; `single_oscillator` takes one out of a
        chain); its xi, stiffness, load and friction law are used.
    - `lower`, `upper`: a bracket of belt speeds, the cycle existing at `lower` and
        not at `upper`. By default `lower` is the Hopf point of steady sliding
        (`hopf_vd_analytic` for eq. (1), `hopf_point` for another law), where
        the cycle exists whenever there is a velocity-weakening Hopf point;
        `upper` is raised by factors of 1.5 (up to 20 times) until the cycle no longer exists there.
    - `tol`: absolute tolerance on the limit.
    - `rtol`: integration tolerance of the slip arc.

    **Returns:**

    The limit belt speed, dimensionless.

    **Raises:**

    `ValidationError` for n_osc != 1. `ValueError` (a failed computation, not a
    `ValidationError`) when steady sliding has no Hopf point to start from and
    `lower` is not given, or when the bracket does not contain the limit.
    """
    params = chain_or_default(params, n_osc=1)
    if params.n_osc != 1:
        raise ValidationError(f"the existence limit is that of one oscillator (n_osc = 1), got "
                              f"n_osc = {params.n_osc}; see single_oscillator")
    if lower is None:
        from .hopf import hopf_speed  # for a default

        lower = hopf_speed(params)
        if not lower > 0:
            raise ValueError(f"no Hopf point of steady sliding to start from (v_d,H = "
                             f"{lower:.3g}): give lower, a belt speed with a stick-slip cycle")
    args = (params, rtol)
    lo, hi = (float(_peak(jnp.asarray(v, dtype=float), args)) for v in (lower, upper))
    for _ in range(20):
        if not (lo > 0 and hi > 0):
            break
        upper *= 1.5
        hi = float(_peak(jnp.asarray(upper, dtype=float), args))
    if not (lo > 0 > hi):
        raise ValueError(f"the bracket [lower, upper] = [{lower}, {upper}] must contain "
                         f"the existence limit: the cycle must exist at lower and not at "
                         f"upper (peak x' - v_d = {lo:.3g}, {hi:.3g})")
    # Bisection stops when the bracket is narrower than tol and |peak| < tol. Where
    # the peak is resolved only to more than tol (v0 = 1e-3: the friction changes
    # within 1e-3 of stick, where the arc grazes), the second never holds; the
    # bracket still halves every step, so after BISECTION_STEPS it is far below tol.
    with errors_as_nan():  # a program without host callbacks, kept in the cache
        sol = optx.root_find(_slip_arc_peak, optx.Bisection(rtol=0.0, atol=tol),
                             jnp.asarray(0.5 * (lower + upper)), args,
                             options={"lower": jnp.asarray(lower, dtype=float),
                                      "upper": jnp.asarray(upper, dtype=float)},
                             max_steps=BISECTION_STEPS, throw=False)
    if sol.result not in (optx.RESULTS.successful, optx.RESULTS.nonlinear_max_steps_reached):
        raise RuntimeError(f"bisection for the existence limit failed: {sol.result}")
    return float(sol.value)


def differentiable_existence_limit(params: ChainParams, limit: float):
    """The existence limit as a traceable function of the parameters near `limit`,
    the limit that `stick_slip_existence_limit` computed for `params`: limit -
    peak(limit; params) / (d peak / d v_d), whose value is `limit` and whose
    derivative in any parameter is that of the limit, -(d peak/d p) / (d peak/d v_d)
    (the implicit function theorem on the grazing condition peak = 0), both
    derivatives by forward-mode differentiation through the slip arc. For
    `jax.jacfwd` and the propagation of uncertainty (`Identification.propagate`).

    **Arguments:** `params`: one oscillator (n_osc = 1); `limit`: its existence
    limit.

    **Returns:** a scalar, `limit` in value.

    **Raises:** `ValidationError` for n_osc != 1.
    """
    if params.n_osc != 1:
        raise ValidationError(f"the existence limit is that of one oscillator (n_osc = 1), got "
                              f"n_osc = {params.n_osc}; see single_oscillator")
    v = jnp.asarray(limit, dtype=float)
    args = (params, 1e-12)
    slope = jax.jacfwd(_slip_arc_peak)(jax.lax.stop_gradient(v),
                                       jax.lax.stop_gradient(args))
    return v - _slip_arc_peak(v, args) / jax.lax.stop_gradient(slope)
