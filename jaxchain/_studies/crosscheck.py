"""The cross-check of an engine (the smoothed model by default) against the
event-driven non-smooth reference, on a grid of belt speeds and initial
conditions."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import time
import uuid
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._engine.progress import tqdm
from .._engine.checks import belt_speeds, check_options, check_params
from .._engine.engines import AbstractEngine, as_engine
from .._engine.horizon import AbstractHorizon
from .._physics.initial import FAMILIES, excited_block
from .._engine.exact.options import NonsmoothOptions
from .._engine.exact.solve import run_exact
from .._physics.params import chain_or_default, ChainParams, with_parameter
from .._physics.record import chain_record, check_recordable
from .._engine.lanes import lane_params, on_devices, run_lanes
from .._sweeps.datasets import PAPER, field_values
from .._engine.status import Status, flag_attributes
from .._analysis.states import IRREGULAR, PERIODIC, ClassTolerances, state_class
from .._sweeps.result_store import read_dataset, settings_key, write_dataset
from .._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: The grid of the issue: belt speeds across the bistable range and a set of
#: eq. (8) and eq. (10) initial conditions, as (family, number excited).
CROSSCHECK_VD = (1.2, 1.5, 1.65, 1.75)
CROSSCHECK_ICS = (("eq8", 1), ("eq8", 2), ("eq8", 5), ("eq8", 20), ("eq10", 2),
                  ("eq10", 20))


_reference_run = eqx.filter_jit(run_exact)


def _halves(params, v_d, y0, engine: AbstractEngine):
    """The engine's runs over the two halves of the observed window (so that the
    extrema of each half are known), all cases as lanes of `run_lanes`."""
    options = engine.options
    mid = 0.5 * (options.transient + options.t_end)
    first = dataclasses.replace(options, t_end=mid)
    second = dataclasses.replace(options, t_end=options.t_end - mid, transient=0.0)
    params = lane_params(params, len(v_d), v_d=v_d)
    a = run_lanes(params, y0, engine=dataclasses.replace(engine, options=first))
    b = run_lanes(params, a.y_final, engine=dataclasses.replace(engine, options=second))
    return a, b


def _gather(a, b) -> dict:
    x_max = np.stack([a.x_max, b.x_max], 1)
    x_min = np.stack([a.x_min, b.x_min], 1)
    amplitudes = 0.5 * (x_max.max(1) - x_min.min(1))
    on_halc = np.asarray(a.on_halc) | np.asarray(b.on_halc)
    status = np.where(np.asarray(a.status) != Status.ok, a.status, b.status)
    return {"amplitudes": amplitudes, "x_max": x_max, "x_min": x_min,
            "n_halc": np.where(status == Status.ok, on_halc.sum(-1), -1), "status": status,
            "num_steps": np.asarray(a.num_steps) + np.asarray(b.num_steps)}


#: The kind of result in the key of a stored reference run (`settings_key`).
_REFERENCE_KIND = "crosscheck reference"
_REFERENCE_FIELDS = ("amplitudes", "x_max", "x_min", "n_halc", "status", "stick_fraction",
                     "num_events", "num_steps")
#: The stored reference's extrema are those of each half (`Observables.x_max_halves`).
_HALVES = {"x_max": "x_max_halves", "x_min": "x_min_halves"}


def _reference_settings(params: ChainParams, y0: np.ndarray,
                        options: NonsmoothOptions) -> dict:
    """Everything that determines a reference run, the key of its stored result:
    every parameter (eps is not one: it is the smoothed engine's, and the reference
    has no smoothing, so one stored run serves every eps), the initial state and
    every reference option."""
    return {"params": {f.name: getattr(params, f.name) for f in dataclasses.fields(params)},
            "y0": y0, "options": options}


@dataclasses.dataclass(frozen=True)
class _References:
    """The reference runs of a cross-check, case i from `y0[i]` at `params_i`.
    With a `folder`, each run is stored there under the key of its settings
    (`_reference_settings`) and read back by a later call with the same settings;
    a stored run of other settings is never read."""

    params: tuple[ChainParams, ...]
    y0: np.ndarray
    options: NonsmoothOptions
    labels: tuple[str, ...]
    folder: Path | None

    def _settings(self, i: int) -> dict:
        return _reference_settings(self.params[i], self.y0[i], self.options)

    def _path(self, i: int) -> Path:
        key = settings_key(_REFERENCE_KIND, **self._settings(i))
        return self.folder / f"reference_{self.labels[i]}_{key[:16]}.nc"

    def read(self, i: int) -> tuple[dict, float] | None:
        """Case i's stored run and its wall time, or None."""
        if self.folder is None:
            return None
        stored = read_dataset(self._path(i), _REFERENCE_KIND, **self._settings(i))
        if stored is None:
            return None
        return {k: stored[k].values for k in _REFERENCE_FIELDS}, stored.attrs["wall_time_s"]

    def run(self, i: int, device) -> tuple[dict, float]:
        """Case i on `device`: read back if stored, else computed (and stored)."""
        import xarray as xr

        stored = self.read(i)
        if stored is not None:
            return stored
        start = time.perf_counter()
        p = self.params[i]
        v_d, y0 = jax.device_put((jnp.asarray(p.v_d), jnp.asarray(self.y0[i])), device)
        obs = _reference_run(with_parameter(p, "v_d", v_d), y0, self.options)
        out = {k: np.asarray(getattr(obs, _HALVES.get(k, k))) for k in _REFERENCE_FIELDS}
        wall = time.perf_counter() - start
        if self.folder is not None:
            dims = {0: (), 1: ("osc",), 2: ("half", "osc")}
            ds = xr.Dataset({k: (dims[v.ndim], v) for k, v in out.items()},
                            attrs={"wall_time_s": wall})
            write_dataset(ds, self._path(i), _REFERENCE_KIND, **self._settings(i))
        return out, wall

    def store(self, i: int, devices) -> None:
        """Case i on the first of `devices`, stored: a task of the Dask route."""
        self.run(i, devices[0])


