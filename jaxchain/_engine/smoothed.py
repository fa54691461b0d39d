"""The smoothed engine's integration of one trajectory of eq. (5) with diffrax,
observing while integrating (friction smoothed by tanh(v_rel/eps))."""

import dataclasses
from collections.abc import Sequence

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Int, PyTree

from .compat import errors_as_nan
from .solver.controller import step_size_controller
from .._physics.custom_types import State
from .status import SMOOTHED_BALANCE_FLOOR, Status, balance_status
from .._physics.forces import smoothed_friction_force
from .._physics.friction import concrete
from .._physics.model import Model, model_field, model_split_field
from .observables import EXACT_FIELDS, Observables
from .observers.base import AbstractObserver, Chunk, no_partial_answers, observe_chunk
from .observers.extrema import Extrema
from .options import DEFAULT_ATOL, DEFAULT_RTOL, SimulationOptions
from .._physics.params import ChainParams
from .progress import tick
from .solver.rosenbrock import Ros34PW2


def _status_code(result, collapsed) -> Int[Array, ""]:
    """The `Status` of one chunk's diffrax result; a chunk out of steps whose steps
    had `collapsed` (shorter than `options.dtmin` on average) is
    `Status.step_size_collapsed`."""
    out_of_steps = jnp.where(collapsed, Status.step_size_collapsed,
                             Status.max_steps_reached)
    return jnp.where(result == diffrax.RESULTS.successful, Status.ok,
                     jnp.where(result == diffrax.RESULTS.max_steps_reached,
                               out_of_steps, Status.solver_failed))


#: Solvers that take eq. (5) split in two: IMEX solvers treat the friction force
#: implicitly, `Ros34PW2` builds its W matrix from the friction's diagonal Jacobian.
SPLIT_SOLVERS = (diffrax.KenCarp3, diffrax.KenCarp4, diffrax.KenCarp5, Ros34PW2)


def terms(solver: diffrax.AbstractSolver):
    """The diffrax terms of eq. (5) for `solver`: one `ODETerm`, or for a solver of
    `SPLIT_SOLVERS` a `MultiTerm` of the non-stiff elastic part and the stiff
    friction part (`split_vector_field`)."""
    if isinstance(solver, SPLIT_SOLVERS):
        return diffrax.MultiTerm(
            diffrax.ODETerm(lambda t, y, m: model_split_field(t, y, m)[0]),
            diffrax.ODETerm(lambda t, y, m: model_split_field(t, y, m)[1]))
    return diffrax.ODETerm(model_field)


def _work_rows(t, z, model: Model):
    """The rows of the work integrals: the power of friction F_n x_n' (and of the
    harmonic force f_n(t) x_n' of a forced chain) and the viscous dissipation
    2 xi_n x_n'^2 of each oscillator (F_n the smoothed friction force, eq. (2) with
    tanh(v_rel/eps); their sums are the rates in the energy balance of
    `mechanical_energy`)."""
    params, v = model.params, z[1]
    force = smoothed_friction_force(params, v - params.v_d, model.eps)
    if params.forcing is not None:
        force = force + params.forcing.force(t)
    return jnp.stack([v * force, 2 * params.xi * v**2])


def _elastic_with_work(t, z, model):
    return jnp.concatenate([model_split_field(t, z[:2], model)[0], _work_rows(t, z, model)])


def _friction_with_work(t, z, model):
    return jnp.concatenate([model_split_field(t, z[:2], model)[1], jnp.zeros_like(z[2:])])


def _field_with_work(t, z, model):
    return jnp.concatenate([model_field(t, z[:2], model), _work_rows(t, z, model)])


def _with_work(solver: diffrax.AbstractSolver):
    """The terms of eq. (5) on a state of shape (4, n_osc): x, x' and the work
    integrals of `_work_rows`, which feed nothing back. For a solver of
    `SPLIT_SOLVERS` the work rows are in the non-stiff term (the stiff term's
    Jacobian stays diagonal). Module-level functions: one compiled run per solver."""
    if isinstance(solver, SPLIT_SOLVERS):
        return diffrax.MultiTerm(diffrax.ODETerm(_elastic_with_work),
                                 diffrax.ODETerm(_friction_with_work))
    return diffrax.ODETerm(_field_with_work)


