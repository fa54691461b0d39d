"""The event-driven run of the exact engine (the non-smooth reference), observing while
integrating."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..._physics.custom_types import State
from ..._physics.initial import AbstractInitialCondition, GivenState
from ..._physics.params import ChainParams
from ..compat import checks_as_nan
from ..observers.base import no_partial_answers
from ..observables import Observables
from ..progress import progress_bar
from ..status import Status, balance_status
from ..._errors import ValidationError
from .options import NonsmoothOptions
from .stepping import OBSERVERS, Carry, chunk, initial_carry, observe_samples, observers_args


class NonsmoothObservables(eqx.Module):
    """What one run of the non-smooth reference observes over [transient, t_end].
    Batched runs give every field the leading batch axes.

    **Fields:**

    - `amplitudes`: half of peak-to-peak of each x_n, shape (n_osc,). Extrema are
        taken at turning points located on the dense output, so they are exact to
        the integration tolerance, with no sampling error.
    - `energy`: E = 1/2 sum_n A_n^2, eq. (9) of the paper, shape ().
    - `on_halc`: whether each oscillator is on the HALC: it sticks during the
        window, `min_slip_speed` = 0 (`sticks` with eps = 0), shape (n_osc,).
    - `n_halc`: number of oscillators on the HALC, shape ().
    - `min_slip_speed`: smallest |x_n' - v_d| over the located samples of the
        window (turning points, switches and chunk ends): exactly 0 for an oscillator that sticks
        (x_n' = v_d in stick); about the event tolerance at a slip reversal (v_rel
        passing through 0 without stick), which is therefore no stick; otherwise an
        upper bound of the true minimum, shape (n_osc,).
    - `stick_fraction`: fraction of the window each oscillator spends in stick,
        shape (n_osc,).
    - `x_max`, `x_min`: extrema of x_n over each half of the window, shape
        (2, n_osc).
    - `half_difference`: largest difference between the two halves' extrema, over
        the oscillators, relative to max(1, max amplitude), shape (). It is at the
        integration tolerance for a periodic state.
    - `y_initial`, `y_final`: state at t = 0 and at t_end, shape (2, n_osc).
    - `modes_final`: modes at t_end (+1/-1 slip, 0 stick), shape (n_osc,).
    - `friction_work`, `viscous_dissipation`: int sum_n F_n x_n' dt and
        int sum_n 2 xi x_n'^2 dt over [0, t_end], shape (). Their difference equals
        the change of `mechanical_energy`.(the energy balance).
    - `log_time`, `log_osc`, `log_kind`: the last `log_size` switches (time,
        oscillator index from 0, index into `SWITCH_KINDS`), oldest first, shape
        (log_size,); unused entries have time NaN and oscillator and kind -1.
    - `num_events`, `num_steps`: switch instants and integration steps (accepted
        or rejected) of the whole run, shape ().
    - `status`: the `Status` of the run (its integer value; `Status.ok` is
        success, `Status.event_not_resolved` its own failure), shape ().

    The window's observables are those of the smoothed engine's `Extrema`, fed
    the state at every turning point, switch and chunk end (`observe_samples`). A failed
    run gives NaN observables and `n_halc` = -1. All quantities are
    dimensionless (eqs. (4)-(6)).
    """

    amplitudes: Float[Array, "*batch n_osc"]
    energy: Float[Array, "*batch"]
    on_halc: Bool[Array, "*batch n_osc"]
    n_halc: Int[Array, "*batch"]
    min_slip_speed: Float[Array, "*batch n_osc"]
    stick_fraction: Float[Array, "*batch n_osc"]
    x_max: Float[Array, "*batch 2 n_osc"]
    x_min: Float[Array, "*batch 2 n_osc"]
    half_difference: Float[Array, "*batch"]
    y_initial: Float[Array, "*batch 2 n_osc"]
    y_final: Float[Array, "*batch 2 n_osc"]
    modes_final: Float[Array, "*batch n_osc"]
    friction_work: Float[Array, "*batch"]
    viscous_dissipation: Float[Array, "*batch"]
    log_time: Float[Array, "*batch log"]
    log_osc: Int[Array, "*batch log"]
    log_kind: Int[Array, "*batch log"]
    num_events: Int[Array, "*batch"]
    num_steps: Int[Array, "*batch"]
    status: Int[Array, "*batch"]


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


def run_exact(params: ChainParams, y0: State, options: NonsmoothOptions,
              progress: bool = False) -> Observables:
    """Pure, traceable run of the exact engine for one trajectory, in the layout of
    the smoothed engine (`Observables`): the engine value `Exact` runs it, and
    `run_lanes` maps it over lanes. An oscillator is on the HALC when it sticks
    during the window (`min_slip_speed` = 0: no eps)."""
    extrema, c = _run(params, y0, options, progress)
    kept = {f.name for f in dataclasses.fields(Observables)}
    return Observables(**{k: v for k, v in extrema.items() if k in kept},
                       y_initial=y0, y_final=c.y, num_steps=c.steps, status=c.status)


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


def run_nonsmooth(params: ChainParams, y0: State, options: NonsmoothOptions,
                  progress: bool = False) -> NonsmoothObservables:
    """The pure, traceable core of `simulate_nonsmooth` for one trajectory: no
    checks and no exceptions (a failure is in `status`), to differentiate or to
    vmap over a batch.

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

    `NonsmoothObservables`, per-oscillator fields of shape (n_osc,).
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
    return NonsmoothObservables(
        amplitudes=extrema["amplitudes"], energy=extrema["energy"],
        on_halc=extrema["on_halc"], n_halc=extrema["n_halc"],
        min_slip_speed=extrema["min_slip_speed"], stick_fraction=stick_fraction,
        x_max=x_max, x_min=x_min, half_difference=half_difference, y_initial=y0,
        y_final=c.y, modes_final=c.modes, friction_work=c.work[0],
        viscous_dissipation=c.work[1], log_time=log_time,
        log_osc=log_osc, log_kind=log_kind, num_events=c.events,
        num_steps=c.steps, status=c.status,
    )