def _on_cluster(client, refs: _References, progress: bool) -> list[tuple[dict, float]]:
    """Each reference run not yet stored is a task on the cluster of `client`
    (`run_tasks`), which stores it; then all are read back here."""
    from .._engine.cluster import run_tasks

    n = len(refs.labels)
    todo = [i for i in range(n) if refs.read(i) is None]
    with tqdm(total=n, initial=n - len(todo), desc="non-smooth reference", unit="case",
              disable=not progress) as bar:
        run_tasks(client, _References.store, refs, [(i,) for i in todo],
                  [f"crosscheck-{refs.labels[i]}-{uuid.uuid4().hex[:8]}" for i in todo], bar)
    results = [refs.read(i) for i in range(n)]
    missing = [refs.labels[i] for i, r in enumerate(results) if r is None]
    if missing:
        raise RuntimeError(f"the cluster ran {len(todo)} reference runs but {len(missing)} "
                           f"are not in {refs.folder}: its workers write to a file system "
                           "this process does not see; give a checkpoint on a shared one")
    return results


def _amplitude_error(smoothed, reference):
    """max_n |A_s - A_r| relative to max(1, max_n A_r)."""
    return np.max(np.abs(smoothed - reference), -1) / np.maximum(1.0, reference.max(-1))


def crosscheck(params: ChainParams | None = None, v_d=CROSSCHECK_VD, ics=CROSSCHECK_ICS,
               solver: diffrax.AbstractSolver | str | None = None,
               options: AbstractHorizon | None = None,
               reference_options: NonsmoothOptions | None = None, *,
               engine: AbstractEngine | str = "smoothed",
               tolerances: ClassTolerances = ClassTolerances(),
               checkpoint: Path | None = None, client=None,
               progress: bool = False) -> xr.Dataset:
    """Run an engine (the smoothed model by default) and the non-smooth reference on
    the same grid of belt speeds x initial conditions, and compare their
    observables.

    Irregular states diverge between any two models (and any two tolerances), so
    they are compared by their statistics over the observed window (amplitudes, E,
    n_HALC), never as time series; the same comparison serves periodic states.

    **Arguments:**

    - `params`: chain parameters; `v_d` is replaced by each belt speed.
    - `v_d`: belt speeds, dimensionless.
    - `ics`: initial conditions as (family, k): eq. (8) ("eq8") or eq. (10)
        ("eq10") with k oscillators excited (`excited_block`).
    - `solver`, `options`, `engine`: the engine under test, as for `simulate`
        (`Smoothed(solver, options, eps)` holds its eps: one cross-check per eps,
        sharing the stored reference runs; "exact": its lanes against its runs).
    - `reference_options`: the reference runs; by default the horizon of
        `options` with `NonsmoothOptions`'s tolerances.
    - `tolerances`: how periodic is told from irregular (`ClassTolerances`: its
        `halves` and `halves_reference`, the change of the extrema between the
        two halves of the observed window).
    - `checkpoint`: a folder where each reference run is stored as it finishes and
        read back on a later call (resuming an interrupted cross-check). Each run
        is stored under the key of everything that determines it (every parameter,
        the initial state and every field of `reference_options`; not the engine
        under test, its eps included): only a run of equal settings is read back,
        the others are computed anew.
    - `client`: a `distributed.Client` to run the reference runs on its cluster,
        one task per case that stores its run in `checkpoint` (which its workers
        must reach); this process reads them back.
    - `progress`: show a tqdm bar over the reference runs.

    The tested runs are lanes of `run_lanes`; the reference runs one case at a
    time per device (`on_devices`), or per worker of `client`.

    **Returns:**

    An `xarray.Dataset` with dims (case, osc) and coords v_d, family, n_excited
    along case, its variables suffixed by the engine's name (`_smoothed` or
    `_exact`, attribute `engine`) and `_reference`:
    amplitudes_smoothed/_reference (case, osc); energy, n_halc,
    half_difference, state_class, status, num_steps of both (case);
    stick_fraction, num_events and wall_time_s of the reference; and the
    comparison: amplitude_error (max over oscillators, relative to max(1, largest
    reference amplitude)), energy_error (relative to max(1, E_reference)),
    n_halc_agrees, class_agrees. Attributes hold parameters, options and the
    engine's settings (`eps` for the smoothed engine).

    **Raises:**

    `ValidationError` for an unknown family, a k outside [1, N], a bad belt speed, or a
    `client` without a `checkpoint`. `RuntimeError` when the scheduler of `client`
    goes away, or when the runs its workers stored are not in `checkpoint` as this
    process sees it.
    """
    params, engine, reference_options, cases, y0 = _check(
        params, v_d, ics, solver, options, reference_options, engine, checkpoint, client)
    vds = np.array([c[0] for c in cases])
    start = time.perf_counter()
    tested = _gather(*_halves(params, vds, jnp.asarray(y0), engine))
    wall = time.perf_counter() - start
    refs = _References(tuple(with_parameter(params, "v_d", c[0]) for c in cases), y0,
                       reference_options,
                       tuple(f"vd{vd:g}_{fam}_k{k}" for vd, fam, k in cases),
                       None if checkpoint is None else Path(checkpoint).resolve())
    if client is None:
        results = on_devices(refs.run, len(cases), "non-smooth reference", progress)
    else:
        results = _on_cluster(client, refs, progress)
    return _assemble(params, engine, reference_options, cases, tested, wall, results,
                     tolerances)


