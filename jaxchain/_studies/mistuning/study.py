"""`mistuning_study`: the paper's localized states on randomly mistuned chains, draw
by draw: the Fig. 4 staircase, basin stability, where the vibration sits, the
edges of the bistable range, and the localization lengths against Anderson's."""

from __future__ import annotations

from typing import TYPE_CHECKING

import concurrent.futures
import math
from pathlib import Path

import numpy as np

from ..._engine.progress import tqdm
from ..._physics.chain import require_line
from ..._physics.record import check_recordable
from ..basin.basin import _key, _key_data
from ..basin.sampling import Box, sample_states
from ..._bifurcation.hopf import hopf_point
from ..._engine.engines import AbstractEngine, Smoothed, as_engine
from ..._engine.checks import check_options, check_params, check_run
from ..._engine.horizon import AbstractHorizon
from ..._engine.options import SimulationOptions
from ..._engine.status import Status
from ..._physics.initial import GivenState, excited_block, localized_family
from ..._analysis.localization import damped_decay, localization_factor, passband_frequency
from ..._physics.model import jacobian
from ..._physics.mistuning import mistune
from ..._physics.params import (
    chain_or_default, ChainParams, single_oscillator, with_fields, with_parameter,
)
from ..._sweeps.datasets import run_attributes, save_dataset
from ..._sweeps.result_store import CsvStore, settings_key
from ..._sweeps.sweep import sweep
from .edges import EDGE_OPTIONS, localized_fold, localized_orbit, upper_edges
from .summary import envelope_decay
from ..._checks import check_count
from ..._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Mistuning strengths sigma / eta_c of the study by default.
STUDY_SIGMAS = (0.0, 0.5, 1.0, 2.0, 4.0)
#: Belt speeds of the staircase and of basin stability: below, at and above the
#: paper's v_d = 1.5, all inside the bistable range (1.15, 1.80) of the ring.
STUDY_VD = (1.3, 1.5, 1.7)
#: The horizon of each run (the horizon of `basin_stability` by default).
STUDY_OPTIONS = SimulationOptions(t_end=2000.0, transient=1500.0)
#: Phases per cell of the localization factor table: the band centre and pi/3.
THETAS = (math.pi / 2, math.pi / 3)
#: sigma / eta_c of the localization factor table.
TABLE_SIGMAS = (0.25, 0.5, 1.0, 2.0, 4.0)


def study_chains(params: ChainParams, sigmas, n_draws: int) -> list[tuple[int, int, ChainParams]]:
    """(sigma index, draw, chain) of the study: draw d of every sigma > 0 is
    `mistune(params, sigma eta_c, seed=d)`, the same normal draws scaled (common
    random numbers across sigma), its `Mistuning` record dropped (the study keeps
    sigma and the draw) and its stiffness of shape (n_osc,); sigma = 0 is the one
    homogeneous chain."""
    out = []
    for i, s in enumerate(sigmas):
        for d in range(1 if s == 0 else n_draws):
            chain = mistune(params, float(s) * float(params.eta_c), d)
            # the record is static metadata: dropped, and the stiffness always one
            # value per oscillator, so that every chain runs the one compiled program
            stiffness = np.broadcast_to(np.asarray(chain.stiffness, float), (params.n_osc,))
            out.append((i, d, with_fields(chain, mistuning=None, stiffness=stiffness.copy())))
    return out


