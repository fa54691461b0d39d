"""The exact engine's event-driven integration: one adaptive Runge-Kutta step at a
time (diffrax's solver and step-size controller), the switches located on each
step's dense output, and the turning points of the oscillators read from it.

A step of the loop:

1. one step of the Runge-Kutta pair from t to t + dt (diffrax's `solver.step`),
   accepted or rejected by the PID controller (`adapt_step_size`), which also
   proposes the next dt;
2. if accepted and the smallest guard (`guard`) has fallen through zero, the
   switch time tau is located on the step's dense output by Chandrupatla's method
   (`Chandrupatla`), the state there is the dense output at tau, and the switching
   rule (`switch`) gives the new modes; the next step starts at tau with the
   solver's stored derivative discarded (`made_jump`: the vector field has
   changed), and with the step size the controller proposed;
3. while observing, every slipping oscillator whose velocity changes sign within
   the step has a turning point there, located on the dense output by Newton's
   method (all oscillators at once); the states at the turning points, at every
   switch and at every chunk end go to the observers. A turning point does not
   stop the integration.

The integration never restarts at a switch (no new initial step, no lost
step size), which is what makes the engine as fast as the smoothed one. Every
event time is a root of a smooth function on the dense output, and its
derivatives are those of the implicit function theorem (optimistix's
`ImplicitAdjoint`): forward-mode differentiation of a run goes through every
switch, and at each it applies the saltation matrix (Leine and Nijmeijer, 2004,
Section 7.1) without forming it.
"""

import math

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float, Int, PyTree

from ..._physics.custom_types import State
from ..._physics.model import Model
from ..._physics.params import ChainParams
from ..observers.base import Chunk, observe_chunk
from ..observers.extrema import Extrema
from ..progress import tick
from ..status import Status
from .root import Chandrupatla
from .switching import guard, initial_modes, mode_field, switch

#: The Runge-Kutta pairs of the exact engine, by the name `NonsmoothOptions.solver`
#: takes.
SOLVERS = {"tsit5": diffrax.Tsit5, "dopri5": diffrax.Dopri5, "dopri8": diffrax.Dopri8}

_TERM = diffrax.ODETerm(mode_field)

# Reverse mode evaluates the vector field through a LAPACK call (`_REVERSE_TERM`).
# jaxchain's XLA flag (`_setup.XLA_FLAGS`) lets XLA's CPU backend compile a while
# loop whose buffers are small into one kernel (its small-while-loop hoisting), and
# that kernel computed wrong values for some of the loops of a reverse-mode run
# under an outer `jax.jit`: the error estimates of the Runge-Kutta stage loops
# (hence other steps and switches), the cotangents of the stage loops inside a
# checkpointed loop's backward pass. The gradients of tests/test_saltation.py's
# ring of four were off by up to 0.72, and right without the flag or without the
# `jit`. XLA never hoists a loop that holds a custom call, so no loop of the step
# that evaluates the field, nor one around it, becomes such a kernel; forward-mode
# runs, whose loops compute right values, keep the kernels and their speed.


def _lapack_one() -> Float[Array, ""]:
    """1.0, from a LAPACK call (the Cholesky factor of [[1]]): a custom call, which
    XLA's CPU backend never hoists into a small-while-loop kernel."""
    return jnp.linalg.cholesky(jnp.ones((1, 1)))[0, 0]


@jax.custom_vjp
def _unhoisted(x):
    return x * _lapack_one()


def _unhoisted_fwd(x):
    return _unhoisted(x), None


def _unhoisted_bwd(_, ct):
    return (ct * _lapack_one(),)


_unhoisted.defvjp(_unhoisted_fwd, _unhoisted_bwd)


def _reverse_field(t, state, args):
    """`mode_field`, each value multiplied by 1.0 from a custom call in the forward and
    the backward pass (`_unhoisted`): no loop that evaluates it, nor one around such
    a loop, is compiled as a small-while-loop kernel."""
    return jax.tree.map(_unhoisted, mode_field(t, state, args))


_REVERSE_TERM = diffrax.ODETerm(_reverse_field)


def _term(options) -> diffrax.ODETerm:
    """The term of a run: `_REVERSE_TERM` for reverse mode."""
    return _REVERSE_TERM if options.adjoint == "reverse" else _TERM

