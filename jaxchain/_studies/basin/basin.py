"""Basin stability of the chain's states: the fraction of random initial states,
drawn from a stated box, that end in each state (Menck, Heitzig, Marwan & Kurths,
Nature Physics 9, 89-92 (2013); for friction oscillators Stender, Hoffmann &
Papangelo, Lubricants 8, 105 (2020))."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import math
from pathlib import Path

import jax
import numpy as np
from jaxtyping import ArrayLike, Float

from ..._physics.record import check_recordable
from ..._engine.checks import belt_speeds, check_params
from ..._engine.engines import AbstractEngine, as_engine
from ..._engine.horizon import AbstractHorizon
from ..._analysis.classify import classify
from ..._physics.initial import GivenState
from ..._engine.lanes import lane_params, run_lanes
from ..._engine.observers.crossings import PeakTimes
from ..._engine.observers.extrema import Extrema
from ..._engine.options import SimulationOptions
from ..._physics.params import ChainParams
from ..._analysis.states import PERIODIC
from ..._sweeps.sweep import sweep
from .classes import class_index, class_names, halc_clusters, wilson_interval
from .sampling import Box, sample_states
from ..._checks import check_count
from ..._engine.status import Status

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: The horizon of `basin_stability` by default: t_end = 2000, classified over
#: [1500, 2000].
BASIN_OPTIONS = SimulationOptions(t_end=2000.0, transient=1500.0)


def _key(key) -> jax.Array:
    """A PRNG key from an integer seed or a key (typed or raw uint32 data)."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        return jax.random.PRNGKey(int(key))
    if isinstance(key, jax.Array) and jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key
    if isinstance(key, (jax.Array, np.ndarray)) and key.dtype == np.uint32 \
            and key.shape == (2,):
        return jax.numpy.asarray(key)
    raise TypeError(f"key must be an integer seed or a JAX PRNG key, got {key!r}")


def _key_data(key) -> list[int]:
    if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    return np.asarray(key).ravel().tolist()


def _doubled(engine: AbstractEngine) -> AbstractEngine:
    """The engine of the convergence check: t_end doubled, the window of the same
    length at its end."""
    options = engine.options
    t_end = 2 * options.t_end
    longer = dataclasses.replace(options, t_end=t_end,
                                 transient=t_end - (options.t_end - options.transient))
    return dataclasses.replace(engine, options=longer)


def _check_run(params, v, states, engine, progress) -> dict:
    """The convergence subset at 2 t_end: n_halc, on_halc, status of shape
    (n_vd, n_check, ...), with peak times for the periodic/irregular class
    (`peak_times`) where the engine observes them (the smoothed one)."""
    n_vd, n = v.size, states.shape[0]
    lanes = lane_params(params, n_vd * n, v_d=np.repeat(v, n))
    y0 = np.tile(np.asarray(states), (n_vd, 1, 1))
    observers = (Extrema(), PeakTimes())
    if engine.can_observe(observers):
        out = run_lanes(lanes, y0, engine=engine, progress=progress, observers=observers)
    else:
        out = dataclasses.asdict(run_lanes(lanes, y0, engine=engine, progress=progress))
    return {k: np.asarray(out[k]).reshape((n_vd, n) + np.shape(out[k])[1:])
            for k in ("n_halc", "on_halc", "status", "peak_times") if k in out}