def mistuning_study(params: ChainParams | None = None, sigmas=STUDY_SIGMAS,
                    n_draws: int = 8, *, v_d=STUDY_VD, n_samples: int = 8, box: Box = Box(),
                    key=0, n_folds: int = 1, engine: AbstractEngine = Smoothed(),
                    options: AbstractHorizon = STUDY_OPTIONS,
                    edge_options: AbstractHorizon = EDGE_OPTIONS,
                    out: str | Path | None = None,
                    resume: bool = False, overwrite: bool = False, client=None,
                    progress: bool = True) -> xr.Dataset:
    """What random stiffness mistuning (Anderson localization of the linear modes)
    does to the friction-localized states of eq. (5): the paper's open question
    (Section 4).

    For each sigma / eta_c in `sigmas` and each of `n_draws` mistuning draws
    (`study_chains`), one `sweep` over the belt speeds `v_d` runs the Fig. 4
    staircase (eq. (8) with k = 1..N excited) and `n_samples` random initial
    states from `box` (the same for every chain), each chain into its own zarr
    store. Then, per chain: the Hopf point of steady sliding (`hopf_point`), the
    largest belt speed at which the single-site state at each oscillator survives
    (`upper_edges`, bisection of simulations), and for the first `n_folds` draws
    of each sigma the fold of that state at the oscillator of the highest edge by
    shooting (`localized_fold`). Beside them the localization factor of the linear
    chain (`localization_factor`) at the band centre, at theta = pi/3 and at the
    frequency of the single-site state.

    **Arguments:**

    - `params`: the chain (v_d is replaced by each belt speed); its stiffness is
        replaced by each draw's.
    - `sigmas`: sigma / eta_c values (>= 0), shape (n_sigma,).
    - `n_draws`: mistuning draws per sigma > 0 (>= 1).
    - `v_d`: belt speeds, shape (n_vd,), dimensionless.
    - `n_samples`: random initial states per chain and belt speed (>= 0).
    - `box`, `key`: the `Box` of random initial states and the seed or key.
    - `n_folds`: draws per sigma whose upper edge is refined by shooting (>= 0).
    - `engine`: the smoothed engine (`Smoothed()` by default: eps = 1e-3, Ros34PW2
        at tolerances that follow eps) of every run, whose eps is also that of the
        Hopf points and of shooting; recorded in the attributes (`eps`, `solver`,
        `rtol`, `atol`).
    - `options`: the horizon of each run (t_end, transient, chunk_length;
        `STUDY_OPTIONS` by default), the engine's other settings kept.
    - `edge_options`: the horizon of the bisection (`EDGE_OPTIONS`).
    - `out`: a folder for the stores (chains/*.zarr, edges.nc, folds.csv) and
        mistuning.nc; None keeps everything in memory.
    - `resume`: continue the stores in `out`; `overwrite`: start them again.
    - `client`: a `distributed.Client`: every chain's sweep is submitted to its
        cluster at once (`sweep(client=...)`, each chain one task), with `out` on a
        file system its workers share; the upper edges and folds run in this
        process.
    - `progress`: progress bars.

    **Returns:**

    An `xarray.Dataset` with dims (sigma, draw, v_d, k, sample, osc, theta):
    `deviations` (sigma, draw, osc), delta_n (NaN for draws sigma = 0 does not
    have); `staircase_n_halc`, `staircase_status` (sigma, draw, v_d, k);
    `staircase_amplitudes`, `staircase_on_halc` (sigma, draw, v_d, k, osc);
    `basin_n_halc`, `basin_status` (sigma, draw, v_d, sample), `basin_on_halc`
    (sigma, draw, v_d, sample, osc); `hopf_vd` (sigma, draw); `site_edge`
    (sigma, draw, osc) and `upper_edge` (sigma, draw); `fold_vd`, `fold_site`
    (sigma, draw), NaN / -1 where not computed; `gamma`, `gamma_error` (sigma,
    theta); `state_gamma`, `state_gamma_error` (sigma), the linear localization
    factor at the single-site state's frequency; `envelope_decay` (sigma, draw),
    the fitted decay per cell of the single-site state's amplitudes. Attributes:
    every parameter and option, the chain record, `key`, `n_samples`, the state's
    `state_period` and `edge_resolution`.

    **Raises:**

    `ValidationError` for a bad count, sigma or belt speed, an engine that does not
    smooth (its Hopf points and damping are the smoothed model's), and as `sweep`.
    """
    params, sigmas, v, engine, edge_options, key, out = _check_study(
        params, sigmas, n_draws, v_d, n_samples, n_folds, key, engine, options,
        edge_options, out, resume, overwrite)
    run = _run_study(params, sigmas, n_draws, v, n_samples, box, key, n_folds, engine,
                     edge_options, out, resume, overwrite, client, progress)
    study = _assemble_study(params, sigmas, n_draws, v, n_samples, box, key, engine, run)
    if out is not None:
        save_dataset(study, out / "mistuning.nc")
    return study


