"""Error against run time (a work-precision study) of every solver, tolerance and
smoothing eps, measured against the event-driven non-smooth reference."""

import dataclasses
import functools
import math
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._engine.checks import real_array
from .._physics.initial import OutOfPhaseExcitation, excited_block
from .._engine.exact.options import NonsmoothOptions
from .._engine.simulate import simulate
from .._engine.solver.controller import CONTROLLERS
from .._engine.options import SimulationOptions
from .._engine.engines import Exact, Smoothed
from .._physics.model import vector_field
from .._physics.params import ChainParams
from .._engine.status import Status
from .._engine.solver.registry import SOLVERS
from .._sweeps.result_store import CsvStore, settings_key
from .._checks import check_count
from .._errors import ValidationError


@dataclasses.dataclass(frozen=True)
class Scene:
    """A scene of the study: the chain, its initial condition (eq. (8), `n_excited`
    oscillators excited), the observed window [transient, t_end] of the
    observables and the short horizon `window` of the trajectory error."""

    name: str
    n_osc: int
    v_d: float
    n_excited: int
    transient: float
    t_end: float
    window: float

    def params(self) -> ChainParams:
        """The chain, the same for every run: the smoothing eps is the engine's
        (`Smoothed`), one per point of the grid."""
        return ChainParams(n_osc=self.n_osc, v_d=self.v_d)

    def y0(self) -> np.ndarray:
        """The initial state, the same for every run: eq. (8) with the non-smooth
        steady sliding mu(v_d) as base displacement."""
        ic = OutOfPhaseExcitation.eq8(excited_block(self.n_osc, self.n_excited))
        return np.asarray(ic(self.params()))


#: The single oscillator and the chain scene (a localized state of the paper's
#: Fig. 4), both at v_d = 1.5.
SCENES = {
    "single": Scene("single", 1, 1.5, 1, 200.0, 400.0, 20.0),
    "chain": Scene("chain", 20, 1.5, 1, 1000.0, 1500.0, 20.0),
}
WP_SOLVERS = ("tsit5", "dopri5", "dopri8", "bosh3", "kvaerno3", "kvaerno5", "kencarp4",
              "ros34pw2")
WP_RTOLS = tuple(10.0**-k for k in range(3, 11))
WP_EPS = (1e-1, 1e-2, 1e-3, 1e-4, 1e-5)
SCIPY_METHODS = ("LSODA", "Radau")
SCIPY_RTOLS = (1e-4, 1e-6, 1e-8)
SCIPY_EPS = (1e-2, 1e-3)
REFERENCE_RTOLS = (1e-6, 1e-8, 1e-10)
#: Tolerance of the reference that every error is measured against.
REFERENCE_RTOL = 1e-12
#: Spacing of the samples from which a scipy run's extrema are taken.
SCIPY_SAMPLE_DT = 0.05

#: Columns of the CSV, one row per (scene, method, eps, rtol). `key` is the
#: `settings_key` of everything that determines the row (`_row_settings`).
COLUMNS = ("scene", "method", "eps", "rtol", "atol", "status", "wall_s", "compile_s",
           "num_steps", "amplitude_error", "energy_error", "trajectory_error",
           "amplitude_max", "key")


@dataclasses.dataclass(frozen=True)
class Reference:
    """The non-smooth reference of a scene: amplitudes and E over the window, and
    the state at t = window."""

    amplitudes: np.ndarray
    energy: float
    y_window: np.ndarray


def _reference_options(scene: Scene, rtol: float) -> tuple[NonsmoothOptions, ...]:
    """The options of the reference's observables run and of its trajectory run."""
    return (NonsmoothOptions(t_end=scene.t_end, transient=scene.transient, rtol=rtol,
                             atol=rtol),
            NonsmoothOptions(t_end=scene.window, transient=0.0, rtol=rtol, atol=rtol))


