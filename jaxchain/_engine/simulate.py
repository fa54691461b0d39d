"""The entry points of one trajectory, `simulate` and `observe`, for either engine."""

from collections.abc import Sequence

import diffrax
import equinox as eqx
from jaxtyping import Array

from .checks import check_params
from .engines import AbstractEngine, as_engine
from .horizon import AbstractHorizon
from .._physics.custom_types import State
from .status import Status
from .._physics.initial import AbstractInitialCondition, GivenState
from .observables import Observables, check_observers
from .observers.base import AbstractObserver
from .options import SimulationOptions
from .programs import compiled
from .progress import progress_bar
from .._physics.params import ChainParams, without_records


def _run(params: ChainParams, y0: State, engine: AbstractEngine,
         progress: bool = False) -> Observables:
    return engine.run(params, y0, progress)


_run_jit = eqx.filter_jit(_run)


def simulate(params: ChainParams, y0: AbstractInitialCondition | State,
             solver: diffrax.AbstractSolver | str | None = None,
             options: AbstractHorizon | None = None, *,
             engine: AbstractEngine | str = "smoothed", throw: bool = True,
             progress: bool = False) -> Observables:
    """Integrate eq. (5) of the paper for one trajectory and return its observables,
    with the smoothed engine (`Smoothed`, the default) or the exact one (`Exact`).

    With the smoothed engine, the run is integrated with `diffrax.diffeqsolve` in chunks of
    `options.chunk_length`, carrying the solver and step-size-controller states
    across chunks; only the step size is guessed anew at each chunk (about 0.1 %
    more steps than one solve). Dense-output
    samples of each chunk after `options.transient` are reduced to running extrema
    at once: memory does not grow with `options.t_end`, and no trajectory is stored.
    An oscillator is on the HALC when it sticks (`sticks`): its smallest sampled
    slip speed |x_n' - v_d| lies within 3 eps of zero.

    **Arguments:**

    - `params`: the chain parameters (`ChainParams`).
    - `y0`: an initial condition (`OutOfPhaseExcitation`, `GivenState`, ...) or a
        state array of shape (2, n_osc) or (2 n_osc,).
    - `solver`: a diffrax solver, the name of one (`SOLVERS`), or "auto" (chosen
        from eps by `auto_solver`); `Ros34PW2()` by default (`DEFAULT_SOLVER`). A
        solver of `SPLIT_SOLVERS` gets the friction force as its stiff term.
    - `options`: `SimulationOptions` (horizon, tolerances, sampling); for the exact
        engine `NonsmoothOptions`, or `SimulationOptions` whose horizon it takes.
    - `engine`: "smoothed" (default), "exact" (the stick/slip switch model: stick
        exact, no eps; an oscillator is on the HALC when it sticks during the
        window), or an engine value (`Smoothed`, `Exact`) holding its settings,
        when `solver` and `options` are not given (`as_engine`).
    - `throw`: raise on failure (default) or return the status.
    - `progress`: show a tqdm bar, one tick per chunk.

    **Returns:**

    `Observables` with per-oscillator fields of shape (n_osc,), the same layout from
    either engine.

    **Raises:**

    `ValidationError` for a state of the wrong shape, an unknown solver or engine
    name, or a solver given to the exact engine; `TypeError` for arguments of the
    wrong type; `RuntimeError` with advice when the run fails and `throw=True`.
    """
    return _single(_run_jit, "simulate", params, y0, solver, options, engine, (), throw,
                   progress)


def _initial_state(y0: AbstractInitialCondition, params: ChainParams) -> State:
    """The initial state of one run, as one compiled program (`compiled`)."""
    return y0(params)


def _single(fn, name, params, y0, solver, options, engine, extra, throw, progress):
    """One checked run of `fn(params, y, engine, *extra, progress)` under a progress
    bar, raising on failure when `throw`."""
    params = check_params(params)
    engine = as_engine(engine, solver, options, params)
    if not isinstance(y0, AbstractInitialCondition):
        y0 = GivenState(y0)
    params = without_records(params)  # one program for every mistuning draw
    y = compiled(_initial_state, y0, params)
    with progress_bar(engine.n_chunks(), name, progress):
        out = fn(params, y, engine, *extra, progress)
    status = int(out["status"] if isinstance(out, dict) else out.status)
    if throw and status != Status.ok:
        raise RuntimeError(f"{Status(status)}: {engine.failure_hint(status, params)}")
    return out


def _observe(params: ChainParams, y0: State, engine: AbstractEngine, observers: tuple,
             progress: bool = False) -> dict:
    return engine.run_observers(params, y0, observers, progress)


_observe_jit = eqx.filter_jit(_observe)


def observe(params: ChainParams, y0: AbstractInitialCondition | State,
            observers: Sequence[AbstractObserver],
            solver: diffrax.AbstractSolver | str | None = None,
            options: SimulationOptions | None = None, *,
            engine: AbstractEngine | str = "smoothed", throw: bool = True,
            progress: bool = False) -> dict[str, Array]:
    """Integrate eq. (5) of the paper for one trajectory and return what the given
    observers saw, and nothing else (`integrate`).

    **Arguments:**

    - `params`, `y0`, `solver`, `options`, `engine`, `throw`, `progress`: as for
        `simulate`; the observers other than `Extrema` need the smoothed engine.
    - `observers`: `Extrema`, `PeakTimes`, `TimeSeries`, `PoincareSection`,
        `LargestLyapunov`, ... (one of each kind at most).

    **Returns:**

    dict of every observer's results by name (shapes in each observer's
    docstring), with `y_initial`, `y_final` (2, n_osc), `num_steps` and `status`.

    **Raises:**

    `ValidationError` for a state of the wrong shape or observers of the same kind,
    `TypeError` for an object that is not an observer; `RuntimeError` with advice
    when the run fails and `throw=True`.
    """
    return _single(_observe_jit, "observe", params, y0, solver, options, engine,
                   (check_observers(observers),), throw, progress)