def _check_study(params, sigmas, n_draws, v_d, n_samples, n_folds, key, engine, options,
                 edge_options, out, resume, overwrite):
    """Every argument of `mistuning_study` checked once: (params, sigmas, v_d,
    engine, edge_options, key, out), the chain the default ring where None, sigmas
    an array, the engine the smoothed one over the horizon of `options`, the key a
    PRNG key and out a `Path` or None."""
    params = check_params(chain_or_default(params))
    engine = as_engine(engine).as_smoothed("the mistuning study")
    params, _, options, v = check_run(params, engine.solver, options, v_d)
    engine = engine.with_horizon(options)
    require_line(params, "the mistuning study")
    check_recordable(params)
    sigmas = np.atleast_1d(np.asarray(sigmas, dtype=float))
    if sigmas.ndim != 1 or sigmas.size == 0 or not np.all(np.isfinite(sigmas)) \
            or np.any(sigmas < 0):
        raise ValidationError(f"sigmas: give sigma / eta_c values >= 0, got {sigmas.tolist()}")
    for name, value, least in (("n_draws", n_draws, 1), ("n_samples", n_samples, 0),
                               ("n_folds", n_folds, 0)):
        check_count(name, value, least)
    if resume and overwrite:
        raise ValidationError("resume and overwrite exclude each other")
    edge_options = check_options(edge_options)
    out = Path(out) if out is not None else None
    return params, sigmas, v, engine, edge_options, _key(key), out


def _run_study(params, sigmas, n_draws, v, n_samples, box, key, n_folds, engine,
               edge_options, out, resume, overwrite, client, progress) -> dict:
    """The computations of `mistuning_study`, as NumPy arrays and numbers by name:
    the sweeps of every chain (`_run_sweeps`), the Hopf points, upper edges and
    folds (`_run_edges`), and the single-site state's linear localization
    (`_run_state`)."""
    n = params.n_osc
    samples = np.asarray(sample_states(key, box, int(n_samples), n)) if n_samples else None
    chains = study_chains(params, sigmas, n_draws)
    ics = {"eq8": localized_family(n, "eq8", params.graph)}
    if samples is not None:
        ics["random"] = GivenState(samples)
    run = _run_sweeps(chains, n, sigmas, n_draws, v, n_samples, ics, engine, out, resume,
                      overwrite, client, progress)
    run |= _run_edges(chains, sigmas, n_draws, n, n_folds, engine, edge_options, out,
                      progress)
    run |= _run_state(params, sigmas, engine)
    k_index = int(np.argmin(np.abs(v - 1.5)))
    run["envelope_decay"] = envelope_decay(run["staircase_amplitudes"][:, :, k_index, 0],
                                           run["staircase_n_halc"][:, :, k_index, 0],
                                           params.boundary)
    return run


def _run_sweeps(chains, n, sigmas, n_draws, v, n_samples, ics, engine, out, resume,
                overwrite, client, progress) -> dict:
    """One `sweep` per chain (each its own store under out/chains, on the cluster of
    `client` all at once): the staircase's and the random states' results by
    (sigma, draw), and the deviations of each chain."""
    shape = (sigmas.size, n_draws, v.size)
    data = {"staircase_n_halc": np.full(shape + (n,), -1),
            "staircase_status": np.full(shape + (n,), Status.not_run),
            "staircase_amplitudes": np.full(shape + (n, n), np.nan),
            "staircase_on_halc": np.zeros(shape + (n, n), dtype=bool),
            "basin_n_halc": np.full(shape + (n_samples,), -1),
            "basin_status": np.full(shape + (n_samples,), Status.not_run),
            "basin_on_halc": np.zeros(shape + (n_samples, n), dtype=bool)}
    deviations = np.full((sigmas.size, n_draws, n), np.nan)
    def chain_sweep(i, d, chain):
        store = out / "chains" / f"sigma{sigmas[i]:g}_draw{d}.zarr" if out else None
        exists = store is not None and store.exists()
        return sweep(chain, v, ics, engine=engine,
                     batch_size=v.size * (n + n_samples),
                     store=store, resume=resume and exists, overwrite=overwrite and exists,
                     client=client, progress=False).load()

    bar = tqdm(total=len(chains), desc="mistuned chains", unit="chain", disable=not progress)
    with bar, concurrent.futures.ThreadPoolExecutor(len(chains) if client else 1) as pool:
        # on a cluster, every chain's sweep waits on its task at once
        sweeps = [pool.submit(chain_sweep, *c) for c in chains]
        for (i, d, chain), future in zip(chains, sweeps):
            ds = future.result()
            bar.update(1)
            deviations[i, d] = np.broadcast_to(np.asarray(chain.stiffness, dtype=float),
                                               (n,)) - 1
            stair, rand = slice(0, n), slice(n, n + n_samples)
            data["staircase_n_halc"][i, d] = ds["n_halc"].values[:, stair]
            data["staircase_status"][i, d] = ds["status"].values[:, stair]
            data["staircase_amplitudes"][i, d] = ds["amplitudes"].values[:, stair]
            data["staircase_on_halc"][i, d] = ds["on_halc"].values[:, stair]
            data["basin_n_halc"][i, d] = ds["n_halc"].values[:, rand]
            data["basin_status"][i, d] = ds["status"].values[:, rand]
            data["basin_on_halc"][i, d] = ds["on_halc"].values[:, rand]
    return data | {"deviations": deviations}