def basin_stability(params: ChainParams, v_d: Float[ArrayLike, " n_vd"], n_samples: int,
                    box: Box = Box(), key=0, *, solver=None,
                    options: AbstractHorizon | None = None,
                    engine: AbstractEngine | str = "smoothed", n_check: int | None = None,
                    batch_size: int = 64, store: str | Path | None = None,
                    resume: bool = False, overwrite: bool = False, client=None,
                    progress: bool = True) -> xr.Dataset:
    """The basin stability of each state of the chain at each belt speed: the
    fraction of `n_samples` initial states, drawn uniformly from `box` with `key`,
    that end in it, with 95 % Wilson intervals.

    The samples run through `sweep` (batched over the cores, each batch written to
    `store` as it finishes, resumable). Each final state is classified by n_HALC
    (`class_names`; for one oscillator "steady sliding" or "stick-slip"), by the
    number of separate groups of HALC oscillators (`halc_clusters`), and, on the
    convergence subset, as periodic or irregular by its time delays (`classify`,
    the paper's criterion of Section 3.3). Convergence in t_end: the first
    `n_check` samples run again to 2 t_end (window of the same length at the end);
    the fraction whose class changed is reported.

    **Arguments:**

    - `params`: chain parameters (`v_d` is replaced by each belt speed).
    - `v_d`: belt speeds, shape (n_vd,), dimensionless.
    - `n_samples`: initial states per belt speed (the same states at each).
    - `box`: the `Box` of initial states, x in [-2, 2], x' in [0, 2] by default.
    - `key`: an integer seed or a JAX PRNG key; kept in the result.
    - `solver`, `options`, `engine`: as for `simulate`; the horizon `BASIN_OPTIONS`
        (t_end = 2000) by default. The exact engine observes no peak times: its
        periodic fractions are NaN.
    - `n_check`: samples of the convergence check, min(n_samples, 50) by default;
        0 for none.
    - `batch_size`, `store`, `resume`, `overwrite`, `client`, `progress`: as for
        `sweep`
        (`client`: the samples run as batches on a Dask cluster; the convergence
        subset runs in this process).

    **Returns:**

    An `xarray.Dataset` with dims (v_d, sample, component, osc, class, cluster,
    check): `y0` (sample, component, osc), the initial states; `n_halc`,
    `clusters`, `class_index`, `status` (v_d, sample); `counts`, `fraction`,
    `ci_low`, `ci_high` (v_d, class); `cluster_counts`, `cluster_fraction`,
    `cluster_ci_low`, `cluster_ci_high` (v_d, cluster); `changed_fraction`
    (v_d), the share of the check subset whose class changed at 2 t_end;
    `periodic_fraction`, `periodic_ci_low`, `periodic_ci_high` (v_d), among the
    check subset's stick-slip states with enough peaks in the window to judge
    (`delay_spread`: 16 peaks of the reference oscillator). Attributes: every parameter and option,
    `key` (its data), `box_x`, `box_v`, `n_samples`, `n_check`.

    **Raises:**

    `ValidationError` for n_samples < 1, bad belt speeds or a bad `n_check`, and as
    `sweep`; `TypeError` for a key that is neither a seed nor a PRNG key.
    """
    params, engine, v, n_check, key = _check(params, v_d, n_samples, box, key, solver,
                                             options, engine, n_check)
    states = sample_states(key, box, int(n_samples), params.n_osc)
    ds = sweep(params, v, GivenState(states), engine=engine, batch_size=batch_size,
               store=store, resume=resume, overwrite=overwrite, client=client,
               progress=progress).load()
    out = _classified(params, v, states, ds)
    index = out["class_index"].values
    out = out.assign(**_convergence(params, v, states[:n_check], index[:, :n_check],
                                    engine, progress))
    out.attrs = {k: val for k, val in ds.attrs.items()
                 if k not in ("batches_total", "batches_done", "batches_run")}
    out.attrs |= {"key": _key_data(key), "box_x": list(box.x),
                  "box_v": list(box.v), "n_samples": int(n_samples), "n_check": int(n_check),
                  "method": "basin stability (Menck et al., Nature Physics 9, 89 (2013))",
                  "interval": "95 % Wilson score interval"}
    return out


def _check(params, v_d, n_samples, box, key, solver, options, engine, n_check) -> tuple:
    """The arguments of `basin_stability`, checked: (params, engine, v_d, n_check,
    key)."""
    params = check_params(params)
    if options is None and not isinstance(engine, AbstractEngine):
        options = BASIN_OPTIONS  # an engine value holds its own horizon
    engine = as_engine(engine, solver, options, params)
    v = belt_speeds(v_d)
    check_recordable(params)
    check_count("n_samples", n_samples)
    if not isinstance(box, Box):
        raise TypeError(f"box must be a jaxchain.Box, got {type(box).__name__}")
    n_check = min(n_samples, 50) if n_check is None else n_check
    check_count("n_check", n_check, 0, n_samples)
    return params, engine, v, n_check, _key(key)