def split_method(method: str) -> tuple[str, str]:
    """The solver and the step-size controller of a method name "SOLVER" (the
    default controller) or "SOLVER/CONTROLLER", for example "ros34pw2/diffrax"."""
    solver, _, controller = method.partition("/")
    return solver, controller or SimulationOptions().controller


def _diffrax_options(scene: Scene, rtol: float, max_steps: int, controller: str
                     ) -> tuple[SimulationOptions, ...]:
    """The options of a smoothed observables run and of its trajectory run, atol =
    rtol / 100. The tolerances are traced, so each solver compiles once per scene."""
    tol = {"rtol": jnp.asarray(rtol), "atol": jnp.asarray(rtol / 100),
           "controller": controller, "max_steps": max_steps}
    return (SimulationOptions(t_end=scene.t_end, transient=scene.transient, **tol),
            SimulationOptions(t_end=scene.window, transient=0.0, **tol))


def reference(scene: Scene, rtol: float = REFERENCE_RTOL, timed: bool = False
              ) -> tuple[Reference, float]:
    """The reference of `scene` at tolerance `rtol`, and the wall time (s) of its
    observables run, compilation excluded when `timed` (the run is then repeated;
    otherwise the time includes compilation)."""
    p, y0 = scene.params(), scene.y0()
    observe, short = _reference_options(scene, rtol)
    obs, wall = _timed(lambda: simulate(p, y0, engine=Exact(observe)))
    if timed:
        obs, wall = _timed(lambda: simulate(p, y0, engine=Exact(observe)))
    end = simulate(p, y0, engine=Exact(short))
    return Reference(np.asarray(obs.amplitudes), float(obs.energy),
                     np.asarray(end.y_final)), wall


def errors(ref: Reference, amplitudes, y_window) -> dict:
    """Amplitude error (max over oscillators, relative to max(1, largest reference
    amplitude)), energy error (relative to max(1, E_ref)) and trajectory error (max
    over the state at t = window, relative to max(1, |y_ref|))."""
    amplitudes = np.asarray(amplitudes)
    energy = 0.5 * np.sum(amplitudes**2)
    scale = max(1.0, float(ref.amplitudes.max()))
    return {
        "amplitude_error": float(np.max(np.abs(amplitudes - ref.amplitudes)) / scale),
        "energy_error": float(abs(energy - ref.energy) / max(1.0, ref.energy)),
        "trajectory_error": float(np.max(np.abs(np.asarray(y_window) - ref.y_window))
                                  / max(1.0, float(np.abs(ref.y_window).max()))),
        "amplitude_max": float(amplitudes.max()),
    }


@eqx.filter_jit
def _diffrax_run(params, y0, engine: Smoothed):
    return engine.run(params, y0)


def _timed(fn):
    start = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - start


def diffrax_point(scene: Scene, ref: Reference, method: str, eps: float, rtol: float,
                  max_steps: int) -> dict:
    """One smoothed run of `scene` (observables, then the trajectory window) with a
    diffrax solver and a step-size controller (`method`, see `split_method`). rtol,
    atol = rtol / 100 and eps (the smoothed engine's, `Smoothed.eps`) are traced, so
    each method compiles once per scene; `compile_s` is the compilation time of
    this call (0 once compiled)."""
    p = scene.params()
    y0 = jnp.asarray(scene.y0())
    solver_name, controller = split_method(method)
    solver = SOLVERS[solver_name]()
    observe, short = (Smoothed(solver, opt, jnp.asarray(eps))
                      for opt in _diffrax_options(scene, rtol, max_steps, controller))
    compile_s = 0.0
    for engine in (observe, short):
        opt = engine.options
        key = (method, opt.t_end, opt.transient, scene.n_osc, max_steps)
        if key not in _compiled:
            start = time.perf_counter()
            _diffrax_run.lower(p, y0, engine).compile()
            compile_s += time.perf_counter() - start
            _compiled.add(key)
    obs, wall = _timed(lambda: _diffrax_run(p, y0, observe))
    end, _ = _timed(lambda: _diffrax_run(p, y0, short))
    status = max(int(obs.status), int(end.status))
    row = {"status": Status(status).name, "wall_s": wall, "compile_s": compile_s,
           "num_steps": int(obs.num_steps)}
    if status == Status.ok:
        row |= errors(ref, obs.amplitudes, end.y_final)
    return row


