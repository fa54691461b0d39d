"""The scenes of Section 3.3 and 4 of the paper (Figs. 5-10). Each runs the chain
with the observers it needs, and only those, and returns an `xarray.Dataset` from
which a function of `jaxchain._plots.dynamics` draws the paper's figure."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
from collections.abc import Sequence

import diffrax
import numpy as np

from .._physics.record import check_recordable
from .._engine.checks import check_params
from .._engine.engines import AbstractEngine, as_engine
from .._physics.initial import FAMILIES, initial_states, localized_family
from .._engine.lanes import lane_params, run_lanes, take_lanes
from .._engine.observers.base import AbstractObserver
from .._engine.observers.crossings import PeakTimes
from .._engine.observers.extrema import Extrema
from .._engine.observers.lyapunov_exponent import LargestLyapunov
from .._engine.observers.series import TimeSeries
from .._engine.options import SimulationOptions
from .._physics.params import chain_or_default, ChainParams
from .._sweeps.datasets import run_attributes
from .._engine.observables import check_observers
from .._engine.status import flag_attributes
from .._engine.solver.registry import DEFAULT_SOLVER, SOLVERS
from .._analysis.states import ClassTolerances
from .._analysis.classify import classify
from .._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: The solutions (numbers of excited oscillators) of Figs. 6 and 7 of the paper.
PAPER_SOLUTIONS = (1, 2, 5, 8, 9, 12, 13, 19, 20)

#: Results that are the same for every solution: kept once, as coordinates.
_SHARED = {"series_t": "time", "lyapunov_time": "lyapunov_time"}


#: The paper's scenes: figure number -> (v_d, initial-condition family, what it shows).
PAPER_FIGURES = {
    "4": (1.5, "eq8", "localized states: circles of radius proportional to amplitude"),
    "5": (1.5, "eq8", "time series and phase plot of 2 excited oscillators, t in [0, 300]"),
    "6": (1.5, "eq8", "time delays against time, solutions 1 2 5 8 9 12 13 19 20"),
    "7": (1.5, "eq8", "3-D phase plots (x11, x12, x13), t in [1e4, 1.5e4], same solutions"),
    "8": (1.5, "eq8", "orbit diagram of the 20 solutions, classified"),
    "9": (1.65, "eq8", "localized states and orbit diagram"),
    "10": (1.75, "eq10", "localized states and orbit diagram, eq. (10) initial conditions"),
}

def _check_solutions(solutions, n_osc: int) -> np.ndarray:
    try:
        solutions = np.asarray(sorted(set(int(k) for k in solutions))
                               if solutions is not None else np.arange(1, n_osc + 1))
    except (TypeError, ValueError):
        raise TypeError(f"solutions must be a list of integers, got {solutions!r}") from None
    if solutions.size == 0 or solutions.min() < 1 or solutions.max() > n_osc:
        raise ValidationError(f"solutions must be numbers of excited oscillators in "
                              f"[1, {n_osc}], got {solutions.tolist()}")
    return solutions


def observe_solutions(params: ChainParams, solutions: Sequence[int] | None,
                      observers: Sequence[AbstractObserver], ics: str = "eq8",
                      solver: diffrax.AbstractSolver | str | None = None,
                      options: SimulationOptions | None = None, *,
                      engine: AbstractEngine | str = "smoothed",
                      schedule: str | None = None, progress: bool = True,
                      tolerances: ClassTolerances = ClassTolerances(),
                      classify_from: float | None = None) -> xr.Dataset:
    """Run the paper's solutions (k oscillators excited by eq. (8) or (10), in the
    block of `excited_block`) at one belt speed, observing only `observers`, spread
    over the devices (`run_lanes`).

    **Arguments:**

    - `params`: chain parameters (one belt speed).
    - `solutions`: the numbers k of excited oscillators, in [1, n_osc]; all if None.
    - `observers`: what to observe (see `jaxchain._engine.observers`).
    - `ics`: "eq8" or "eq10".
    - `solver`, `options`, `engine`, `schedule`, `progress`: as for `ensemble`.
    - `tolerances`, `classify_from`: when the observers include `Extrema` and
        `PeakTimes` of every oscillator and `LargestLyapunov`, each state is
        classified (`classify`) over the peaks after `classify_from`
        (`options.transient` by default).

    **Returns:**

    A Dataset with dim `solution` (coordinate: k), the dims of each observer's
    results and `status`; classified: `class`, `class_delays`, `class_lyapunov`,
    `delay_spread`, `delay_period`, `ref` (1-based). Attributes: as `ensemble`.

    **Raises:**

    `ValidationError` for solutions outside [1, n_osc] or an unknown family;
    `TypeError` or `ValidationError` for bad observers (`check_observers`).
    """
    import xarray as xr

    observers = check_observers(observers)
    params = check_params(params)
    check_recordable(params)
    engine = as_engine(engine, solver, options, params)
    options = engine.options
    solutions = _check_solutions(solutions, params.n_osc)
    family = take_lanes(localized_family(params.n_osc, ics, params.graph), solutions - 1)
    lanes = lane_params(params, solutions.size)
    out = run_lanes(lanes, initial_states(lanes, family), engine=engine,
                    schedule=schedule, progress=progress, observers=observers)
    dims = {"y_initial": ("component", "osc"), "y_final": ("component", "osc"),
            "num_steps": (), "status": ()}
    coords = {"solution": solutions, "osc": np.arange(1, params.n_osc + 1),
              "component": ["x", "v"]}
    for o in observers:
        dims |= o.dims(options)
        chosen = getattr(o, "oscillators", False)
        if chosen is not False:
            picked = np.arange(params.n_osc) if chosen is None else np.asarray(chosen)
            coords["peak_osc" if isinstance(o, PeakTimes) else "series_osc"] = picked + 1
    data = {}
    for name, value in out.items():
        if name in _SHARED:
            coords[_SHARED[name]] = np.asarray(value)[0]
        else:
            data[name] = (("solution",) + dims[name], np.asarray(value))
    ds = xr.Dataset(data, coords=coords)
    ds["status"].attrs.update(flag_attributes())
    ds.attrs = run_attributes(params, engine, ics, "") | {"ics_family": ics}
    kinds = {type(o) for o in observers}
    peaks = [o for o in observers if isinstance(o, PeakTimes)]
    if {Extrema, LargestLyapunov} <= kinds and peaks and peaks[0].oscillators is None:
        start = options.transient if classify_from is None else classify_from
        rows = [classify(ds["peak_times"].values[i], ds["on_halc"].values[i],
                         int(ds["n_halc"][i]), int(ds["status"][i]),
                         float(ds["lyapunov"][i]), float(ds["lyapunov_error"][i]),
                         start, tolerances, params.graph) for i in range(solutions.size)]
        for key in rows[0]:
            ds[key] = ("solution", np.asarray([r[key] for r in rows]))
        ds["ref"] = ds["ref"] + 1
        ds.attrs |= {"classify_from": start, "delay_tolerance": tolerances.delay,
                     "max_period": tolerances.max_period}
    return ds


def time_series_scene(params: ChainParams | None = None, n_excited: int = 2,
                      ics: str = "eq8", t_end: float = 300.0, dt: float = 0.1,
                      solver: diffrax.AbstractSolver = SOLVERS[DEFAULT_SOLVER](), *,
                      progress: bool = True) -> xr.Dataset:
    """Fig. 5 of the paper: x_n(t) and x_n'(t) of every oscillator from t = 0, over a
    window that shows the transient, for `n_excited` oscillators excited (the
    paper's case has two on the HALC). Observes only `TimeSeries`.

    **Returns:**

    `observe_solutions`'s Dataset: `series` (solution, time, component,
    series_osc), dimensionless.

    **Raises:**

    `ValidationError` for t_end <= 0, dt <= 0 or n_excited outside [1, n_osc].
    """
    params = chain_or_default(params, v_d=1.5)
    options = SimulationOptions(t_end=t_end, transient=0.0)
    return observe_solutions(params, [n_excited], (TimeSeries(dt=dt),), ics, solver,
                             options, progress=progress)


def time_delay_scene(params: ChainParams | None = None,
                     solutions: Sequence[int] | None = PAPER_SOLUTIONS, ics: str = "eq8",
                     solver: diffrax.AbstractSolver = SOLVERS[DEFAULT_SOLVER](),
                     options: SimulationOptions = SimulationOptions(), *,
                     progress: bool = True,
                     tolerances: ClassTolerances = ClassTolerances()) -> xr.Dataset:
    """Fig. 6 of the paper: the peak times of every oscillator over the whole run
    [0, t_end], from which the time delays phi_i = tau_peak,i - tau_peak,11 of the
    HALC oscillators are drawn against time (`time_delays`); with the extrema and
    the largest Lyapunov exponent over [transient, t_end], each state classified
    (`classify`).

    **Returns:**

    `observe_solutions`'s Dataset, classified.
    """
    params = chain_or_default(params, v_d=1.5)
    start = options.transient
    run_options = dataclasses.replace(options, transient=0.0)
    observers = (Extrema(t_start=start), PeakTimes(t_start=0.0),
                 LargestLyapunov(t_start=start))
    return observe_solutions(params, solutions, observers, ics, solver, run_options,
                             progress=progress, tolerances=tolerances,
                             classify_from=start)


def phase_portrait_scene(params: ChainParams | None = None,
                         solutions: Sequence[int] | None = PAPER_SOLUTIONS,
                         oscillators: tuple[int, int, int] | None = None, ics: str = "eq8",
                         dt: float = 0.1,
                         solver: diffrax.AbstractSolver = SOLVERS[DEFAULT_SOLVER](),
                         options: SimulationOptions = SimulationOptions(), *,
                         progress: bool = True) -> xr.Dataset:
    """Fig. 7 of the paper: 3-D phase plots (x_11, x_12, x_13) over
    [transient, t_end] (the paper's [1e4, 1.5e4]). Observes only the `TimeSeries`
    of those three oscillators, every `dt`.

    **Arguments:**

    - `oscillators`: three 0-based indices; (N//2, N//2 + 1, N//2 + 2), the
        paper's 11, 12 and 13 of 20, if None.

    **Returns:**

    `observe_solutions`'s Dataset: `series` (solution, time, component, series_osc).
    """
    params = chain_or_default(params, v_d=1.5)
    n = params.n_osc
    if oscillators is None:
        oscillators = tuple((n // 2 + i) % n for i in range(3))
    if len(oscillators) != 3 or not all(0 <= i < n for i in oscillators):
        raise ValidationError(f"oscillators must be three indices in [0, {n}), got {oscillators}")
    observers = (TimeSeries(oscillators=tuple(int(i) for i in oscillators), dt=dt),)
    return observe_solutions(params, solutions, observers, ics, solver, options,
                             progress=progress)


def orbit_diagram_scene(params: ChainParams | None = None,
                        solutions: Sequence[int] | None = None, ics: str = "eq8",
                        solver: diffrax.AbstractSolver = SOLVERS[DEFAULT_SOLVER](),
                        options: SimulationOptions = SimulationOptions(), *,
                        progress: bool = True,
                        tolerances: ClassTolerances = ClassTolerances()) -> xr.Dataset:
    """Figs. 8, 9 and 10 of the paper: for each solution, the amplitudes (the circle
    plot of Figs. 9(a) and 10(a)), the peak times over [transient, t_end] (the
    orbit diagram: the delays phi over the last t_end - transient = 5000 time units
    against the solution number), the largest Lyapunov exponent, and the class of
    each state (`classify`). Fig. 8: v_d = 1.5, eq. (8); Fig. 9: v_d = 1.65; Fig.
    10: v_d = 1.75 with eq. (10).

    **Returns:**

    `observe_solutions`'s Dataset, classified.
    """
    params = chain_or_default(params, v_d=1.5)
    if ics not in FAMILIES:
        raise ValidationError(f"ics must be one of {sorted(FAMILIES)}, got {ics!r}")
    observers = (Extrema(), PeakTimes(), LargestLyapunov())
    return observe_solutions(params, solutions, observers, ics, solver, options,
                             progress=progress, tolerances=tolerances)