def _check(params, v_d, ics, solver, options, reference_options, engine, checkpoint,
           client) -> tuple:
    """The arguments of `crosscheck`, checked: (params, engine, reference_options,
    cases, y0), a case (v_d, family, k) starting from y0[i]."""
    params = chain_or_default(params)
    if client is not None and checkpoint is None:
        raise ValidationError("checkpoint: a cross-check on a Dask cluster needs a checkpoint "
                              "folder its workers can reach")
    params = check_params(params)
    engine = as_engine(engine, solver, options, params)
    v_d = belt_speeds(v_d)
    check_recordable(params)
    ics = list(ics)
    if not ics:
        raise ValidationError("ics must list at least one (family, n_excited) pair, got none")
    window = (engine.options.t_end, engine.options.transient)
    if reference_options is None:
        reference_options = NonsmoothOptions.reference(t_end=window[0], transient=window[1])
    check_options(reference_options, NonsmoothOptions, "reference_options")
    if (reference_options.t_end, reference_options.transient) != window:
        raise ValidationError("reference_options must observe the same window as options")
    cases = [(float(vd), fam, int(k)) for vd in v_d for fam, k in ics]
    y0 = []
    for vd, fam, k in cases:
        if fam not in FAMILIES:
            raise ValidationError(f"ics family must be one of {sorted(FAMILIES)}, got {fam!r}")
        p = with_parameter(params, "v_d", vd)
        y0.append(np.asarray(FAMILIES[fam](excited_block(params.n_osc, k, params.graph))(p)))
    return params, engine, reference_options, cases, np.stack(y0)