_compiled: set = set()


def _numpy_field(p: ChainParams, eps: float) -> Callable:
    """Eq. (5) smoothed at `eps` for scipy: the one `vector_field`, compiled by
    `jax.jit` once and called with NumPy arrays (a few microseconds of dispatch per
    call, as a NumPy expression of the same field costs)."""
    field = jax.jit(lambda y: vector_field(0.0, y, p, eps))

    def rhs(t, y):
        return np.asarray(field(y))
    return rhs


class _OutOfTime(Exception):
    pass


def _scipy_point(scene: Scene, ref: Reference, method: str, eps: float, rtol: float,
                 budget_s: float) -> dict:
    """One smoothed run of `scene` with `scipy.integrate.solve_ivp`, the extrema
    taken from samples spaced `SCIPY_SAMPLE_DT` as in `simulate`. A run longer than
    `budget_s` is stopped and recorded as such."""
    from scipy.integrate import solve_ivp

    rhs = _numpy_field(scene.params(), eps)
    y0 = scene.y0().reshape(-1)
    deadline = time.perf_counter() + budget_s

    def clock(t, y):
        if time.perf_counter() > deadline:
            raise _OutOfTime
        return 1.0

    samples = np.linspace(scene.transient, scene.t_end,
                          int(round((scene.t_end - scene.transient) / SCIPY_SAMPLE_DT)) + 1)
    start = time.perf_counter()
    try:
        sol = solve_ivp(rhs, (0.0, scene.t_end), y0, method=method, rtol=rtol,
                        atol=rtol / 100, t_eval=samples, events=clock)
        wall = time.perf_counter() - start
        end = solve_ivp(rhs, (0.0, scene.window), y0, method=method, rtol=rtol,
                        atol=rtol / 100, events=clock)
    except _OutOfTime:
        return {"status": f"{Status.solver_failed}: time budget of {budget_s:g} s exceeded",
                "wall_s": time.perf_counter() - start, "compile_s": 0.0}
    if not (sol.success and end.success):
        return {"status": f"{Status.solver_failed}: scipy: {sol.message}", "wall_s": wall,
                "compile_s": 0.0}
    n = scene.n_osc
    x = sol.y[:n]
    amplitudes = 0.5 * (x.max(1) - x.min(1))
    row = {"status": Status.ok.name, "wall_s": wall, "compile_s": 0.0,
           "num_steps": int(sol.nfev)}
    return row | errors(ref, amplitudes, end.y[:, -1].reshape(2, n))


def _row_settings(scene: Scene, method: str, eps: float, rtol: float, *,
                  max_steps: int, scipy_budget_s: float) -> dict:
    """Everything that determines a row of the study, the settings of its `key`
    (`settings_key`): the scene (every field), its initial state and the options
    of the reference that errors are measured against; then, by method, the
    parameters (every `ChainParams` field) and the smoothing eps, the solver (its
    class and every field) and its options (every `SimulationOptions` field), or
    scipy's method, tolerances, time budget and sample spacing, or the options of
    the reference at `rtol` (no eps: the reference does not smooth).

    **Arguments:**

    - `scene`: the scene.
    - `method`: a name in `SOLVERS` (optionally "/" and a name in `CONTROLLERS`),
        "scipy <method>" or "exact" (the exact engine).
    - `eps`, `rtol`: the point of the grid.
    - `max_steps`, `scipy_budget_s`: as for `work_precision`.

    **Returns:**

    A dict of the settings, as `settings_key` takes them.
    """
    out = {"scene": scene, "y0": scene.y0(), "params": scene.params(),
           "reference": _reference_options(scene, REFERENCE_RTOL)}
    if method == "exact":
        return out | {"options": _reference_options(scene, rtol)}
    out["eps"] = eps
    if method.startswith("scipy "):
        return out | {"solve_ivp": method.removeprefix("scipy "), "rtol": rtol,
                      "atol": rtol / 100, "budget_s": scipy_budget_s,
                      "sample_dt": SCIPY_SAMPLE_DT}
    solver_name, controller = split_method(method)
    return out | {"solver": SOLVERS[solver_name](),
                  "options": _diffrax_options(scene, rtol, max_steps, controller)}