def _state_norm(error):
    """The error norm of a state with work rows: the RMS norm of x and x' only (the
    rows 0 and 1), so that the work integrals do not move the steps."""
    return optx.rms_norm(error[:2])


def _controller(options: SimulationOptions, work: bool):
    """The step-size controller of `options`; with `work` rows in the state, its
    error norm is that of x and x' alone (`_state_norm`)."""
    controller = step_size_controller(options)
    return dataclasses.replace(controller, norm=_state_norm) if work else controller


def _balanced(solver: diffrax.AbstractSolver) -> bool:
    """Whether a run with `solver` integrates the work integrals beside the state
    (`_with_work`): every solver but `Ros34PW2(block=True)`, whose W takes a state
    of two rows."""
    return not getattr(solver, "block", False)


def _advance(terms_, solver, args, options, observers, progress, tangent, carry, t0, t1,
             n_samples, work=False):
    """Integrate one chunk [t0, t1] and hand it to the observers: its `n_samples`
    dense samples (if any) and, with a `tangent` (static) carried beside the state,
    the log of its growth (it is then renormalised)."""
    y, solver_state, controller_state, made_jump, states, steps, status = carry
    # Once a chunk has failed the rest of the run is skipped (a zero-length solve),
    # so a failed lane does not hold up the others under vmap.
    t1 = jnp.where(status == Status.ok, t1, t0)
    subs = [diffrax.SubSaveAt(t1=True)]
    ts = None
    if n_samples:
        ts = t0 + (t1 - t0) * jnp.linspace(0.0, 1.0, n_samples)
        subs.append(diffrax.SubSaveAt(ts=ts))
    if tangent:
        # The solver state holds f of the state, stale once the tangent is rescaled:
        # it starts afresh each chunk (one more evaluation of f per chunk).
        solver_state = None
    with errors_as_nan():  # diffrax's checks of its arguments: no host callback
        sol = diffrax.diffeqsolve(
            terms_, solver, t0, t1, None, y, args,
            saveat=diffrax.SaveAt(subs=subs, solver_state=True, controller_state=True,
                                  made_jump=True),
            stepsize_controller=_controller(options, work),
            max_steps=options.max_steps, throw=False,
            solver_state=solver_state, controller_state=controller_state,
            made_jump=made_jump,
        )
    y_end = sol.ys[0][-1]
    samples = None if ts is None else sol.ys[1]
    log_growth = None
    if tangent:
        norm = jnp.sqrt(jnp.sum(y_end[1] ** 2))
        log_growth = jnp.log(norm)
        y_end = jnp.stack([y_end[0], y_end[1] / norm])
        samples = None if ts is None else samples[:, 0]
    if work and ts is not None:
        samples = samples[:, :2]
    chunk = Chunk(t0=t0, t1=t1, ts=ts, ys=samples, log_growth=log_growth)
    states = observe_chunk(observers, states, chunk, args, options)
    state_end = y_end[0] if tangent else y_end[:2]
    # Where a failed solve stopped: its t1 save holds the time it reached.
    mean_step = (sol.ts[0][-1] - t0) / jnp.maximum(sol.stats["num_steps"], 1)
    code = jnp.where(jnp.all(jnp.isfinite(state_end)),
                     _status_code(sol.result, mean_step < options.dtmin),
                     Status.non_finite_state)
    status = jnp.where(status == Status.ok, code, status)
    if progress:
        tick(jnp.ravel(y_end)[0])
    return (y_end, sol.solver_state, sol.controller_state, sol.made_jump, states,
            steps + sol.stats["num_steps"], status)


def _with_tangent(terms_):
    """The terms of the state and a tangent vector, stacked on a new leading axis:
    each `ODETerm` f becomes (f(y), J(y) u) with J u by `jax.jvp` (the variational
    equation). The state under the Jacobian is held constant
    (`lax.stop_gradient`): derivatives of the stacked field, as a solver takes
    them for its implicit or W matrix, then see J on both blocks and not the
    second derivative of f, which such matrices may leave out. Elementwise solvers
    (`Ros34PW2`) get their diagonal right on both blocks."""
    if isinstance(terms_, diffrax.MultiTerm):
        return diffrax.MultiTerm(*(_with_tangent(t) for t in terms_.terms))
    vf = terms_.vector_field

    def field(t, yu, args):
        y, u = yu[0], yu[1]
        _, ju = jax.jvp(lambda z: vf(t, z, args), (jax.lax.stop_gradient(y),), (u,))
        return jnp.stack([vf(t, y, args), ju])

    return diffrax.ODETerm(field)