#: Newton iterations that locate a turning point from the secant within a step:
#: the error squares at each, from the secant's O(h^2) to rounding in three.
_NEWTON = 4

#: What the exact engine observes (`Extrema`, with the halves of the window).
OBSERVERS = (Extrema(),)


#: How the loops of a run are built for each mode of differentiation
#: (`NonsmoothOptions.adjoint`): (the Runge-Kutta stages, the steps of a chunk).
#: Reverse mode runs the steps too in equinox's bounded loop (`_base`): faster to
#: compile and run than its checkpointed loop here (20 s against 26 s for the cycle
#: gradients of tests/test_nonsmooth.py).
_LOOPS = {"forward": ("lax", "lax"), "reverse": ("bounded", "bounded")}

#: The one line that reverse-mode differentiation of a forward-mode run raises
#: (`forward_only`), in place of JAX's own about `lax.while_loop`.
REVERSE_MODE_ADVICE = ("reverse-mode differentiation (jax.grad, jax.vjp) of the exact engine "
                       "needs NonsmoothOptions(adjoint='reverse'); the default, "
                       "adjoint='forward', runs loops that only forward mode (jax.jvp, "
                       "jax.jacfwd) differentiates")


def forward_only(c: "Carry") -> "Carry":
    """The carry after a forward-mode chunk, unchanged, its floating-point leaves
    marked so that transposing them (`jax.grad`, `jax.vjp`) raises
    `REVERSE_MODE_ADVICE` (equinox's `nondifferentiable_backward`). Reverse mode
    transposes a program from its outputs back, so every cotangent that would
    reach a chunk's `lax.while_loop` (which JAX cannot transpose) reaches its mark
    first. An identity in evaluation, `jax.jvp` and `vmap`: forward-mode runs are
    compiled as before."""
    dynamic, static = eqx.partition(c, eqx.is_inexact_array)
    return eqx.combine(eqxi.nondifferentiable_backward(dynamic, msg=REVERSE_MODE_ADVICE),
                       static)


def _solver(options) -> diffrax.AbstractAdaptiveSolver:
    """The Runge-Kutta pair, its stages in a loop that the run's mode of
    differentiation passes (as diffrax's `ForwardMode` and
    `RecursiveCheckpointAdjoint` set them)."""
    return SOLVERS[options.solver](scan_kind=_LOOPS[options.adjoint][0])


def _controller(options) -> diffrax.PIDController:
    return diffrax.PIDController(rtol=options.rtol, atol=options.atol)


class Carry(eqx.Module):
    """The state of a run between steps."""

    t: Float[Array, ""]
    y: State
    work: Float[Array, "2"]
    modes: Float[Array, " n_osc"]
    dt: Float[Array, ""]
    solver_state: PyTree
    controller_state: PyTree
    made_jump: Array
    observed: tuple
    stick_time: Float[Array, " n_osc"]
    log_time: Float[Array, " log"]
    log_kind: Int[Array, "log n_osc"]
    events: Int[Array, ""]
    chunk_events: Int[Array, ""]
    steps: Int[Array, ""]
    chunk_steps: Int[Array, ""]
    status: Int[Array, ""]


def observers_args(params: ChainParams) -> Model:
    """The model as the observers see it: eps = 0, since the exact engine has no
    smoothing (its stick band is v_rel = 0, `sticks`)."""
    return Model(params, jnp.zeros(()))


def observe_samples(states: tuple, ts, ys, params: ChainParams, options) -> tuple:
    """The observers' states after the located samples `ys` at the times `ts`
    (samples at a time outside the window, such as -inf, are not seen): a chunk
    through `observe_chunk`, the route of the smoothed engine."""
    chunk = Chunk(t0=jnp.min(ts), t1=jnp.max(ts), ts=ts, ys=ys, log_growth=None)
    return observe_chunk(OBSERVERS, states, chunk, observers_args(params), options)