def work_precision(path: Path, scenes: Iterable[str] = tuple(SCENES),
                   solvers: Iterable[str] = WP_SOLVERS, rtols: Iterable[float] = WP_RTOLS,
                   eps_values: Iterable[float] = WP_EPS, *, scipy: bool = True,
                   reference_points: bool = True, max_steps: int = 100_000,
                   scipy_budget_s: float = 60.0, progress: Callable = lambda msg: None
                   ) -> list[dict]:
    """Measure error against wall time for every (scene, solver, eps, rtol) and
    append each result to the CSV at `path` as soon as it is known, so that an
    interrupted study resumes.

    Each row carries the key of everything that determines it (`settings_key`). A
    row in the CSV is reused only when its key equals that of the row asked for;
    rows of other settings (another `max_steps`, another scene definition, another
    solver configuration) stay in the file but are never read back, and the row is
    computed anew. A CSV of an older layout, without
    keys, is rewritten with an empty key column.

    A failed run is recorded with its status. Once a (solver, eps) pair reaches
    max_steps at some rtol, its tighter rtols are recorded as skipped (they only
    take more steps), and so are its smaller eps (stiffer problems); a stored
    failure counts as a new one.

    The outside points are `scipy.integrate.solve_ivp` (LSODA, Radau) at
    `SCIPY_EPS` x `SCIPY_RTOLS`, and the exact engine at `REFERENCE_RTOLS` (method
    "exact", eps 0: the reference at looser tolerances), its error taken against
    the reference at `REFERENCE_RTOL`.

    **Arguments:**

    - `path`: the CSV file (columns `COLUMNS`).
    - `scenes`: names in `SCENES`.
    - `solvers`: names in `SOLVERS`, each optionally followed by "/" and a
        step-size controller of `CONTROLLERS` ("ros34pw2/diffrax"); without one,
        the default controller.
    - `rtols`, `eps_values`: the grid; atol = rtol / 100. `eps_values` are the
        smoothing velocities of the smoothed engine (`Smoothed.eps`) that the study
        compares: its axis, not a setting of one run.
    - `scipy`, `reference_points`: include the outside points.
    - `max_steps`: step budget per chunk of 250 time units.
    - `scipy_budget_s`: wall-time budget of one scipy run.
    - `progress`: called with a short message before each run.

    **Returns:**

    The rows of this call's grid, reused or new, in the order they are run, as
    dicts of strings: what a call into an empty folder returns, wall times aside.

    **Raises:**

    Before the CSV is opened or anything runs: `ValidationError` naming the argument
    for no scene or solver, an unknown scene or solver, an empty `rtols` or
    `eps_values`, an rtol outside (0, 1), an eps that is not a finite number > 0, a
    `max_steps` that is not an integer >= 1 or a `scipy_budget_s` that is not a
    finite number > 0; `TypeError` for a grid that is not a list of real numbers, a `path` that
    is not a path or a `progress` that cannot be called.
    """
    scenes, solvers, rtols, eps = _check(path, scenes, solvers, rtols, eps_values,
                                         max_steps, scipy_budget_s, progress)
    rows: list[dict] = []
    with CsvStore(path, COLUMNS) as store:
        for scene_name in scenes:
            _scene(store, rows, SCENES[scene_name], solvers, rtols, eps, scipy=scipy,
                   reference_points=reference_points, max_steps=max_steps,
                   scipy_budget_s=scipy_budget_s, progress=progress)
    return rows


