"""`sweep`: a grid of parameter values x initial conditions through the engine,
batch by batch, each batch stored as it finishes; a killed sweep resumes where it
stopped.

With a Dask client, each batch is one task on its cluster (`run_tasks`): the
worker that takes it integrates its trajectories with the sweep's engine, on its
own devices, writes them into their region of the store and flags the batch done.
The cluster computes the same programs as this process (the same block of the
queue schedule, chosen here), so on the same kind of device (and XLA_FLAGS) its
result equals the in-process sweep to the last bit. A lost worker's batches are
run again by Dask; a batch written twice is written identically. If the scheduler
goes away, the flagged batches stay in the store, and `resume=True` (in process or
on any cluster) runs the others."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path

import diffrax
import jax
import numpy as np
from jaxtyping import ArrayLike, Float

from .._engine.progress import tqdm
from .._physics.record import check_recordable
from .._engine.checks import check_params
from .._engine.engines import AbstractEngine, as_engine
from .._engine.horizon import AbstractHorizon
from .._physics.initial import AbstractInitialCondition
from .._engine.lanes import block_size, expected_cost, run_lanes, take_lanes
from .._physics.params import ChainParams
from .datasets import observables_variables, run_attributes
from .result_store import settings_json, settings_key
from .._analysis.fronts import propagating_fronts
from .grid import ENGINE_PARAMETERS, SweepGrid
from .zarr_store import SweepStore
from .._checks import check_count
from .._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: The kind of result in the key of a sweep's store (`settings_key`).
KIND = "sweep"


def sweep(params: ChainParams, values: Float[ArrayLike, " n_values"],
          ics: AbstractInitialCondition | Mapping[str, AbstractInitialCondition],
          solver: diffrax.AbstractSolver | str | None = None,
          options: AbstractHorizon | None = None, *,
          engine: AbstractEngine | str = "smoothed",
          where: Callable | str = "v_d", batch_size: int = 64,
          store: str | Path | None = None, resume: bool = False, overwrite: bool = False,
          schedule: str | None = None, client=None, progress: bool = True) -> xr.Dataset:
    """Run every (value, initial condition) pair of a grid, batch by batch, and
    write each batch to a zarr store as it finishes: the bifurcation diagram of
    Fig. 3(b) of the paper when `where` is the belt speed.

    The trajectories are laid out value by value and cut into batches of
    `batch_size`; each batch runs through `run_lanes` (all cores), so memory is set
    by the batch size, never by the size of the grid. With a `store`, a finished
    batch is written into its own zarr chunks and then flagged done; a batch cut
    short by a crash or a kill is not flagged, and `resume=True` redoes it while
    skipping every flagged one. The store is keyed by a hash of every setting that
    determines the result (`settings_key`: the parameters, the swept values, the
    initial conditions, the engine with its solver and options, and the batch
    size), and is never resumed with other settings.

    With a Dask `client`, each batch is one task on its cluster (module docstring).

    **Arguments:**

    - `params`: the chain parameters; the field `where` is replaced by each value.
    - `values`: the values of the swept parameter, shape (n_values,), dimensionless.
    - `ics`: initial conditions, batched along the leading axis of their array
        fields (`localized_family(N, "eq8")`, `GivenState(y0)` with y0 of shape
        (n, 2, N)), or a dict of such families by name. They are evaluated with
        each value (eq. (8) starts from that belt speed's steady sliding).
    - `solver`, `options`, `engine`: as for `simulate` ("smoothed" by default, or
        "exact", or an engine value).
    - `where`: the swept parameter: a name (`"v_d"`, `"eta_c"`, `"xi"`, `"eps"`,
        ...) or a lens such as `lambda p: p.eta_c` (see `parameter_name`).
    - `batch_size`: trajectories per batch (>= 1): the unit of storing and resuming.
    - `store`: a folder for the zarr store (`*.zarr`), or None (in memory only).
    - `resume`: continue the sweep in `store`, skipping its finished batches, or
        an overwrite of `store` with these settings that was cut short.
    - `overwrite`: replace the sweep that `store` holds by a new one, built
        beside it (`<store>.overwrite`) and swapped in once complete: until then
        the old one stays whole (a killed overwrite is finished by `resume=True`).
    - `schedule`: "queue" or "vmap" (see `run_lanes`); on a cluster, each worker's
        default by default (the queue on CPUs, vmap on GPUs).
    - `client`: a `distributed.Client` to run the batches on its cluster (with a
        `store` that this process and every worker share); None: in this process.
    - `progress`: a tqdm bar over the trajectories (batches on a cluster).

    **Returns:**

    An `xarray.Dataset` with dims (name, ic, osc), where name is the swept field
    (`v_d` by default): every observable of `simulate` (amplitudes and the other
    per-oscillator fields (name, ic, osc); energy, n_halc, num_steps, status
    (name, ic); n_halc_halves (name, ic, half); y_initial, y_final (name, ic,
    component, osc)) and `front` (`propagating_fronts`). Along `ic`, the
    coordinates `family` and `n_excited`. Attributes: every parameter and option,
    the engine, the settings and their key, `batches_total`, `batches_done` and
    `batches_run` (by this call). With a store the variables are read from it
    lazily (dask arrays; `.load()` reads them all).

    **Raises:**

    `ValidationError` for a bad value (naming the parameter), an empty grid, initial
    conditions of the wrong shape, batch_size < 1, an existing store without
    `resume` or `overwrite`, a store of other settings (naming those that
    differ) or of something else than a sweep (left untouched), or a `client`
    without a `store`. `RuntimeError` when the scheduler of `client` goes away,
    or when batches the cluster ran are not in the store.
    """
    params = check_params(params)
    engine = as_engine(engine, solver, options, params)
    plan = _plan(params, values, ics, engine, where, batch_size, store, resume, overwrite,
                 schedule, client)
    if client is not None:
        _run_on_cluster(client, plan, progress)
        parts = []
    else:
        parts = _run_here(plan, progress)
    return _assemble(plan, parts)


@dataclasses.dataclass(frozen=True)
class _Plan:
    """A checked sweep: its batches, its store (None in memory) and where they go
    (`target`), and which batches remain (`todo`)."""

    work: "_Batches"
    store: SweepStore | None
    target: SweepStore | None
    done: np.ndarray
    todo: list


def _plan(params, values, ics, engine, where, batch_size, store, resume, overwrite,
          schedule, client) -> _Plan:
    """Check every argument of `sweep` and plan its batches and store."""
    check_recordable(params)
    grid = SweepGrid.build(params, where, values, ics)
    check_count("batch_size", batch_size)
    if resume and overwrite:
        raise ValidationError("resume and overwrite exclude each other")
    if grid.name in ENGINE_PARAMETERS:  # the engine refuses a parameter it lacks
        engine.with_parameter(grid.name, grid.values[0])
    if client is not None and store is None:
        raise ValidationError("store: a sweep on a Dask cluster needs a store its workers "
                              "can reach")
    n, name = grid.n_trajectories, grid.name
    n_batches = -(-n // batch_size)
    settings = dict(
        params={f.name: getattr(params, f.name) for f in dataclasses.fields(params)
                if f.name != name},
        where=name, values=grid.values, ics=grid.families, engine=engine,
        batch_size=batch_size)
    key, text = settings_key(KIND, **settings), settings_json(KIND, **settings)
    st = SweepStore(store) if store is not None else None
    target = None if st is None else _target(st, key, text, resume, overwrite)
    done = target.done() if target is not None and target.exists() \
        else np.zeros(n_batches, dtype=bool)
    coords = {name: grid.values, "ic": np.arange(grid.n_ics), **grid.ic_coords(),
              "osc": np.arange(1, params.n_osc + 1),
              "component": np.array(["x", "v"], dtype=object)}
    attrs = run_attributes(params, engine, ",".join(grid.families), name)
    attrs |= {"swept": name, "batch_size": batch_size, "settings_key": key,
              "settings": text}
    work = _Batches(grid, batch_size, engine, schedule,
                    block_size(batch_size, len(jax.local_devices())), coords, attrs)
    return _Plan(work, st, target, done, [b for b in range(n_batches) if not done[b]])


def _run_on_cluster(client, plan: _Plan, progress: bool) -> None:
    """Each remaining batch as one task on the cluster of `client`, written into the
    store by the worker that runs it."""
    from .._engine.cluster import run_tasks

    work, todo, target = plan.work, plan.todo, plan.target
    n_batches, key = plan.done.size, work.attrs["settings_key"]
    with tqdm(total=n_batches, initial=n_batches - len(todo), desc="sweep",
              unit="batch", disable=not progress) as bar:
        run_tasks(client, _Batches.store, work,
                  [(target.path.resolve(), b) for b in todo],
                  [f"sweep-{key[:12]}-batch-{b}-{uuid.uuid4().hex[:8]}" for b in todo],
                  bar, costs=[work.cost(b) for b in todo])
    missing = [b for b in todo if not (target.exists() and target.done()[b])]
    if missing:
        raise RuntimeError(f"the cluster ran {len(todo)} batches but {len(missing)} "
                           f"are not in {target.path.resolve()}: its workers write to "
                           "a file system this process does not see; give a store on "
                           "a shared one")


def _run_here(plan: _Plan, progress: bool) -> list:
    """Each remaining batch in this process: written into the store, or returned
    (in memory, without a store)."""
    work, parts = plan.work, []
    initial = sum(work.size(b) for b in np.flatnonzero(plan.done))
    with tqdm(total=work.grid.n_trajectories, initial=initial, desc="sweep",
              unit="trajectory", disable=not progress, smoothing=0.1) as bar:
        for b in plan.todo:
            if plan.store is None:
                parts.append(work.run(b, bar))
            else:
                work.store(plan.target.path, b, bar)
    return parts


def _assemble(plan: _Plan, parts: list) -> xr.Dataset:
    """The sweep's Dataset on its grid (name, ic, ...), read from the store (an
    overwrite swapped in first) or joined from the batches in memory."""
    import xarray as xr

    st, work = plan.store, plan.work
    n_batches, grid = plan.done.size, work.grid
    if st is not None and plan.target.path != st.path:  # an overwrite, now complete
        st.swap_in(plan.target)
    if st is None:
        flat = xr.concat(parts, "trajectory").assign_coords(work.coords)
        flat = flat.assign_attrs(work.attrs)
        n_done = n_batches
    else:
        flat = st.open()
        n_done = int(np.sum(flat["batch_done"].values == 1))
    ds = _on_grid(flat, grid.name, grid.values.size, grid.n_ics)
    ds.attrs |= {"batches_total": n_batches, "batches_done": n_done,
                 "batches_run": len(plan.todo), "store": str(st.path) if st else ""}
    return ds


def _target(st: SweepStore, key: str, text: str, resume: bool,
            overwrite: bool) -> SweepStore:
    """The store that the batches of the sweep of `key` go to, for the store `st`
    asked for:

    - nothing at `st`: `st` itself, a new store.
    - `overwrite`: `st` itself if it holds nothing, else a new store beside it
        (`st.pending()`, replacing any earlier unfinished overwrite), swapped in
        when complete; the old one stays whole until then.
    - `resume`: `st` if it holds this sweep; else the unfinished overwrite of
        this sweep beside it (`pending`), if there is one, to finish and swap in.

    A swap cut short by a kill is finished first (`recover`).

    **Raises:**

    `ValidationError` naming the path when something other than a jaxchain sweep
    store is at `st` (or at `st.pending()` on overwrite), which is left untouched;
    when `st` holds a sweep of other settings on `resume` (naming them); when it
    holds a sweep and neither `resume` nor `overwrite` is given.
    """
    st.recover()
    st.require_sweep("overwrite" if overwrite else "resume" if resume else "write into")
    if not st.is_sweep():
        return st
    pending = st.pending()
    if overwrite:
        pending.require_sweep("overwrite")
        if pending.occupied():
            pending.remove()
        return pending
    if not resume:
        raise ValidationError(f"store {st.path} exists: resume it or overwrite it")
    if st.key() != key and pending.key() == key:
        return pending
    st.check(key, text)
    return st


@dataclasses.dataclass(frozen=True)
class _Batches:
    """The batches of a sweep: batch b holds the trajectories [b B, (b + 1) B) of
    the grid, B the batch size, run through `run_lanes` with a fixed `block`
    (chosen by the process that plans the sweep, so that a batch is the same
    compiled program wherever it runs)."""

    grid: SweepGrid
    batch_size: int
    engine: AbstractEngine
    schedule: str | None
    block: int
    coords: dict
    attrs: dict

    def size(self, b: int) -> int:
        return min(self.grid.n_trajectories, (b + 1) * self.batch_size) - b * self.batch_size

    def lanes(self, b: int):
        start = b * self.batch_size
        return self.grid.lanes(start, start + self.size(b))

    def cost(self, b: int) -> float:
        """A proxy of batch b's cost: the sum of its lanes' `expected_cost`."""
        return float(np.sum(expected_cost(*self.lanes(b))))

    def run(self, b: int, progress: bool | tqdm = False, devices=None) -> xr.Dataset:
        """Batch b's observables, dims (trajectory, ...), on `devices` (all of this
        process's by default)."""
        import xarray as xr

        lane_params, y0 = self.lanes(b)
        if self.grid.name not in ENGINE_PARAMETERS:
            obs = run_lanes(lane_params, y0, engine=self.engine, schedule=self.schedule,
                            block=self.block, progress=progress, devices=devices)
        else:  # one run of the lanes per value of the engine's setting
            start = b * self.batch_size
            values = self.grid.lane_values(start, start + self.size(b))
            parts, order = [], []
            for value in np.unique(values):
                lanes = np.flatnonzero(values == value)
                engine = self.engine.with_parameter(self.grid.name, np.asarray(value))
                parts.append(run_lanes(take_lanes(lane_params, lanes), y0[lanes],
                                       engine=engine, schedule=self.schedule,
                                       block=self.block, progress=progress,
                                       devices=devices))
                order.append(lanes)
            back = np.argsort(np.concatenate(order))
            obs = jax.tree_util.tree_map(lambda *x: np.concatenate(x)[back], *parts)
        return xr.Dataset(observables_variables(obs, ("trajectory",)))

    def store(self, path: Path, b: int, progress: bool | tqdm = False,
              devices=None) -> None:
        """Run batch b and write it into its region of the store at `path`
        (creating the store's layout if no batch made it yet), then flag it done:
        the task of the Dask route.

        **Raises:**

        `RuntimeError` when the store at `path` holds another sweep (it was
        overwritten with other settings while this batch ran), before and after
        making the layout: a batch of a cancelled run never lands in another."""
        batch = self.run(b, progress, devices)
        st = SweepStore(path)
        if not st.exists():
            st.create(batch, self.grid.n_trajectories, self.batch_size, self.coords,
                      self.attrs)
        if st.settings()[0] != self.attrs["settings_key"]:
            raise RuntimeError(f"{path} now holds another sweep: batch {b} of this one "
                               "is not written")
        st.write(b, b * self.batch_size, batch)