def initial_carry(params: ChainParams, y0: State, options, observed: tuple) -> Carry:
    """The carry at t = 0: the modes of `initial_modes`, the first step chosen by
    the controller and the solver's initial state, as `diffrax.diffeqsolve` makes
    them (not differentiated, as there)."""
    solver, controller = _solver(options), _controller(options)
    modes = initial_modes(params, y0)
    state = (y0, jnp.zeros(2))
    tnext, controller_state = controller.init(_term(options), 0.0, options.t_end, state, None,
                                              (params, modes), solver.func,
                                              solver.error_order(_term(options)))
    solver_state = solver.init(_term(options), 0.0, tnext, state, (params, modes))
    dt, solver_state, controller_state = jax.lax.stop_gradient(
        (jnp.asarray(tnext, float), solver_state, controller_state))
    size = options.log_size
    zero = jnp.array(0)
    return Carry(
        t=jnp.array(0.0), y=y0, work=state[1], modes=modes, dt=dt,
        solver_state=solver_state, controller_state=controller_state,
        made_jump=jnp.array(False), observed=observed,
        stick_time=jnp.zeros(params.n_osc), log_time=jnp.full(size, jnp.nan),
        log_kind=jnp.full((size, params.n_osc), -1),
        events=zero, chunk_events=zero, steps=zero, chunk_steps=zero,
        status=jnp.where(jnp.all(jnp.isfinite(y0)), Status.ok, Status.non_finite_state),
    )


def _root(fn, t0, t1, tol):
    """The root of fn on [t0, t1] (fn(t0) > 0 >= fn(t1); else t1), Chandrupatla's
    method (its value: `_switch_point` gives its derivatives)."""
    return optx.root_find(lambda t, _: fn(t), Chandrupatla(atol=tol), t1,
                          options=dict(lower=t0, upper=t1), throw=False).value


def _turning_points(interp, c: Carry, y_end, t0, t_end):
    """The turning points of the slipping oscillators within [t0, t_end]: where x_n'
    changes sign, located on the dense output by Newton's method from the secant
    (`_NEWTON` iterations, all oscillators at once, kept within the step); (times,
    states), shape (n_osc,) and (n_osc, 2, n_osc), time -inf where an oscillator
    has none. The times carry no derivative: an extremum's derivative is that of x
    at fixed time, x' being 0 there."""
    v0, v1 = c.y[1], y_end[1]
    turns = (c.modes != 0) & (v0 * v1 < 0)
    osc = jnp.arange(v0.size)

    def newton(t, n):
        v, a = jax.jvp(lambda s: interp.evaluate(s)[0][1, n], (t,), (jnp.ones_like(t),))
        return jnp.clip(t - v / jnp.where(a == 0, 1.0, a), t0, t_end)

    def locate():
        t = t0 + (t_end - t0) * jnp.where(turns, v0 / (v0 - v1), 0.5)
        for _ in range(_NEWTON):
            t = jax.vmap(newton)(t, osc)
        t = jax.lax.stop_gradient(t)
        return jnp.where(turns, t, -jnp.inf), jax.vmap(lambda s: interp.evaluate(s)[0])(t)

    def none():
        return (jnp.full(v0.shape, -jnp.inf), jnp.broadcast_to(y_end, v0.shape + y_end.shape))

    return jax.lax.cond(jnp.any(turns), locate, none)


def _switch_point(interp, params, modes, t0, t1, tol, held):
    """The switch within a step: its time, the root of the smallest guard on the
    step's dense output (Chandrupatla's method, `_root`), and the state (y, work)
    there. Their derivatives are those of the implicit function theorem written
    out: d tau = -dg / (dg/dt), with g the guard at the dense output's state at
    the fixed root and dg/dt the guard's rate along the vector field there, not
    along the interpolating polynomial, whose slope is a few orders less accurate
    (it would enter the saltation matrix of a slip reversal, whose acceleration
    jumps); the state there moves with tau along the vector field. One vector
    field evaluation per switch."""
    fixed = jax.lax.stop_gradient(
        _root(lambda t: guard(params, interp.evaluate(t)[0], modes, held), t0, t1, tol))
    state = interp.evaluate(fixed)
    rate = mode_field(fixed, state, (params, modes))
    g, g_rate = jax.jvp(lambda y: guard(params, y, modes, held), (state[0],), (rate[0],))
    # the shift's value is 0; a tangential guard (rate 0, where no derivative
    # exists) or a branch that vmap computes in a lane without a switch (whose
    # values may not be finite) leaves the time and the state as they are
    inverse = jax.lax.stop_gradient(1.0 / jnp.where(g_rate == 0, 1.0, g_rate))
    shift = jnp.where(jnp.isfinite(g) & jnp.isfinite(inverse),
                      (g - jax.lax.stop_gradient(g)) * inverse, 0.0)
    tau = fixed - shift
    return tau, jax.tree.map(lambda y, r: y - jnp.where(jnp.isfinite(r), r, 0.0) * shift,
                             state, rate)