def _check(path, scenes, solvers, rtols, eps, max_steps, scipy_budget_s, progress
           ) -> tuple:
    """The arguments of `work_precision`, checked: (scenes, solvers, rtols, eps),
    the grids sorted from the loosest."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be a path to a CSV file, got {type(path).__name__}")
    scenes, solvers = _names(scenes, "scenes"), _names(solvers, "solvers")
    if not scenes:
        raise ValidationError(f"scenes must name at least one of {sorted(SCENES)}, got none")
    for name in scenes:
        if name not in SCENES:
            raise ValidationError(f"scene must be one of {sorted(SCENES)}, got {name!r}")
    if not solvers:
        raise ValidationError(f"solvers must name at least one of {sorted(SOLVERS)}, got "
                              "none")
    for name in solvers:
        solver_name, controller = split_method(name) if isinstance(name, str) else (name, "")
        if solver_name not in SOLVERS or controller not in CONTROLLERS:
            raise ValidationError(f"solver must be one of {sorted(SOLVERS)}, optionally "
                                  f"followed by /CONTROLLER with CONTROLLER one of "
                                  f"{sorted(CONTROLLERS)}, got {name!r}")
    rtols = _grid(rtols, "rtols", 1.0, "numbers in (0, 1)")
    eps = _grid(eps, "eps_values", math.inf, "finite numbers > 0")
    check_count("max_steps", max_steps)
    if isinstance(scipy_budget_s, bool) \
            or not isinstance(scipy_budget_s, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(scipy_budget_s) and scipy_budget_s > 0):
        raise ValidationError(f"scipy_budget_s must be a finite number > 0, got "
                              f"{scipy_budget_s!r}")
    if not callable(progress):
        raise TypeError(f"progress must be callable, got {type(progress).__name__}")
    return scenes, solvers, sorted(rtols, reverse=True), sorted(eps, reverse=True)


def _names(names, what: str) -> list:
    """`names` (scenes or solvers) as a list; one name alone is a list of one.

    **Raises:**

    `TypeError` naming `what` when `names` is not an iterable of names.
    """
    if isinstance(names, str):
        return [names]
    try:
        return list(names)
    except TypeError:
        raise TypeError(f"{what} must be a list of names, got {names!r}") from None


def _grid(values, name: str, below: float, accepted: str) -> list:
    """The values of one axis of the grid (`rtols` or `eps_values`), as given.

    **Raises:**

    `TypeError` naming `name` for values that are not real numbers;
    `ValidationError` naming it for an empty list, or a value that is not finite, is
    <= 0 or is not below `below` (`accepted` says what is).
    """
    try:
        values = list(values)
    except TypeError:
        raise TypeError(f"{name} must be a list of numbers, got {values!r}") from None
    a = real_array(values, name)
    if a.ndim != 1 or a.size == 0:
        raise ValidationError(f"{name} must be a list of at least one number, got {values!r}")
    if not np.all(np.isfinite(a) & (a > 0) & (a < below)):
        raise ValidationError(f"{name} must hold {accepted}, got {a.tolist()}")
    return values


def _scene(store: CsvStore, rows: list[dict], scene: Scene, solvers, rtols, eps, *,
           scipy, reference_points, max_steps, scipy_budget_s, progress):
    """Append the rows of one scene to `rows` (see `work_precision`). The reference
    is computed only if some row is."""

    @functools.cache
    def ref() -> Reference:
        progress(f"{scene.name}: non-smooth reference")
        return reference(scene)[0]

    def point(method, e, r, atol, run: Callable[[], dict], **extra) -> dict:
        """The row of (method, e, r), stored or computed by `run`. A skipped row
        has its reason in `extra`, and so its own key."""
        settings = _row_settings(scene, method, e, r, max_steps=max_steps,
                                 scipy_budget_s=scipy_budget_s)
        row = {"scene": scene.name, "method": method, "eps": e, "rtol": r, "atol": atol,
               "key": settings_key("work-precision row", **settings, **extra)}

        def compute():
            if not extra:
                progress(f"{scene.name}: {method}, eps {e:g}, rtol {r:g}")
            return run()
        rows.append(store.fetch(row, compute))
        return rows[-1]

    def reference_point(r):
        coarse, wall = reference(scene, r, timed=True)
        return ({"status": Status.ok.name, "wall_s": wall, "compile_s": 0.0}
                | errors(ref(), coarse.amplitudes, coarse.y_window))

    if reference_points:
        for r in REFERENCE_RTOLS:
            point("exact", 0.0, r, r, functools.partial(reference_point, r))
    for solver in solvers:
        failed_eps = None
        for e in eps:
            failed_rtol = None
            for r in rtols:
                if failed_eps is not None or failed_rtol is not None:
                    why = (f"eps {failed_eps:g}" if failed_eps is not None
                           else f"rtol {failed_rtol:g}")
                    status = f"{Status.not_run}: max_steps at {why}"
                    point(solver, e, r, r / 100, lambda: {"status": status}, skipped=why)
                    continue
                result = point(solver, e, r, r / 100,
                               lambda: diffrax_point(scene, ref(), solver, e, r, max_steps))
                if result["status"] == Status.max_steps_reached.name:
                    failed_rtol = r
                    if r == rtols[0]:
                        failed_eps = e
    if scipy:
        for method in SCIPY_METHODS:
            for e in SCIPY_EPS:
                for r in SCIPY_RTOLS:
                    point(f"scipy {method}", e, r, r / 100,
                          lambda: _scipy_point(scene, ref(), method, e, r, scipy_budget_s))


def _ok(rows, scene):
    return [r for r in rows if r["scene"] == scene and r["status"] == Status.ok.name
            and r["amplitude_error"] != ""]


def _confirmed(run: dict, rows: list[dict], target: float) -> bool:
    """Whether the run at rtol/10 (same scene, solver and eps) succeeded and moves
    the largest amplitude by less than a tenth of the target, relative:
    |A(rtol) - A(rtol/10)| < (target/10) |A(rtol/10)|. The run's error is then
    that of eps, which carries over to other scenes, and not a lucky loose
    tolerance (a loose rtol can even land on another attractor).

    The rtol/10 run is matched by a relative comparison (to 1e-9) with no absolute
    tolerance, so that a run at a tiny rtol can never stand in for its own
    rtol/10 run."""
    tighter = float(run["rtol"]) / 10
    for r in _ok(rows, run["scene"]):
        if (r["method"] == run["method"] and float(r["eps"]) == float(run["eps"])
                and math.isclose(float(r["rtol"]), tighter, rel_tol=1e-9, abs_tol=0.0)):
            a, b = float(run["amplitude_max"]), float(r["amplitude_max"])
            return abs(a - b) < target / 10 * abs(b)
    return False


def recommend(rows: list[dict], scene: str, target: float) -> dict | None:
    """The fastest diffrax run of `scene` whose amplitude error is below `target`
    and which a run at rtol/10 confirms (`_confirmed`): tightening rtol tenfold
    moves its largest amplitude by less than target/10, relative.

    **Arguments:**

    - `rows`: rows of one study (`work_precision`).
    - `scene`: a scene name.
    - `target`: the relative amplitude error asked for.

    **Returns:**

    The row, or None when no run qualifies (a run without a successful rtol/10
    run never does).
    """
    fits = [r for r in _ok(rows, scene) if r["method"] in SOLVERS
            and float(r["amplitude_error"]) < target and _confirmed(r, rows, target)]
    return min(fits, key=lambda r: float(r["wall_s"])) if fits else None