def _initial_states(terms_, solver: diffrax.AbstractSolver, y0: PyTree, args: PyTree,
                    options: SimulationOptions, t0, t1, work: bool = False
                    ) -> tuple[PyTree, PyTree]:
    """The solver's and the step-size controller's states at the start of a run, as
    `diffrax.diffeqsolve` makes them when it is given none (each one's `init`, the
    controller choosing the first step), for the first chunk [t0, t1]: so that the
    first chunk too is a step of the scan over chunks, and the run compiles one copy
    of the solve per phase instead of two. Not differentiated (diffrax stops the
    gradient of the states it makes itself)."""
    controller = _controller(options, work)
    tnext, controller_state = controller.init(terms_, t0, t1, y0, None, args, solver.func,
                                              solver.error_order(terms_))
    solver_state = solver.init(terms_, t0, jnp.minimum(tnext, t1), y0, args)
    return jax.lax.stop_gradient((solver_state, controller_state))


def _spans(options: SimulationOptions) -> list[tuple[float, float, int, int]]:
    """The phases of a run (`AbstractHorizon.phases`) as (start, chunk length,
    number of chunks, samples per chunk): the transient (not sampled), then the
    observed window."""
    return [(start, length, count,
             int(np.ceil(length / options.sample_dt)) + 1 if observed else 0)
            for start, length, count, observed in options.phases()]


def integrate(terms_, solver: diffrax.AbstractSolver, y0: PyTree, args: PyTree,
              options: SimulationOptions, observers: Sequence[AbstractObserver],
              progress: bool = False, work: bool = False
              ) -> tuple[tuple[dict, ...], PyTree, Array, Array]:
    """Integrate any ODE in chunks, observing while integrating: the pure,
    traceable engine under `run` and `observe`, not specific to the chain.

    The run is integrated with `diffrax.diffeqsolve` in chunks (see
    `SimulationOptions.chunks`), carrying the solver and step-size-controller
    states across chunks. After each chunk, outside the step loop, every observer
    gets the chunk's dense samples (every `sample_dt` after `options.transient`)
    and reduces them into its state of fixed size: memory never grows with
    `t_end`. If an observer `needs_tangent`, a tangent vector u is integrated
    beside the state by the variational equation u' = J(y) u (`jax.jvp` of the
    vector field; `_with_tangent`), under the same error control, and
    renormalised after each chunk.

    With `work`, the chain's work integrals are integrated beside the state (the
    terms are those of `_with_work`, on a state of shape (4, n_osc); the error
    norm is that of x and x' alone, so the steps are those of the run without
    them), and a run whose energy balance fails is `Status.energy_balance_failed`
    (`balance_status`).

    **Arguments:**

    - `terms_`: diffrax terms of the ODE; `args` is passed to them.
    - `solver`, `options`: the diffrax solver and `SimulationOptions`.
    - `y0`: the initial state (an array).
    - `observers`: the observers (`AbstractObserver`).
    - `progress` (static): tick the active progress bar once per chunk.
    - `work` (static): the terms carry the work rows of `_with_work` (`args` a
        `Model`); not with an observer that `needs_tangent`.

    **Returns:**

    (results, y_final, num_steps, status): one dict per observer (NaN, -1 or False
    where the run failed), the state at t_end (or where it stopped), the steps
    taken and the `Status` (its integer value).
    """
    status = jnp.where(jnp.all(jnp.isfinite(y0)), Status.ok, Status.non_finite_state)
    states = tuple(o.init(y0, args, options) for o in observers)
    lyapunov = [o for o in observers if o.needs_tangent]
    tangent = bool(lyapunov)
    y = y0
    if tangent:
        y = jnp.stack([y0, lyapunov[0].initial_tangent(y0)])
        terms_ = _with_tangent(terms_)
    if work:
        y = jnp.concatenate([y0, jnp.zeros_like(y0)])
    spans = _spans(options)
    solver_state, controller_state = _initial_states(terms_, solver, y, args, options,
                                                     spans[0][0], spans[0][0] + spans[0][1],
                                                     work)
    carry = (y, solver_state, controller_state, jnp.array(False), states, jnp.array(0),
             status)
    # Every chunk of a phase is one step of its scan, the first too (its solver and
    # controller states made above): one compiled copy of the solve per phase.
    for start, length, count, samples in spans:
        t0s = start + length * jnp.arange(count)

        def body(c, t0, length=length, samples=samples):
            return _advance(terms_, solver, args, options, observers, progress,
                            tangent, c, t0, t0 + length, samples, work), None

        carry, _ = jax.lax.scan(body, carry, t0s)
    y_final, _, _, _, states, steps, status = carry
    if tangent:
        y_final = y_final[0]
    if work:
        y_final, (friction_work, dissipation) = y_final[:2], jnp.sum(y_final[2:], axis=-1)
        status = balance_status(status, args.params, y0, y_final, friction_work,
                                dissipation, options.rtol, options.atol,
                                SMOOTHED_BALANCE_FLOOR)
    ok = status == Status.ok
    results = tuple(no_partial_answers(o.result(s, args, options), ok)
                    for o, s in zip(observers, states))
    return results, y_final, steps, status


