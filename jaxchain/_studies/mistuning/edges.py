"""The upper edge of the bistable range of a mistuned chain: the largest belt speed
at which the single-site localized state (k = 1 of eq. (8)) at each oscillator
still vibrates, by bisection of direct simulations, and precisely by shooting as
the fold of that state's branch of limit cycles."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..._engine.progress import tqdm
from ..._bifurcation.branches import follow_branch
from ..._bifurcation.continuation import ContinuationOptions
from ..._bifurcation.fold import FoldPoint, fold_point
from ..._bifurcation.periodic_orbit import periodic_orbit
from ..._bifurcation.shooting import Shooting
from ..._engine.engines import AbstractEngine, Smoothed
from ..._engine.horizon import AbstractHorizon
from ..._engine.lanes import run_lanes
from ..._engine.options import SimulationOptions
from ..._physics.initial import OutOfPhaseExcitation, initial_states
from ..._physics.params import ChainParams, stack_chains, with_parameter
from ..snake.starts import _turning_point
from ..snake.orbits import snake_orbits
from ..._sweeps.result_store import read_dataset, write_dataset
from ..._checks import check_count
from ..._errors import ValidationError
from ..._engine.status import Status

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Each simulation of the bisection: long enough for a state just past its fold
#: to die out (it lingers near the ghost of the fold for a time that grows as the
#: distance shrinks); the resolution of the bisection is its bracket's width.
EDGE_OPTIONS = SimulationOptions(t_end=1000.0, transient=800.0)

#: The kind of result of the stored bisection (`write_dataset`).
KIND = "mistuning-edges"


def _site_excitation(n_osc: int, sites) -> OutOfPhaseExcitation:
    """Eq. (8) with one oscillator excited, at each of `sites` (0-based): a batch
    of `len(sites)` initial conditions."""
    sites = np.asarray(sites, dtype=int)
    masks = np.zeros((sites.size, n_osc), dtype=bool)
    masks[np.arange(sites.size), sites] = True
    return OutOfPhaseExcitation(excited=jnp.asarray(masks),
                                velocity=jnp.zeros(sites.size), base_sign=-1.0)


def _vibrates(chains, v, engine: AbstractEngine, bar) -> np.ndarray:
    """Whether the single-site state of each (chain, site) lane still has an
    oscillator on the HALC at t_end, at belt speeds v of shape (n_chains, n_osc),
    by `engine`."""
    n_chains, n_osc = v.shape
    lanes = stack_chains([with_parameter(c, "v_d", float(v[i, j]))
                          for i, c in enumerate(chains) for j in range(n_osc)])
    y0 = initial_states(lanes, _site_excitation(n_osc, np.tile(np.arange(n_osc), n_chains)))
    out = run_lanes(lanes, np.asarray(y0),
                    engine=engine, progress=bar)
    status = np.asarray(out.status).reshape(n_chains, n_osc)
    n_halc = np.asarray(out.n_halc).reshape(n_chains, n_osc)
    return np.where(status == Status.ok, n_halc > 0, np.nan)


def _bracket(store, settings: dict, low: float, high: float, shape: tuple) -> tuple:
    """(lo, hi, valid, steps done) of the bisection of `upper_edges`: read from
    `store` where it holds a run of the same settings, else the whole bracket."""
    state = read_dataset(Path(store), KIND, **settings) if store is not None else None
    if state is None:
        return (np.full(shape, float(low)), np.full(shape, float(high)),
                np.ones(shape, dtype=bool), 0)
    return (state["edge_low"].values, state["edge_high"].values,
            state["valid"].values.astype(bool), int(state.attrs["steps_done"]))


def upper_edges(chains: list[ChainParams], *, engine: AbstractEngine = Smoothed(),
                low: float = 1.7, high: float = 1.9, steps: int = 7,
                options: AbstractHorizon = EDGE_OPTIONS, store: str | Path | None = None,
                progress: bool = True) -> xr.Dataset:
    """For each chain and each oscillator n, the largest belt speed at which the
    single-site localized state at n (eq. (8), k = 1) survives direct simulation:
    bisection on [low, high], every (chain, oscillator) lane at once through
    `run_lanes`. The chain's upper edge of the bistable range is the largest over
    its oscillators (on the homogeneous ring the fold of the single-site state,
    1.7956 for eq. (7), is the highest fold of the stable localized states: documentation,
    "The snake").

    **Arguments:**

    - `chains`: the chains (one n_osc), each at any v_d.
    - `engine`: the engine of the simulations (`Smoothed()` by default: eq. (5)
        smoothed at its eps, by its solver and tolerances).
    - `low`, `high`: the bracket of belt speeds; a lane that does not vibrate at
        `low`, or still vibrates at `high`, gets NaN.
    - `steps`: bisection steps after the ends: resolution (high - low) / 2^steps.
    - `options`: the horizon of each simulation (t_end, transient, chunk_length:
        `EDGE_OPTIONS` by default); the engine's other settings are kept.
    - `store`: a netCDF file holding the bracket after each step, from which a
        run of the same settings continues.
    - `progress`: a tqdm bar over the simulations.

    **Returns:**

    An `xarray.Dataset` with dims (chain, osc): `edge` (the bracket's midpoint,
    NaN where the bracket does not hold the state's end), `edge_low`,
    `edge_high`; attribute `resolution`.

    **Raises:**

    `ValidationError` unless 0 < low < high and steps >= 1.
    """
    import xarray as xr

    if not 0 < low < high:
        raise ValidationError(f"low, high: need 0 < low < high, got {low!r}, {high!r}")
    check_count("steps", steps, 1)
    engine = engine.with_horizon(options)
    n_chains, n_osc = len(chains), chains[0].n_osc
    settings = dict(chains=[{f.name: getattr(c, f.name) for f in dataclasses.fields(c)
                              if f.name != "v_d"} for c in chains],
                    engine=engine, low=low, high=high, steps=steps)
    lo, hi, valid, done = _bracket(store, settings, low, high, (n_chains, n_osc))
    with tqdm(total=(steps + 2) * n_chains * n_osc, initial=done * n_chains * n_osc,
              desc="upper edges", unit="simulation", disable=not progress) as bar:
        for step in range(done, steps + 2):
            if step == 0:
                valid &= _vibrates(chains, lo, engine, bar) == 1
            elif step == 1:
                valid &= _vibrates(chains, hi, engine, bar) == 0
            else:
                mid = 0.5 * (lo + hi)
                alive = _vibrates(chains, mid, engine, bar)
                lo = np.where(alive == 1, mid, lo)
                hi = np.where(alive == 0, mid, hi)
                valid &= np.isfinite(alive)
            ds = xr.Dataset({"edge_low": (("chain", "osc"), lo),
                             "edge_high": (("chain", "osc"), hi),
                             "valid": (("chain", "osc"), valid.astype(np.int8))},
                            attrs={"steps_done": step + 1})
            if store is not None:
                write_dataset(ds, Path(store), KIND, **settings)
    edge = np.where(valid, 0.5 * (lo + hi), np.nan)
    return xr.Dataset({"edge": (("chain", "osc"), edge), "edge_low": (("chain", "osc"), lo),
                       "edge_high": (("chain", "osc"), hi)},
                      coords={"osc": np.arange(1, n_osc + 1)},
                      attrs={"resolution": (high - low) / 2**steps,
                             "method": "bisection of direct simulations from eq. (8), "
                                       "k = 1 at each oscillator"})


#: Continuation from the start towards the fold: small steps, upward in v_d.
FOLD_CONTINUATION = ContinuationOptions(ds=0.01, ds_max=0.05, p_max=2.2, max_points=60)


def localized_orbit(params: ChainParams, site: int, *,
                    options: SimulationOptions = SimulationOptions(t_end=3000.0,
                                                                   transient=2500.0),
                    engine: AbstractEngine = Smoothed()):
    """The periodic single-site localized state at oscillator `site` (0-based) at
    `params.v_d`, refined by shooting from a simulation of eq. (8) with that
    oscillator excited, both of `engine`'s model: the simulation by `engine` over
    the horizon of `options`, the shooting on its flow made `for_orbits`
    (`Shooting.from_simulations`: Levenberg-Marquardt on the smoothed model).

    **Returns:**

    (`PeriodicOrbit`, the `Shooting` of its phase condition), or
    (None, None) when the simulated state is not periodic or does not vibrate. The
    orbit's chain has one stiffness per oscillator, shape (n_osc,), also where
    `params` gives one for all (the programs of a ring of its size are then those
    of each of its mistuned draws).
    """
    from ..._engine.simulate import simulate

    if np.ndim(params.stiffness) == 0:
        # one stiffness per oscillator, as a mistuned ring has them: the programs of
        # the homogeneous ring are then those of every mistuned ring of its size
        params = with_parameter(params, "stiffness", jnp.full(params.n_osc, params.stiffness))
    engine = engine.with_horizon(options)
    # shooting from the simulation (Levenberg-Marquardt), on the oscillator's phase
    method = Shooting.from_simulations(engine, phase_oscillator=int(site))
    mask = np.arange(params.n_osc) == site
    y0 = OutOfPhaseExcitation(excited=jnp.asarray(mask), velocity=0.0, base_sign=-1.0)(params)
    obs = simulate(params, y0, engine=engine)
    if int(obs.status) != Status.ok or int(obs.n_halc) == 0:
        return None, None
    guess = _turning_point(snake_orbits(method, engine), params, np.asarray(obs.y_final),
                           int(site))
    if guess is None:
        return None, None
    orbit = periodic_orbit(params, guess, method, throw=False)
    return (orbit, method) if bool(orbit.converged) else (None, None)


def localized_fold(params: ChainParams, site: int, *,
                   continuation_options: ContinuationOptions = FOLD_CONTINUATION,
                   engine: AbstractEngine = Smoothed()) -> tuple[FoldPoint | None, object]:
    """The fold of limit cycles that ends the single-site localized state at
    oscillator `site` upwards in v_d: its orbit at `params.v_d` (`localized_orbit`),
    its branch followed upwards (`follow_branch`) to the first fold, then Newton's method on
    the Moore-Spence extended system (`fold_point`) from the point where the fold
    was detected, or else from one of its neighbours on the branch. Everything is
    of `engine`'s model (`Smoothed()` by default: eq. (5) smoothed at eps = 1e-3),
    as `localized_orbit` takes it, which the problem carries.

    **Returns:**

    (`FoldPoint`, the limit cycles' `ContinuationProblem`), or (None, None) when
    the state is not periodic at `params.v_d` or no fold is met.
    """
    orbit, opts = localized_orbit(params, site, engine=engine)
    if orbit is None:
        return None, None
    followed = follow_branch(orbit, opts, continuation_options,
                             directions=(continuation_options.direction,))
    (problem, branch, _), *_ = followed.pieces
    if not branch.folds:
        return None, None
    good = np.flatnonzero(np.asarray(branch.converged))
    i = int(branch.folds[0])
    for j in (i, i + 1, i - 1):  # Newton's method may fail from one point, not its neighbour
        if 0 <= j < good.size:
            z = jnp.concatenate([branch.u[good[j]], branch.p[good[j]][None]])
            fold = fold_point(problem, z, throw=False)
            if bool(fold.converged):
                return fold, problem
    return None, None