def open_sweep(store: str | Path) -> xr.Dataset:
    """The sweep stored in `store`, read lazily (dask arrays), as `sweep` returns
    it. Batches that have not finished read as NaN (floats), -1 (status, n_halc)
    or False, and `batches_done` < `batches_total`.

    **Raises:**

    `ValidationError` when `store` holds no sweep.
    """
    st = SweepStore(store)
    if not st.is_sweep():
        raise ValidationError(f"store {store} holds no sweep")
    flat = st.open()
    name = flat.attrs["swept"]
    ds = _on_grid(flat, name, flat.sizes[name], flat.sizes["ic"])
    done = flat["batch_done"].values == 1
    ds.attrs |= {"batches_total": done.size, "batches_done": int(done.sum()),
                 "store": str(st.path)}
    return ds


def _on_grid(flat: xr.Dataset, name: str, n_values: int, n_ics: int) -> xr.Dataset:
    """The flat `trajectory` axis of a stored sweep as the grid (name, ic), with
    the propagating fronts flagged."""
    import xarray as xr

    data = {}
    for k, var in flat.data_vars.items():
        if "trajectory" in var.dims:
            data[k] = ((name, "ic", *var.dims[1:]),
                       var.data.reshape(n_values, n_ics, *var.shape[1:]), var.attrs)
    coords = {c: v for c, v in flat.coords.items() if "trajectory" not in v.dims}
    ds = xr.Dataset(data, coords=coords, attrs=dict(flat.attrs))
    ds["front"] = propagating_fronts(ds)
    return ds