#: Interior points of each step at which the guard is checked as well as at its
#: end, as DifferentialEquations.jl's `ContinuousCallback` checks `interp_points`
#: (10 by default): a guard that falls through zero and rises again within one
#: step is seen where it is below zero at one of them.
_INTERIOR = 10


def _first_fall(interp, params, modes, t0, t1, y0, y_end, held):
    """(t, fallen): the first of the step's interior points (`_INTERIOR`, evenly
    spaced on its dense output) or its end where the smallest guard is <= 0, and
    whether there is one; the step's end and False if none. The switch lies
    between t0 and that point.

    The interior points are looked at only where a slip guard can dip below zero
    inside the step: some slipping oscillator approaches the belt speed at the
    step's start and recedes from it at its end (its relative velocity has an
    extremum inside), with its guard at both ends within h max|x''| of zero (no
    deeper dip fits in the step). Elsewhere, on most steps, the check costs two
    slopes of the dense output."""
    at_end = guard(params, y_end, modes, held) <= 0
    h = t1 - t0

    def slope(t):
        return jax.jvp(lambda s: interp.evaluate(s)[0][1], (t,), (jnp.ones_like(t),))[1]

    a0, a1 = slope(t0), slope(t1)
    g0, g1 = modes * (y0[1] - params.v_d), modes * (y_end[1] - params.v_d)
    dip = ((modes != 0) & (modes * a0 < 0) & (modes * a1 > 0)
           & (jnp.minimum(g0, g1) <= h * jnp.maximum(jnp.abs(a0), jnp.abs(a1))))

    def inside():
        ts = t0 + h * jnp.arange(1, _INTERIOR + 1) / (_INTERIOR + 1)
        fallen = jax.vmap(lambda t: guard(params, interp.evaluate(t)[0], modes, held))(ts) <= 0
        return ts[jnp.argmax(fallen)], fallen.any()

    t, fallen = jax.lax.cond(jnp.any(dip), inside, lambda: (t1, jnp.array(False)))
    # a bracket only (the switch time's derivative is the implicit function
    # theorem's, `_switch_point`); the step's own end keeps its derivative
    return jnp.where(fallen, jax.lax.stop_gradient(t), t1), fallen | at_end


class _Attempt(eqx.Module):
    """One Runge-Kutta step from the carry's time, before any switch is located:
    its span [t0, t1], its end (y, work), whether the controller keeps it, the
    solver's and the controller's states after it, the step size the controller
    proposes next, the step's dense output, and whether the solver and the
    controller succeeded."""

    t0: Float[Array, ""]
    t1: Float[Array, ""]
    end: tuple
    keep: Array
    solver_state: PyTree
    controller_state: PyTree
    next_dt: Float[Array, ""]
    interp: diffrax.AbstractLocalInterpolation
    solved: Array


def _attempt(params: ChainParams, options, t_stop, c: Carry) -> _Attempt:
    """Item 1 of the loop (see the module docstring): one step of the Runge-Kutta
    pair from c.t by c.dt, cut at `t_stop`, judged by the PID controller."""
    solver, controller = _solver(options), _controller(options)
    args = (params, c.modes)
    t0 = c.t
    t1 = c.t + c.dt
    # the chunk's end is a step's end (within 100 units of rounding, as diffrax)
    t1 = jnp.where(t1 > t_stop - 100 * jnp.finfo(float).eps * abs(t_stop), t_stop, t1)
    start = (c.y, c.work)
    end, error, dense, solver_state, solver_result = solver.step(
        _term(options), t0, t1, start, args, c.solver_state, c.made_jump)
    error = jax.tree.map(lambda e: jnp.where(jnp.isnan(e), jnp.inf, e), error)
    keep, next_t0, next_t1, _, controller_state, controller_result = \
        controller.adapt_step_size(t0, t1, start, end, args, error,
                                   solver.error_order(_term(options)), c.controller_state)
    return _Attempt(
        t0=t0, t1=t1, end=end, keep=keep, solver_state=solver_state,
        controller_state=controller_state, next_dt=next_t1 - next_t0,
        interp=solver.interpolation_cls(t0=t0, t1=t1, **dense),
        solved=diffrax.is_okay(solver_result) & diffrax.is_okay(controller_result))