def _classified(params: ChainParams, v, states, ds: xr.Dataset) -> xr.Dataset:
    """Each sample's class and HALC groups from the sweep `ds`, and the fractions
    of each, with their Wilson intervals."""
    import xarray as xr

    n_osc, n_samples = params.n_osc, states.shape[0]
    status = ds["status"].values
    index = class_index(ds["n_halc"].values, status, n_osc)
    clusters = np.where(status == Status.ok,
                        halc_clusters(ds["on_halc"].values, params.graph), -1)
    names = class_names(n_osc)
    counts = np.stack([(index == c).sum(-1) for c in range(len(names))], axis=-1)
    low, high = wilson_interval(counts, n_samples)
    n_clusters = max(1, n_osc // 2) + 1
    cluster_counts = np.stack([(clusters == c).sum(-1) for c in range(n_clusters)], axis=-1)
    c_low, c_high = wilson_interval(cluster_counts, n_samples)
    return xr.Dataset(
        {"y0": (("sample", "component", "osc"), np.asarray(states)),
         "n_halc": (("v_d", "sample"), ds["n_halc"].values),
         "clusters": (("v_d", "sample"), clusters),
         "class_index": (("v_d", "sample"), index),
         "status": (("v_d", "sample"), status),
         "counts": (("v_d", "class"), counts),
         "fraction": (("v_d", "class"), counts / n_samples),
         "ci_low": (("v_d", "class"), low), "ci_high": (("v_d", "class"), high),
         "cluster_counts": (("v_d", "cluster"), cluster_counts),
         "cluster_fraction": (("v_d", "cluster"), cluster_counts / n_samples),
         "cluster_ci_low": (("v_d", "cluster"), c_low),
         "cluster_ci_high": (("v_d", "cluster"), c_high)},
        coords={"v_d": v, "class": names, "cluster": np.arange(n_clusters),
                "component": ["x", "v"]})


def _convergence(params, v, states, index, engine, progress) -> dict:
    """The share of the check subset whose class changed at 2 t_end, and the
    periodic share among its stick-slip states (by time delays)."""
    nan = np.full(v.size, math.nan)
    if states.shape[0] == 0:
        return {"changed_fraction": ("v_d", nan), "periodic_fraction": ("v_d", nan),
                "periodic_ci_low": ("v_d", nan), "periodic_ci_high": ("v_d", nan)}
    longer = _doubled(engine)
    run = _check_run(params, v, states, longer, progress)
    index2 = class_index(run["n_halc"], run["status"], params.n_osc)
    changed = (index2 != index).mean(-1)
    periodic, moving = np.zeros(v.size, int), np.zeros(v.size, int)
    for i in range(v.size):
        for j in range(states.shape[0]):
            if run["status"][i, j] != Status.ok or run["n_halc"][i, j] == 0 \
                    or "peak_times" not in run:
                continue
            verdict = classify(run["peak_times"][i, j], run["on_halc"][i, j],
                               int(run["n_halc"][i, j]), 0, math.nan, math.nan,
                               longer.options.transient, boundary=params.graph)
            if not math.isfinite(verdict["delay_spread"]):  # too few peaks to judge
                continue
            moving[i] += 1
            periodic[i] += verdict["class_delays"] == PERIODIC
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(moving > 0, periodic / np.maximum(moving, 1), math.nan)
        low, high = wilson_interval(periodic, np.maximum(moving, 1))
    low, high = np.where(moving > 0, low, math.nan), np.where(moving > 0, high, math.nan)
    return {"changed_fraction": ("v_d", changed), "periodic_fraction": ("v_d", share),
            "periodic_ci_low": ("v_d", low), "periodic_ci_high": ("v_d", high)}