def _assemble(params, engine, reference_options, cases, tested, wall, results,
              tolerances) -> xr.Dataset:
    """The cross-check's Dataset: both sides' observables, each case's state class,
    and their differences."""
    import xarray as xr

    s = engine.name
    walls = [r[1] for r in results]
    ref = {k: np.stack([r[0][k] for r in results]) for k in results[0][0]}
    n = params.n_osc
    half_s = _half_difference(tested)
    half_r = _half_difference(ref)
    class_s = [state_class(int(h), n, PERIODIC if d <= tolerances.halves else IRREGULAR)
               for h, d in zip(tested["n_halc"], half_s)]
    class_r = [state_class(int(h), n, PERIODIC if d <= tolerances.halves_reference
                           else IRREGULAR) for h, d in zip(ref["n_halc"], half_r)]
    energy_s = 0.5 * np.sum(tested["amplitudes"] ** 2, -1)
    energy_r = 0.5 * np.sum(ref["amplitudes"] ** 2, -1)
    case, osc = ("case",), ("case", "osc")
    ds = xr.Dataset(
        {
            f"amplitudes_{s}": (osc, tested["amplitudes"]),
            "amplitudes_reference": (osc, ref["amplitudes"]),
            f"energy_{s}": (case, energy_s), "energy_reference": (case, energy_r),
            f"n_halc_{s}": (case, tested["n_halc"]),
            "n_halc_reference": (case, ref["n_halc"]),
            f"half_difference_{s}": (case, half_s),
            "half_difference_reference": (case, half_r),
            f"state_class_{s}": (case, class_s),
            "state_class_reference": (case, class_r),
            f"status_{s}": (case, tested["status"], flag_attributes()),
            "status_reference": (case, ref["status"], flag_attributes()),
            f"num_steps_{s}": (case, tested["num_steps"]),
            "num_steps_reference": (case, ref["num_steps"]),
            "num_events_reference": (case, ref["num_events"]),
            "stick_fraction_reference": (osc, ref["stick_fraction"]),
            "wall_time_s_reference": (case, np.array(walls)),
            "amplitude_error": (case, _amplitude_error(tested["amplitudes"],
                                                       ref["amplitudes"])),
            "energy_error": (case, np.abs(energy_s - energy_r) / np.maximum(1.0, energy_r)),
            "n_halc_agrees": (case, tested["n_halc"] == ref["n_halc"]),
            "class_agrees": (case, np.array(class_s) == np.array(class_r)),
        },
        coords={"v_d": (case, np.array([c[0] for c in cases])),
                "family": (case, [c[1] for c in cases]),
                "n_excited": (case, [c[2] for c in cases]), "osc": np.arange(1, n + 1)},
    )
    attrs = field_values(engine.options, f"{s}_") | field_values(reference_options,
                                                                 "reference_")
    attrs |= {k: v for k, v in chain_record(params).items() if k != "v_d"}
    attrs |= {k: v for k, v in engine.attributes().items() if f"{s}_{k}" not in attrs}
    attrs |= {f"wall_time_s_{s}": wall,
              f"periodic_tol_{s}": tolerances.halves,
              "periodic_tol_reference": tolerances.halves_reference,
              "paper": PAPER, "units": "dimensionless, eqs. (4)-(6) of the paper"}
    ds.attrs = {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                for k, v in attrs.items()}
    return ds


def _half_difference(obs) -> np.ndarray:
    """Largest change of an extremum between the two half windows, relative to
    max(1, largest amplitude), per case."""
    x_max, x_min = np.asarray(obs["x_max"]), np.asarray(obs["x_min"])
    scale = np.maximum(1.0, 0.5 * (x_max.max(1) - x_min.min(1)).max(-1))
    change = np.maximum(np.abs(x_max[:, 0] - x_max[:, 1]).max(-1),
                        np.abs(x_min[:, 0] - x_min[:, 1]).max(-1))
    return change / scale
