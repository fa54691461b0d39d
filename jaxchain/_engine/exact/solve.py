"""The event-driven run of the exact engine (the non-smooth reference), observing while
integrating."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._physics.custom_types import State
from ..._physics.initial import AbstractInitialCondition, GivenState
from ..._physics.params import ChainParams
from ..compat import checks_as_nan
from ..observers.base import no_partial_answers
from ..observables import Observables
from ..status import Status, balance_status
from ..._errors import ValidationError
from .options import NonsmoothOptions
from .stepping import OBSERVERS, Carry, chunk, initial_carry, observe_samples, observers_args


def _run(params: ChainParams, y0: State, options: NonsmoothOptions,
         progress: bool) -> tuple[dict, Carry]:
    """One trajectory event by event: what `Extrema` observed over the window (NaN
    where the run failed) and the final carry."""
    c = initial_carry(params, y0, options,
                      tuple(o.init(y0, params, options) for o in OBSERVERS))
    # One scan over the chunks of every phase (one compiled copy of a segment), each
    # chunk's end and whether it lies in the observed window as its inputs. A
    # sample at the start of the window is the end of the transient's last chunk;
    # the observers ignore the samples of the transient by their time.
    ends, observed = [], []
    for start, length, count, observe in options.phases(halves=True):
        ends.append(start + length * np.arange(1, count + 1))
        observed.append(np.full(count, observe))
    if not options.transient:  # the window's edge, where no step ends
        c = eqx.tree_at(lambda d: d.observed, c,
                        observe_samples(c.observed, c.t[None], c.y[None], params, options))

    def body(d, xs):
        t_stop, observe = xs
        return chunk(params, options, progress, observe, d, t_stop), None

    c, _ = jax.lax.scan(body, c, (jnp.asarray(np.concatenate(ends)),
                                  jnp.asarray(np.concatenate(observed))))
    c = eqx.tree_at(lambda d: d.status, c, balance_status(
        c.status, params, y0, c.y, c.work[0], c.work[1], options.rtol, options.atol))

    ok = c.status == Status.ok
    (extrema,) = (no_partial_answers(o.result(s, observers_args(params), options), ok)
                  for o, s in zip(OBSERVERS, c.observed))
    return extrema, c


def _switch_log(c: Carry, size: int):
    """The last `size` switches (time, oscillator, kind), oldest first, from the
    run's ring buffer of the last `size` switch instants (`Carry.log_time`, and
    `Carry.log_kind` of every oscillator there, -1 where it did not switch);
    unused entries first, with time NaN and oscillator and kind -1."""
    rows = (c.events + jnp.arange(size)) % size  # oldest first
    n = c.log_kind.shape[-1]
    kind = c.log_kind[rows].reshape(-1)
    time = jnp.repeat(c.log_time[rows], n)
    osc = jnp.tile(jnp.arange(n), size)
    valid = kind >= 0
    after = jnp.cumsum(valid[::-1])[::-1]  # valid entries from here to the newest
    slot = jnp.where(valid & (after <= size), size - after, size)
    return (jnp.full(size, jnp.nan).at[slot].set(time, mode="drop"),
            jnp.full(size, -1).at[slot].set(osc, mode="drop"),
            jnp.full(size, -1).at[slot].set(kind, mode="drop"))


def run_exact(params: ChainParams, y0: State, options: NonsmoothOptions,
              progress: bool = False) -> Observables:
    """Pure, traceable run of the exact engine for one trajectory (`Exact.run`): no
    checks and no exceptions (a failure is in `status`), to differentiate or to
    map over lanes (`run_lanes`). Its `Observables` are those of the smoothed
    engine, in the same layout, with the exact engine's own fields filled in (the
    switch log, the energy balance, the stick fractions, the halves' extrema). An
    oscillator is on the HALC when it sticks during the window (`min_slip_speed`
    = 0: no eps).

    Differentiable through every switch with respect to `params` and `y0`: each
    switch time by the implicit function theorem on its guard, each extremum as x
    at its turning point's time (x' = 0 there), so that an event time, a period
    (the difference of two switch times in the log) or an amplitude has the
    derivative of the exact model (Leine and Nijmeijer, *Dynamics and Bifurcations
    of Non-Smooth Mechanical Systems*, 2004: the saltation matrix of each switch,
    applied without forming it). In forward mode (`jax.jvp`, `jax.jacfwd`) with
    `options.adjoint` "forward", the default; in reverse mode (`jax.grad`,
    `jax.vjp`) with "reverse". A derivative is meaningful on a periodic state
    (a limit cycle, as of the stick-slip cycle); on an irregular one it is that of
    one trajectory over the horizon, which grows with it.

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: the initial state, shape (2, n_osc).
    - `options`: `NonsmoothOptions` (static).
    - `progress`: tick the active progress bar once per chunk (static).

    **Returns:**

    `Observables`, per-oscillator fields of shape (n_osc,).
    """
    size = options.log_size
    extrema, c = _run(params, y0, options, progress)
    ok = c.status == Status.ok
    x_max, x_min = extrema["x_max_halves"], extrema["x_min_halves"]
    scale = jnp.maximum(1.0, jnp.max(extrema["amplitudes"]))
    half_difference = jnp.maximum(jnp.max(jnp.abs(x_max[0] - x_max[1])),
                                  jnp.max(jnp.abs(x_min[0] - x_min[1]))) / scale
    window = options.t_end - options.transient
    stick_fraction = jnp.where(ok, c.stick_time / window, jnp.nan)
    log_time, log_osc, log_kind = _switch_log(c, size)
    kept = {f.name for f in dataclasses.fields(Observables)}
    return Observables(
        **{k: v for k, v in extrema.items() if k in kept}, y_initial=y0, y_final=c.y,
        num_steps=c.steps, status=c.status, half_difference=half_difference,
        stick_fraction=stick_fraction,
        modes_final=c.modes, friction_work=c.work[0], viscous_dissipation=c.work[1],
        log_time=log_time, log_osc=log_osc, log_kind=log_kind, num_events=c.events)


@checks_as_nan
@eqx.filter_jit
def nonsmooth_flow(params: ChainParams, y0: State, ts, options: NonsmoothOptions):
    """The flow map of the exact switch model: the states at the times `ts` from
    the state `y0` at t = 0, event by event through every switch. Pure and
    traceable (no checks, no exceptions; a failure is its status), to
    differentiate, vmap or use inside a Newton solve such as shooting.

    Differentiable with respect to `params` and `y0` through every switch: in
    forward mode (`jax.jvp`, `jax.jacfwd`) with `options.adjoint` "forward" (the
    default), in reverse mode with "reverse". The Jacobian with respect to `y0`
    is the product of the smooth flows' Jacobians and the saltation matrix of
    each switch (`saltation_matrix`; Leine and Nijmeijer, *Dynamics and
    Bifurcations of Non-Smooth Mechanical Systems*, 2004, Section 7.1). A
    sticking oscillator is one whose x_n' equals v_d exactly (`initial_modes`):
    its velocity's column is zero (stick does not read it).

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: the state at t = 0, shape (2, n_osc).
    - `ts`: times, increasing, > 0, shape (m,), dimensionless (eq. (4)).
    - `options`: `NonsmoothOptions` (static); its tolerances, budgets and adjoint
        apply, its horizon does not.

    **Returns:**

    (states, status): shape (m, 2, n_osc), and the run's `Status` as an integer
    (shape ()).
    """

    c, ys = _flow(params, y0, ts, options)
    return ys, c.status


def _flow(params: ChainParams, y0: State, ts, options: NonsmoothOptions):
    """The exact engine from `y0` to each time of `ts` in turn, observing nothing:
    (the final carry, the states at `ts`)."""

    def body(c, t):
        c = chunk(params, options, False, False, c, t)
        return c, c.y

    return jax.lax.scan(body, initial_carry(params, y0, options, ()), ts)


@checks_as_nan
@eqx.filter_jit
def nonsmooth_switches(params: ChainParams, y0: State, t_end, options: NonsmoothOptions):
    """The switches of the exact switch model from the state `y0` at t = 0 to
    `t_end` (traced: one program for every horizon), as `run_exact` logs them
    (`Observables.log_time`).
    Pure and traceable, like `nonsmooth_flow`.

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: the state at t = 0, shape (2, n_osc).
    - `t_end`: the horizon (> 0), shape (), dimensionless (eq. (4)).
    - `options`: `NonsmoothOptions` (static); its tolerances, budgets and log size
        apply, its horizon does not.

    **Returns:**

    (time, oscillator, kind, status): the last `options.log_size` switches, oldest
    first, each of shape (log_size,) (unused entries have time NaN and oscillator
    and kind -1; kind indexes `SWITCH_KINDS`), and the run's `Status` as an
    integer, shape ().
    """
    c, _ = _flow(params, y0, jnp.atleast_1d(t_end), options)
    return _switch_log(c, options.log_size) + (c.status,)


def nonsmooth_trajectory(params: ChainParams, y0: AbstractInitialCondition | State,
                         ts: Float[Array, " m"],
                         options: NonsmoothOptions = NonsmoothOptions.reference()
                         ) -> Float[Array, "m 2 n_osc"]:
    """The state of the non-smooth reference (the exact engine) at the times
    `ts`: the exact switch model, integrated event by event from t = 0 to each
    sample in turn, so that every sample is exact to the integration tolerance
    (no interpolation across a switch). This is the reference from which the
    identification's tests make their records.

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: an initial condition or a state of shape (2, n_osc) at t = 0.
    - `ts`: sample times, increasing, >= 0, shape (m,), dimensionless (eq. (4)).
    - `options`: `NonsmoothOptions`; its tolerances and event budget apply (its
        horizon does not: `ts` is the horizon).

    **Returns:**

    The states, shape (m, 2, n_osc): rows (x, x') at each time.

    **Raises:**

    `ValidationError` for times that are not increasing or negative;
    `RuntimeError` naming the status when the run fails.
    """
    ts = np.asarray(ts, dtype=float)
    if ts.ndim != 1 or ts.size == 0 or ts[0] < 0 or np.any(np.diff(ts) <= 0):
        raise ValidationError("ts must be a non-empty increasing array of times >= 0")
    if not isinstance(y0, AbstractInitialCondition):
        y0 = GivenState(y0)
    ys, status = nonsmooth_flow(params, y0(params), jnp.asarray(ts), options)
    status = Status(int(status))
    if status is not Status.ok:
        raise RuntimeError(f"{status}: {status.message}")
    return ys