def _run_edges(chains, sigmas, n_draws, n, n_folds, engine, edge_options, out,
               progress) -> dict:
    """The upper edge of the single-site state at each oscillator of every chain
    (`upper_edges`), their highest, the Hopf point of each chain, and the folds by
    shooting of the first `n_folds` draws (`_folds`), all of the smoothed `engine`'s
    model."""
    edges = upper_edges([c for *_, c in chains], engine=engine, options=edge_options,
                        store=out / "edges.nc" if out else None, progress=progress)
    site_edge = np.full((sigmas.size, n_draws, n), np.nan)
    hopf = np.full((sigmas.size, n_draws), np.nan)
    for c, (i, d, chain) in enumerate(chains):
        site_edge[i, d] = edges["edge"].values[c]
        hopf[i, d] = float(np.max(hopf_point(chain, engine=engine).v_d))
    with np.errstate(invalid="ignore"):
        upper = np.where(np.all(np.isnan(site_edge), -1), np.nan,
                         np.nanmax(np.where(np.isnan(site_edge), -np.inf, site_edge), -1))
    fold, fold_site = _folds(chains, site_edge, n_folds, engine, out, progress)
    return {"site_edge": site_edge, "hopf_vd": hopf, "upper_edge": upper, "fold_vd": fold,
            "fold_site": fold_site, "edge_resolution": edges.attrs["resolution"]}


def _run_state(params: ChainParams, sigmas, engine: Smoothed) -> dict:
    """The single-site state of the homogeneous chain at v_d = 1.5 (its period and
    the damping about sliding at its site, of the smoothed `engine`'s model), and the linear
    chain's localization factor for each sigma at the band centre, at theta = pi/3
    (`THETAS`) and at the state's frequency."""
    centre = int(np.flatnonzero(excited_block(params.n_osc, 1, params.graph))[0])
    orbit, _ = localized_orbit(with_parameter(params, "v_d", 1.5), centre,
                               engine=engine.simulating())
    period = float(orbit.period) if orbit is not None else math.nan
    omega2 = (2 * math.pi / period) ** 2
    eta_c = float(params.eta_c)
    damping = _sliding_damping(with_parameter(params, "v_d", 1.5), centre, engine)
    gamma = np.zeros((sigmas.size, len(THETAS)))
    gamma_err = np.zeros_like(gamma)
    state_gamma, state_err = np.zeros(sigmas.size), np.zeros(sigmas.size)
    for i, s in enumerate(sigmas):
        g, e = localization_factor(eta_c, s * eta_c, passband_frequency(eta_c, np.array(THETAS)))
        gamma[i], gamma_err[i] = np.asarray(g), np.asarray(e)
        if math.isfinite(omega2):
            g, e = localization_factor(eta_c, s * eta_c, omega2)
            state_gamma[i], state_err[i] = float(g), float(e)
        else:
            state_gamma[i] = state_err[i] = math.nan
    return {"gamma": gamma, "gamma_error": gamma_err, "state_gamma": state_gamma,
            "state_gamma_error": state_err, "state_period": period, "state_omega2": omega2,
            "sliding_damping": damping,
            "state_damped_decay": float(damped_decay(eta_c, omega2, damping))}