_run_jit = eqx.filter_jit(run_nonsmooth)


def simulate_nonsmooth(params: ChainParams, y0: AbstractInitialCondition | State,
                       options: NonsmoothOptions = NonsmoothOptions.reference(), *,
                       throw: bool = True, progress: bool = False
                       ) -> NonsmoothObservables:
    """Integrate eq. (5) of the paper with the non-smooth friction law of eqs.
    (1)-(2), event-driven, and return the observables.

    Each oscillator is in slip (eq. (5) with F = -mu(|v_rel|) sign(v_rel)) or in
    stick (x_n' = v_d while the force it needs, `stick_force`, stays below mu_st in
    magnitude). Stick ends when |f_n| reaches mu_st; slip ends when v_rel reaches
    zero, and the oscillator then sticks if |f_n| < mu_st and otherwise reverses
    slip direction. This is the switch model of Leine et al. (1998), Nonlinear
    Dynamics 16, 41-54, without its stick band: stick is exact.

    The run advances one adaptive Runge-Kutta step at a time (diffrax's solver and
    PID controller, `options.solver` at `options.rtol`), never restarting at a
    switch: each switch is located on the dense output of the step in which the
    smallest guard falls through zero, by Chandrupatla's bracketed method (to
    `options.root_tol`), and the turning points of the oscillators (the extrema
    from which the amplitudes are taken) are read from the dense output between
    switches (`jaxchain/_engine/exact/stepping.py`). The states at the turning
    points, the switches and the chunk ends of the window go to the observers of
    the smoothed engine (`Extrema`, `observe_chunk`), so both engines compute
    their amplitudes, extrema and HALC alike. Several oscillators that switch at
    the same instant (within `options.switch_tol` on their guards) switch
    together: the force needed to stick depends on displacements only, so each
    decision is independent of the others.

    Its default options are the reference's (`NonsmoothOptions.reference`: Tsit5
    at rtol = atol = 1e-12); `engine="exact"` runs the same engine at the exact
    engine's defaults (`NonsmoothOptions()`).

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: an initial condition or a state of shape (2, n_osc).
    - `options`: `NonsmoothOptions`.
    - `throw`: raise on failure (default) or return the status.
    - `progress`: show a tqdm bar, one tick per chunk.

    **Returns:**

    `NonsmoothObservables`, per-oscillator fields of shape (n_osc,).

    **Raises:**

    `ValidationError` for a state of the wrong shape; `RuntimeError` with advice when the
    run fails and `throw=True`.
    """
    if not isinstance(y0, AbstractInitialCondition):
        y0 = GivenState(y0)
    y = y0(params)
    with progress_bar(options.n_chunks(halves=True), "non-smooth reference", progress):
        obs = _run_jit(params, y, options, progress)
    status = Status(int(obs.status))
    if throw and status is not Status.ok:
        raise RuntimeError(f"{status}: {status.message}")
    return obs


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
    `t_end` (traced: one program for every horizon), as `run_nonsmooth` logs them.
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
    """The state of the non-smooth reference (`simulate_nonsmooth`) at the times
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