def _unverified(options: SimulationOptions) -> bool:
    """Whether a run's tolerances are looser than `DEFAULT_RTOL` or `DEFAULT_ATOL`, the
    loosest at which the cross-check against the exact engine holds (every n_HALC
    agrees): such a run is audited by its energy balance. Runs at or inside them
    are not (the work rows cost about 40 % per step on the Fig. 4 chain).
    Tolerances that are not concrete (traced) are the engine's own, inside them."""
    values = [concrete(v) for v in (options.rtol, options.atol)]
    if any(v is None for v in values):
        return False
    rtol, atol = (float(np.max(v)) for v in values)
    return rtol > DEFAULT_RTOL or atol > DEFAULT_ATOL


def _integrate_chain(params: ChainParams, eps, y0: State, solver: diffrax.AbstractSolver,
                     options: SimulationOptions, observers: tuple, progress: bool):
    """`integrate` eq. (5) at the smoothing velocity `eps`, with its energy balance
    checked (`work`) where its tolerances are looser than those the cross-check
    verified (`_unverified`), unless an observer needs a tangent or the solver
    cannot carry the work rows (`_balanced`)."""
    work = (_unverified(options) and _balanced(solver)
            and not any(o.needs_tangent for o in observers))
    return integrate(_with_work(solver) if work else terms(solver), solver, y0,
                     Model(params, eps), options, observers, progress, work)


def run(params: ChainParams, eps, y0: State, solver: diffrax.AbstractSolver,
        options: SimulationOptions, progress: bool = False) -> Observables:
    """Pure, traceable core of `simulate` for one trajectory: the `Extrema` of eq.
    (5) at the smoothing velocity `eps` by `integrate`; no checks, no exceptions.
    `run_lanes` maps it over lanes. With `progress` (static), each chunk ticks the
    active progress bar through a host callback."""
    (extrema,), y_final, steps, status = _integrate_chain(params, eps, y0, solver, options,
                                                          (Extrema(),), progress)
    kept = {f.name for f in dataclasses.fields(Observables)} - set(EXACT_FIELDS)
    return Observables(**{k: v for k, v in extrema.items() if k in kept},
                       y_initial=y0, y_final=y_final, num_steps=steps, status=status)


def run_observers(params: ChainParams, eps, y0: State, solver: diffrax.AbstractSolver,
                  options: SimulationOptions, observers: Sequence[AbstractObserver],
                  progress: bool = False) -> dict[str, Array]:
    """Pure, traceable core of `observe`: one trajectory of eq. (5) with the given
    observers only, at the smoothing velocity `eps`; `run_lanes` maps it over lanes.

    **Returns:**

    Every observer's results by name, with `y_initial`, `y_final`, `num_steps` and
    `status` (see `Observables`).
    """
    results, y_final, steps, status = _integrate_chain(params, eps, y0, solver, options,
                                                       observers, progress)
    merged = {"y_initial": y0, "y_final": y_final, "num_steps": steps, "status": status}
    for r in results:
        merged |= r
    return merged