def _assemble_study(params, sigmas, n_draws, v, n_samples, box, key, engine,
                    run: dict) -> xr.Dataset:
    """The dataset of `mistuning_study` from the arrays of `_run_study`."""
    import xarray as xr

    n = params.n_osc
    dims = ("sigma", "draw", "v_d")
    layout = {"deviations": ("sigma", "draw", "osc"),
              "staircase_n_halc": dims + ("k",), "staircase_status": dims + ("k",),
              "staircase_amplitudes": dims + ("k", "osc"),
              "staircase_on_halc": dims + ("k", "osc"),
              "basin_n_halc": dims + ("sample",), "basin_status": dims + ("sample",),
              "basin_on_halc": dims + ("sample", "osc"),
              "hopf_vd": ("sigma", "draw"), "site_edge": ("sigma", "draw", "osc"),
              "upper_edge": ("sigma", "draw"), "fold_vd": ("sigma", "draw"),
              "fold_site": ("sigma", "draw"), "gamma": ("sigma", "theta"),
              "gamma_error": ("sigma", "theta"), "state_gamma": "sigma",
              "state_gamma_error": "sigma", "envelope_decay": ("sigma", "draw")}
    return xr.Dataset(
        {name: (dims_of, run[name]) for name, dims_of in layout.items()},
        coords={"sigma": sigmas, "draw": np.arange(n_draws), "v_d": v,
                "k": np.arange(1, n + 1), "osc": np.arange(1, n + 1),
                "sample": np.arange(n_samples), "theta": np.array(THETAS)},
        attrs=run_attributes(params, engine, "eq8,random", "v_d") | {
               "n_draws": int(n_draws),
               "n_samples": int(n_samples), "key": _key_data(key), "box_x": list(box.x),
               "box_v": list(box.v), "state_period": run["state_period"],
               "state_omega2": run["state_omega2"],
               "sliding_damping": run["sliding_damping"],
               "state_damped_decay": run["state_damped_decay"],
               "edge_resolution": run["edge_resolution"],
               "sigma_units": "sigma / eta_c"})


def _folds(chains, site_edge, n_folds, engine: Smoothed, out, progress
           ) -> tuple[np.ndarray, np.ndarray]:
    """The fold by shooting (of the smoothed `engine`'s model, at its default
    settings for simulations) of the single-site state at the
    oscillator of the highest simulated edge, for the first `n_folds` draws of each
    sigma; stored row by row in folds.csv."""
    shape = site_edge.shape[:2]
    fold, site = np.full(shape, np.nan), np.full(shape, -1)
    todo = [(i, d, c) for i, d, c in chains if d < n_folds
            and np.any(np.isfinite(site_edge[i, d]))]
    store = CsvStore(out / "folds.csv", ("key", "fold_vd", "site")) if out else None
    try:
        for i, d, chain in tqdm(todo, desc="folds by shooting", unit="fold",
                                disable=not progress):
            j = int(np.nanargmax(site_edge[i, d]))
            start = with_parameter(chain, "v_d", 1.5)

            def compute(start=start, j=j):
                point, _ = localized_fold(start, j, engine=engine.simulating())
                return {"fold_vd": float(point.p) if point is not None else math.nan,
                        "site": j}

            row = {"key": settings_key("mistuning fold", chain=start, site=j,
                                       eps=float(engine.eps))}
            row = store.fetch(row, compute) if store else row | compute()
            fold[i, d], site[i, d] = float(row["fold_vd"]), int(row["site"])
    finally:
        if store:
            store.file.close()
    return fold, site


def _sliding_damping(params: ChainParams, site: int, engine: Smoothed) -> float:
    """c = 2 xi + mu'(v_d) (times the load) of oscillator `site` about steady
    sliding: minus the velocity entry of its Jacobian (eq. (5) linearized, smoothed
    at the `engine`'s eps)."""
    single = single_oscillator(params, site)
    y = np.asarray(engine.steady_sliding(single)).reshape(2, 1)
    return -float(np.asarray(jacobian(single, y, engine.eps)).reshape(2, 2)[1, 1])