def _located(params: ChainParams, options, observe, c: Carry, a: _Attempt, t1, event,
             at_end) -> tuple:
    """Items 2 and 3 of the loop on a kept step that ends at `t1` (the first fall
    of the guard, `_first_fall`), switches (`event`), ends the chunk (`at_end`) or
    holds a turning point: the switch (its time, the state there, the new modes),
    the turning points before it, and the samples observed; (tau, y, work,
    observed) + `switch`'s (y, modes, kind, resolved)."""
    tau, (y, work) = jax.lax.cond(
        event, lambda: _switch_point(a.interp, params, c.modes, a.t0, t1, options.root_tol,
                                     options.held),
        lambda: (t1, a.end))
    turn_ts, turn_ys = jax.lax.cond(
        observe, lambda: _turning_points(a.interp, c, y, a.t0, tau),
        lambda: (jnp.full(c.modes.shape, -jnp.inf),
                 jnp.broadcast_to(y, c.modes.shape + y.shape)))
    sample_t = jnp.where((observe & event) | at_end, tau, -jnp.inf)
    observed = observe_samples(c.observed, jnp.append(turn_ts, sample_t),
                               jnp.concatenate([turn_ys, y[None]]), params, options)
    switched = jax.lax.cond(
        event, lambda: switch(params, y, c.modes, options.switch_tol, options.held),
        lambda: (y, c.modes, jnp.full(c.modes.shape, -1), jnp.array(True)))
    return (tau, y, work, observed) + switched


def _events(params: ChainParams, options, observe, t_stop, c: Carry, a: _Attempt) -> tuple:
    """The step's events: the earliest switch within it (the smallest guard
    fallen through 0 at the step's end or at one of its interior points on the
    dense output, `_first_fall`: a slip phase that touches v_rel = 0 and turns
    back within one step has both ends positive), the step then ending at the
    first such point; the chunk's end; the turning points. (event, (tau, y,
    work, observed, y_switched, modes, kind, resolved)), through `_located` where
    any of them happens and the step's end as it is elsewhere."""
    t1, event = _first_fall(a.interp, params, c.modes, a.t0, a.t1, c.y, a.end[0], options.held)
    event = a.keep & event
    at_end = a.keep & (t1 >= t_stop)
    turning = observe & a.keep & jnp.any((c.modes != 0) & (c.y[1] * a.end[0][1] < 0))

    def plain():
        return (t1, a.end[0], a.end[1], c.observed, a.end[0], c.modes,
                jnp.full(c.modes.shape, -1), jnp.array(True))

    return event, jax.lax.cond(
        event | at_end | turning,
        lambda: _located(params, options, observe, c, a, t1, event, at_end), plain)


def _status(a: _Attempt, y, event, resolved) -> Int[Array, ""]:
    """The step's status: the solver's or the controller's failure; a kept state
    that is not finite (a rejected step may overflow: the controller then
    shortens it); a switch that no guard accounts for, which would repeat forever."""
    code = jnp.where(a.solved,
                     jnp.where(~a.keep | jnp.all(jnp.isfinite(y)), Status.ok,
                               Status.non_finite_state),
                     Status.solver_failed)
    return jnp.where((code == Status.ok) & event & ~resolved, Status.event_not_resolved,
                     code)


def _logged(c: Carry, options, event, tau, kind) -> tuple:
    """The switch log after the step, (log_time, log_kind): a ring buffer of switch
    instants, the time and every oscillator's kind of switch (a row written in
    place; a scatter of the switching oscillators into a list costs more than the
    step)."""
    row = c.events % options.log_size
    log_time = jax.lax.dynamic_update_index_in_dim(
        c.log_time, jnp.where(event, tau, c.log_time[row]), row, 0)
    log_kind = jax.lax.dynamic_update_index_in_dim(
        c.log_kind, jnp.where(event, kind, c.log_kind[row]), row, 0)
    return log_time, log_kind


