"""Grazing of the single oscillator's stick-slip cycle in the exact switch model, the
end of its branch: located by Newton's method on its defining condition from a
point of the exact continuation, and followed in a second parameter."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._engine.compat import checks_as_nan
from .._engine.exact.options import NonsmoothOptions
from .._engine.exact.solve import run_exact
from .._engine.exact.switching import SWITCH_KINDS, mode_field
from .._errors import ValidationError
from .._physics.model import stick_force
from .._physics.params import ChainParams, parameter_value, with_parameter
from .existence import stick_exit_state
from .._printing import values_repr


class GrazingPoint(eqx.Module):
    """A grazing point of the stick-slip cycle: the parameter value at which the slip
    arc that leaves stick touches v_rel = 0 without crossing it.

    **Fields:**

    - `params`: the oscillator, with the parameter at the grazing value.
    - `where`: the name of the parameter located (`with_parameter`).
    - `value`: its value at grazing, dimensionless, shape ().
    - `time`: the duration of the slip arc from the stick exit to the tangency,
        shape ().
    - `residual`: the largest residual of the defining condition, shape ().
    - `converged`: whether Newton's method converged, shape ().
    """

    params: ChainParams
    where: str = eqx.field(static=True)
    value: Float[Array, ""]
    time: Float[Array, ""]
    residual: Float[Array, ""]
    converged: Bool[Array, ""]

    __repr__ = values_repr


def _arc_end(time, params: ChainParams, rtol: float):
    """The state (x, x') after `time` on the slip arc that leaves stick, integrated
    in slip with the exact model's slip field (`mode_field`, mode fixed: no switch),
    shape (2, 1)."""
    y0 = stick_exit_state(params)
    args = (params, -jnp.sign(stick_force(params, y0[0])))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(mode_field), diffrax.Dopri8(), 0.0, time, None,
        (y0, jnp.zeros(2)), args, saveat=diffrax.SaveAt(t1=True),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol),
        adjoint=diffrax.ForwardMode(), max_steps=100_000)
    return sol.ys[0][-1], args


def _tangency(z, args):
    """The defining condition of grazing, zero at (time, value): the relative
    velocity x' - v_d and the acceleration x'' at the end of the slip arc (a
    turning point of x' at v_rel = 0)."""
    time, value = z
    params, where, rtol = args
    p = with_parameter(params, where, value)
    y, field_args = _arc_end(time, p, rtol)
    dy, _ = mode_field(time, (y, jnp.zeros(2)), field_args)
    return jnp.stack([y[1, 0] - p.v_d, dy[1, 0]])


@checks_as_nan
@eqx.filter_jit
def _return_time(params: ChainParams, options: NonsmoothOptions):
    """The time from the stick exit to the first return to stick (slip to stick) by
    the exact engine, NaN if none within `options.t_end`."""
    obs = run_exact(params, stick_exit_state(params), options)
    returns = jnp.where(obs.log_kind == SWITCH_KINDS.index("slip to stick"), obs.log_time,
                        jnp.inf)
    first = jnp.min(returns)
    return jnp.where(jnp.isfinite(first), first, jnp.nan)


_newton = checks_as_nan(eqx.filter_jit(lambda z, args, tol: optx.root_find(
    _tangency, optx.Newton(rtol=tol, atol=tol), z, args, max_steps=50, throw=False)))


def stick_slip_grazing(params: ChainParams, where: str = "v_d", near: float | None = None,
                       *, tol: float = 1e-12, rtol: float = 1e-12) -> GrazingPoint:
    """The grazing point of the single oscillator's stick-slip cycle in the exact
    switch model, where its branch ends: the value of the parameter `where` at
    which the slip arc that leaves stick (x' = v_d, stick margin 0) returns to the
    belt speed tangentially. Located by Newton's method on its defining condition,
    x' = v_d and x'' = 0 at the arc's end, in the unknowns (arc duration, value)
    (Di Bernardo, Budd, Champneys and Kowalczyk, *Piecewise-smooth Dynamical
    Systems*, Springer 2008, Sect. 7.2: grazing of a periodic orbit with a
    switching surface), started from a point `near` of the exact continuation
    (`cycle_problem` on the exact engine), whose first return to stick by the exact engine
    gives the arc's duration. The arc is integrated in slip with the exact
    model's slip field (Dopri8 at `rtol`), so that the condition is smooth on
    both sides of the grazing value.

    **Arguments:**

    - `params`: one oscillator (n_osc = 1).
    - `where`: the parameter, a name that `with_parameter` takes ("v_d", "xi",
        "mu_st", ...).
    - `near`: a value of `where` at which the stick-slip cycle exists, near the
        grazing value (the last point of a continuation). By default (`where`
        "v_d" only) the last of the belt speeds from the Hopf point up in steps of
        `MARCH_STEP` at which the exact engine's arc returns to stick.
    - `tol`: Newton's tolerance (rtol = atol) on the duration and the value.
    - `rtol`: integration tolerance of the slip arc (rtol = atol).

    **Returns:**

    `GrazingPoint`.

    **Raises:**

    `ValidationError` for n_osc != 1, an unknown parameter, or no `near` for a
    parameter other than v_d; `ValueError` when the cycle does not return to stick
    at `near` (no stick-slip cycle there) or, without `near`, at the Hopf point.
    """
    if params.n_osc != 1:
        raise ValidationError(f"stick_slip_grazing takes one oscillator (n_osc = 1), got "
                              f"n_osc = {params.n_osc}; see single_oscillator")
    if near is None:
        if where != "v_d":
            raise ValidationError(f"stick_slip_grazing in {where}: give near, a value of "
                                  f"{where} with a stick-slip cycle")
        near, time = _march(params)
    else:
        near = float(near)
        time = float(_return_time(with_parameter(params, where, near), _RETURN))
    if not np.isfinite(time):
        raise ValueError(f"no return to stick from the stick exit at {where} = {near}: "
                         f"no stick-slip cycle there to start from")
    return _solve(params, where, jnp.array([time, near]), tol, rtol)


#: The exact engine's run from the stick exit that finds the first return to stick.
_RETURN = NonsmoothOptions.reference(t_end=200.0, transient=0.0)

#: The steps of `_march` in v_d.
MARCH_STEP = 0.05


def _march(params: ChainParams) -> tuple[float, float]:
    """A start near the grazing point in v_d: from the Hopf point of steady sliding
    (`hopf_speed`), where the stick-slip cycle exists whenever steady sliding loses
    stability there subcritically, up in steps of `MARCH_STEP` while the exact
    engine's arc from the stick exit returns to stick (natural-parameter stepping);
    the last such v_d and its return time.

    **Raises:** `ValueError` when there is no Hopf point, or no return to stick at
    it."""
    from .hopf import hopf_speed  # a default start

    v_d = hopf_speed(params)
    if not v_d > 0:
        raise ValueError(f"no Hopf point of steady sliding to start from (v_d,H = {v_d:.3g}): "
                         f"give near, a value with a stick-slip cycle")
    last = (v_d, float(_return_time(with_parameter(params, "v_d", v_d), _RETURN)))
    for _ in range(400):
        time = float(_return_time(with_parameter(params, "v_d", last[0] + MARCH_STEP), _RETURN))
        if not np.isfinite(time):
            break
        last = (last[0] + MARCH_STEP, time)
    return last


def _solve(params, where, z0, tol, rtol) -> GrazingPoint:
    args = (params, where, rtol)
    sol = _newton(z0, args, tol)
    residual = jnp.max(jnp.abs(_tangency(sol.value, args)))
    converged = (sol.result == optx.RESULTS.successful) & (residual < 1e-9) & (sol.value[0] > 0)
    return GrazingPoint(params=with_parameter(params, where, sol.value[1]), where=where,
                        value=sol.value[1], time=sol.value[0], residual=residual,
                        converged=converged)


def grazing_curve(point: GrazingPoint, other: str, values, *, tol: float = 1e-12,
                  rtol: float = 1e-12) -> GrazingPoint:
    """The grazing points of the stick-slip cycle as a second parameter `other` runs
    through `values`: a two-parameter curve of grazing (the exact model's
    counterpart of the smoothed model's fold curves, `boundary_curves`), by
    natural-parameter continuation (Seydel, *Practical Bifurcation and Stability
    Analysis*, 3rd ed. 2010, Sect. 4.1): Newton's method on the defining
    condition (`stick_slip_grazing`) at each value, from the solution at the
    previous one, outwards from the value nearest to that of `point`.

    **Arguments:**

    - `point`: a converged `GrazingPoint`.
    - `other`: the second parameter, a name that `with_parameter` takes.
    - `values`: its values, shape (m,), increasing.

    **Returns:**

    `GrazingPoint` with fields of shape (m,) (`params` that of `point`): the
    grazing value of `point.where` and the arc's duration at each value.

    **Raises:**

    `ValidationError` for a `point` that did not converge, or values that are not
    increasing.
    """
    if not bool(point.converged):
        raise ValidationError("grazing_curve starts from a converged GrazingPoint")
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or np.any(np.diff(values) <= 0):
        raise ValidationError("values must be a 1-D array of increasing values")
    at = int(np.argmin(np.abs(values - float(parameter_value(point.params, other)))))
    found = [None] * values.size
    for order in (range(at, values.size), range(at - 1, -1, -1)):
        z = jnp.array([point.time, point.value])
        for k in order:
            params = with_parameter(point.params, other, values[k])
            found[k] = _solve(params, point.where, z, tol, rtol)
            z = jnp.array([found[k].time, found[k].value])
    return GrazingPoint(params=point.params, where=point.where,
                        **{name: jnp.stack([getattr(f, name) for f in found])
                           for name in ("value", "time", "residual", "converged")})


def grazing_slope(point: GrazingPoint, other: str) -> float:
    """The derivative of the grazing value in another parameter: the implicit function
    theorem on the defining condition F(time, value; q) = 0 of `stick_slip_grazing`,
    d(time, value)/dq = -(dF/d(time, value))^-1 dF/dq, both Jacobians by forward-mode
    differentiation through the slip arc.

    **Arguments:** `point`: a converged `GrazingPoint` (one point, not a curve);
    `other`: the parameter, a name that `with_parameter` takes.

    **Returns:** d value / d other, dimensionless.

    **Raises:** `ValidationError` for a point that did not converge.
    """
    if not bool(point.converged):
        raise ValidationError("grazing_slope takes a converged GrazingPoint")
    z = jnp.array([point.time, point.value])
    return float(_slope(z, point.params, point.where, other))


@checks_as_nan
@eqx.filter_jit
def _slope(z, params: ChainParams, where: str, other: str) -> Float[Array, ""]:
    """`grazing_slope` as one compiled program (not op by op)."""
    rtol = 1e-12
    jac_z = jax.jacfwd(_tangency)(z, (params, where, rtol))
    jac_q = parameter_value(jax.jacfwd(lambda p: _tangency(z, (p, where, rtol)))(params),
                            other)
    return -jnp.linalg.solve(jac_z, jnp.reshape(jac_q, (2,)))[1]
