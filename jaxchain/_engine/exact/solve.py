"""The event-driven run of the exact engine (the non-smooth reference), observing while
integrating."""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from ..._physics.custom_types import State
from ..._physics.initial import AbstractInitialCondition, GivenState
from ..._physics.model import Model
from ..._physics.params import ChainParams
from ..compat import errors_as_nan
from ..observers.base import Chunk, no_partial_answers, observe_chunk
from ..observers.extrema import Extrema
from ..observables import Observables
from ..progress import progress_bar, tick
from ..status import Status
from ..._errors import ValidationError
from .options import NonsmoothOptions
from .root import Chandrupatla
from .switching import guard, initial_modes, mode_field, switch, turning_directions



class NonsmoothObservables(eqx.Module):
    """What one run of the non-smooth reference observes over [transient, t_end].
    Batched runs give every field the leading batch axes.

    **Fields:**

    - `amplitudes`: half of peak-to-peak of each x_n, shape (n_osc,). Extrema are
        taken at turning points located as events, so they are exact to the
        integration tolerance, with no sampling error.
    - `energy`: E = 1/2 sum_n A_n^2, eq. (9) of the paper, shape ().
    - `on_halc`: whether each oscillator is on the HALC: it sticks during the
        window, `min_slip_speed` = 0 (`sticks` with eps = 0), shape (n_osc,).
    - `n_halc`: number of oscillators on the HALC, shape ().
    - `min_slip_speed`: smallest |x_n' - v_d| over the located samples of the
        window (events and chunk ends): exactly 0 for an oscillator that sticks
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
    - `num_events`, `num_steps`: segments ended by an event and integration steps
        of the whole run, shape ().
    - `status`: the `Status` of the run (its integer value; `Status.ok` is
        success, `Status.event_not_resolved` its own failure), shape ().

    The window's observables are those of the smoothed engine's `Extrema`, fed
    the state at every located event and chunk end (`observe_sample`). A failed
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


class _Carry(eqx.Module):
    t: Float[Array, ""]
    y: State
    work: Float[Array, "2"]
    modes: Float[Array, " n_osc"]
    observed: tuple
    stick_time: Float[Array, " n_osc"]
    log_time: Float[Array, " log"]
    log_osc: Int[Array, " log"]
    log_kind: Int[Array, " log"]
    log_count: Int[Array, ""]
    events: Int[Array, ""]
    chunk_events: Int[Array, ""]
    steps: Int[Array, ""]
    status: Int[Array, ""]


#: What the reference observes (`Extrema`, with the halves of the window).
_OBSERVERS = (Extrema(),)


def _observers_args(params: ChainParams) -> Model:
    """The model as the observers see it: eps = 0, since the exact engine has no
    smoothing (its stick band is v_rel = 0, `sticks`)."""
    return Model(params, jnp.zeros(()))


def observe_sample(states: tuple, t, y, params: ChainParams, options) -> tuple:
    """The observers' states after one located sample, the state `y` at time `t`:
    a chunk of one sample through `observe_chunk`, the route of the smoothed
    engine."""
    chunk = Chunk(t0=t, t1=t, ts=jnp.reshape(t, (1,)), ys=y[None], log_growth=None)
    return observe_chunk(_OBSERVERS, states, chunk, _observers_args(params), options)


def _segment(params, options, observe, t_stop, c: _Carry) -> _Carry:
    """Integrate from c.t with fixed modes until the first event or t_stop, hand
    the state there to the observers, then apply the switching rule. `observe`
    (traced, the chunk lies in the observed window) adds the turning points to the
    events and counts the stick time; the observers take only samples in their
    window, by time."""
    sigma = turning_directions(params, c.y, c.modes, options.switch_tol)
    args = (params, c.modes, sigma, observe, options.switch_tol)
    # The smallest guard starts every segment above zero and the event is its fall
    # through zero (direction=False), located on the dense output of the step in
    # which it occurs by Chandrupatla's bracketed method (`Chandrupatla`), which
    # raises nothing where that bracket holds no sign change (every lane under
    # vmap without an event, and a rounding that keeps the guard's sign at the
    # step's end): the root is then the step's end. diffrax's own checks of its
    # arguments are traced as NaN (`errors_as_nan`).
    with errors_as_nan():
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(mode_field), diffrax.Dopri8(), 0.0, t_stop - c.t, None,
            (c.y, c.work), args, saveat=diffrax.SaveAt(t1=True),
            stepsize_controller=diffrax.PIDController(rtol=options.rtol, atol=options.atol),
            event=diffrax.Event(guard, Chandrupatla(atol=options.root_tol), direction=False),
            max_steps=options.max_steps, throw=False,
            # Forward mode: the segments run in a while loop, which reverse mode
            # cannot cross anyway; forward mode differentiates a run through every
            # event, its time by the implicit function theorem (optimistix's root
            # find), which gives the saltation matrix of each switch.
            adjoint=diffrax.ForwardMode(),
        )
    tau = sol.ts[-1]
    y, work = sol.ys[0][-1], sol.ys[1][-1]
    event = sol.event_mask
    ok = diffrax.is_okay(sol.result)
    code = jnp.where(sol.result == diffrax.RESULTS.max_steps_reached,
                     Status.max_steps_reached, Status.solver_failed)
    finite = jnp.where(jnp.all(jnp.isfinite(y)), Status.ok, Status.non_finite_state)
    code = jnp.where(ok, finite, code)

    stick_time = c.stick_time + jnp.where(observe & (c.modes == 0), tau, 0.0)
    t_new = jnp.where(event, c.t + tau, t_stop)
    observed = observe_sample(c.observed, t_new, y, params, options)
    y_new, modes, kind, _, resolved = switch(params, y, c.modes, sigma, observe,
                                             options.switch_tol)
    # An event that no guard accounts for would repeat forever: stop the run.
    code = jnp.where((code == Status.ok) & event & ~resolved, Status.event_not_resolved,
                     code)
    modes = jnp.where(event, modes, c.modes)
    y = jnp.where(event, y_new, y)
    # Event log: a ring buffer; the switching oscillators are appended in index order.
    logged = event & (kind >= 0)
    size = options.log_size
    slot = jnp.where(logged, (c.log_count + jnp.cumsum(logged) - 1) % size, size)
    return _Carry(
        t=t_new, y=y, work=work, modes=modes, observed=observed, stick_time=stick_time,
        log_time=c.log_time.at[slot].set(t_new, mode="drop"),
        log_osc=c.log_osc.at[slot].set(jnp.arange(params.n_osc), mode="drop"),
        log_kind=c.log_kind.at[slot].set(kind, mode="drop"),
        log_count=c.log_count + jnp.sum(logged), events=c.events + event,
        chunk_events=c.chunk_events + event, steps=c.steps + sol.stats["num_steps"],
        status=jnp.where(c.status == Status.ok, code, c.status),
    )


def _chunk(params, options, progress, observe, c: _Carry, t_stop) -> _Carry:
    """Advance to t_stop through as many event-separated segments as it takes
    (`observe`: see `_segment`)."""
    c = eqx.tree_at(lambda d: d.chunk_events, c, jnp.array(0))

    def cond(d):
        return (d.t < t_stop) & (d.status == Status.ok) & (d.chunk_events < options.max_events)

    c = jax.lax.while_loop(cond, lambda d: _segment(params, options, observe, t_stop, d),
                           c)
    status = jnp.where((c.status == Status.ok) & (c.t < t_stop),
                       Status.event_not_resolved, c.status)
    c = eqx.tree_at(lambda d: d.status, c, status)
    if progress:
        tick(c.t)
    return c


def _initial_carry(params: ChainParams, y0: State, options: NonsmoothOptions,
                   observed: tuple) -> _Carry:
    size = options.log_size
    return _Carry(
        t=jnp.array(0.0), y=y0, work=jnp.zeros(2), modes=initial_modes(params, y0),
        observed=observed, stick_time=jnp.zeros(params.n_osc),
        log_time=jnp.full(size, jnp.nan), log_osc=jnp.full(size, -1),
        log_kind=jnp.full(size, -1), log_count=jnp.array(0), events=jnp.array(0),
        chunk_events=jnp.array(0), steps=jnp.array(0),
        status=jnp.where(jnp.all(jnp.isfinite(y0)), Status.ok, Status.non_finite_state),
    )


def _run(params: ChainParams, y0: State, options: NonsmoothOptions,
         progress: bool) -> tuple[dict, _Carry]:
    """One trajectory event by event: what `Extrema` observed over the window (NaN
    where the run failed) and the final carry."""
    c = _initial_carry(params, y0, options,
                       tuple(o.init(y0, params, options) for o in _OBSERVERS))
    # One scan over the chunks of every phase (one compiled copy of a segment), each
    # chunk's end and whether it lies in the observed window as its inputs. A
    # sample at the start of the window is the end of the transient's last chunk;
    # the observers ignore the samples of the transient by their time.
    ends, observed = [], []
    for start, length, count, observe in options.phases(halves=True):
        ends.append(start + length * np.arange(1, count + 1))
        observed.append(np.full(count, observe))
    if not options.transient:  # the window's edge, where no segment ends
        c = eqx.tree_at(lambda d: d.observed, c,
                        observe_sample(c.observed, c.t, c.y, params, options))

    def body(d, chunk):
        t_stop, observe = chunk
        return _chunk(params, options, progress, observe, d, t_stop), None

    c, _ = jax.lax.scan(body, c, (jnp.asarray(np.concatenate(ends)),
                                  jnp.asarray(np.concatenate(observed))))

    ok = c.status == Status.ok
    (extrema,) = (no_partial_answers(o.result(s, _observers_args(params), options), ok)
                  for o, s in zip(_OBSERVERS, c.observed))
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


def run_nonsmooth(params: ChainParams, y0: State, options: NonsmoothOptions,
                  progress: bool = False) -> NonsmoothObservables:
    """Pure, traceable core of `simulate_nonsmooth` for one trajectory: no checks,
    no exceptions; vmap it for batches."""
    size = options.log_size
    extrema, c = _run(params, y0, options, progress)
    ok = c.status == Status.ok
    x_max, x_min = extrema["x_max_halves"], extrema["x_min_halves"]
    scale = jnp.maximum(1.0, jnp.max(extrema["amplitudes"]))
    half_difference = jnp.maximum(jnp.max(jnp.abs(x_max[0] - x_max[1])),
                                  jnp.max(jnp.abs(x_min[0] - x_min[1]))) / scale
    window = options.t_end - options.transient
    stick_fraction = jnp.where(ok, c.stick_time / window, jnp.nan)
    # Oldest first in the ring buffer of the log.
    order = (c.log_count + jnp.arange(size)) % size
    return NonsmoothObservables(
        amplitudes=extrema["amplitudes"], energy=extrema["energy"],
        on_halc=extrema["on_halc"], n_halc=extrema["n_halc"],
        min_slip_speed=extrema["min_slip_speed"], stick_fraction=stick_fraction,
        x_max=x_max, x_min=x_min, half_difference=half_difference, y_initial=y0,
        y_final=c.y, modes_final=c.modes, friction_work=c.work[0],
        viscous_dissipation=c.work[1], log_time=c.log_time[order],
        log_osc=c.log_osc[order], log_kind=c.log_kind[order], num_events=c.events,
        num_steps=c.steps, status=c.status,
    )


_run_jit = eqx.filter_jit(run_nonsmooth)


def simulate_nonsmooth(params: ChainParams, y0: AbstractInitialCondition | State,
                       options: NonsmoothOptions = NonsmoothOptions(), *,
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

    The state at every event and chunk end of the window is handed to the
    observers of the smoothed engine (`Extrema`, `observe_chunk`), so both engines
    compute their amplitudes, extrema and HALC alike.

    Every event (a switch, or a turning point of an oscillator while observing) is
    located by Chandrupatla's bracketed method (`Chandrupatla`, to
    `options.root_tol`) on diffrax's dense output of the smooth segment
    (`diffrax.Event`): the guards change sign at an event, so a bracket exists
    and the method cannot leave it.
    Time is measured from the segment start so
    that event times keep full precision. Smooth segments use Dopri8 at
    `options.rtol`. Several oscillators that switch at the same instant (within
    `options.switch_tol` on their guards) switch together: the force needed to
    stick depends on displacements only, so each decision is independent of the
    others. Switches in quick succession are separate events.

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


@eqx.filter_jit
def sampled_states(params: ChainParams, y0: State, ts, options: NonsmoothOptions):
    """The exact engine's states at the times `ts` (increasing, from t = 0) from the
    state `y0`, event by event, shape (len(ts), 2, n_osc), and the run's `Status`.
    Pure and traceable; differentiable in forward mode (`jax.jvp`, `jax.jacfwd`)
    through every switch with respect to `params` and `y0`."""

    def body(c, t):
        c = _chunk(params, options, False, False, c, t)
        return c, c.y

    c, ys = jax.lax.scan(body, _initial_carry(params, y0, options, ()), ts)
    return ys, c.status


def nonsmooth_trajectory(params: ChainParams, y0: AbstractInitialCondition | State,
                         ts: Float[Array, " m"],
                         options: NonsmoothOptions = NonsmoothOptions()
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
    ys, status = sampled_states(params, y0(params), jnp.asarray(ts), options)
    status = Status(int(status))
    if status is not Status.ok:
        raise RuntimeError(f"{status}: {status.message}")
    return ys