def _step(params: ChainParams, options, observe, t_stop, c: Carry) -> Carry:
    """One step of the loop (see the module docstring): the Runge-Kutta step
    (`_attempt`), its events (`_events`), its status (`_status`) and the switch
    log (`_logged`). `observe` (traced: the chunk lies in the observed window) adds
    the turning points and counts the stick time; the observers take only samples
    in their window, by time."""
    a = _attempt(params, options, t_stop, c)
    event, (tau, y, work, observed, y_switched, modes, kind, resolved) = _events(
        params, options, observe, t_stop, c, a)
    keep = a.keep
    log_time, log_kind = _logged(c, options, event, tau, kind)
    return Carry(
        t=jnp.where(keep, tau, a.t0),
        y=jnp.where(event, y_switched, jnp.where(keep, y, c.y)),
        work=jnp.where(keep, work, c.work),
        modes=jnp.where(event, modes, c.modes),
        # the step sizes carry no derivative (as the initial one, and diffrax's
        # step factor): the grid shifts with each switch time, and no more, else a
        # step cut short at a chunk's end would amplify its time's derivative as
        # the steps grow again
        dt=jax.lax.stop_gradient(a.next_dt),
        solver_state=jax.tree.map(lambda new, old: jnp.where(keep, new, old), a.solver_state,
                                  c.solver_state),
        controller_state=a.controller_state,
        made_jump=event | (c.made_jump & ~(keep & a.solved)),
        observed=observed,
        stick_time=c.stick_time + jnp.where(observe & keep & (c.modes == 0), tau - a.t0, 0.0),
        log_time=log_time, log_kind=log_kind,
        events=c.events + event,
        chunk_events=c.chunk_events + event, steps=c.steps + 1,
        chunk_steps=c.chunk_steps + 1,
        status=jnp.where(c.status == Status.ok, _status(a, y, event, resolved), c.status),
    )


def _base(max_steps: int) -> int:
    """The length of each of the two nested scans of a bounded loop that covers
    `max_steps`: sqrt(max_steps), so that the backward pass keeps about 2
    sqrt(max_steps) states and recomputes each step once more (two-level
    checkpointing; sixteen, equinox's default, nests five levels for the default
    budget and takes twice the time to compile and run)."""
    return max(2, math.isqrt(max_steps - 1) + 1)


def chunk(params: ChainParams, options, progress: bool, observe, c: Carry, t_stop) -> Carry:
    """Advance to t_stop, step by step through every switch (`observe`: see
    `_step`); the step budget (`max_steps`) and the switch budget (`max_events`,
    more means chattering) are per chunk. For reverse-mode differentiation the
    steps run in equinox's bounded loop: two nested scans of sqrt(`max_steps`)
    steps (`_base`), the outer checkpointed, so that the backward pass keeps about
    2 sqrt(`max_steps`) states and recomputes the others (two-level checkpointing,
    Griewank and Walther, "Evaluating Derivatives", 2nd ed., SIAM 2008, Ch. 12):
    memory does not grow with the steps taken, nor with the chunks of a run."""
    c = eqx.tree_at(lambda d: (d.chunk_events, d.chunk_steps), c,
                    (jnp.array(0), jnp.array(0)))

    def cond(d):
        return ((d.t < t_stop) & (d.status == Status.ok)
                & (d.chunk_events < options.max_events) & (d.chunk_steps < options.max_steps))

    kind = _LOOPS[options.adjoint][1]
    c = eqxi.while_loop(cond, lambda d: _step(params, options, observe, t_stop, d), c,
                        max_steps=None if kind == "lax" else options.max_steps,
                        kind=kind, base=_base(options.max_steps))
    if kind == "lax":
        c = forward_only(c)
    status = jnp.where((c.status == Status.ok) & (c.t < t_stop),
                       jnp.where(c.chunk_steps >= options.max_steps, Status.max_steps_reached,
                                 Status.event_not_resolved), c.status)
    c = eqx.tree_at(lambda d: d.status, c, status)
    if progress:
        tick(c.t)
    return c
