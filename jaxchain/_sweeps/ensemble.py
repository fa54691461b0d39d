"""Ensembles: the single-trajectory run over a grid of belt speeds and initial
conditions, vmapped and spread over the devices (`run_lanes`)."""

from typing import TYPE_CHECKING

import diffrax
import jax
import numpy as np
from jaxtyping import ArrayLike, Float

from .._physics.record import check_recordable
from .._engine.checks import belt_speeds, check_params
from .._engine.engines import AbstractEngine, as_engine
from .._engine.horizon import AbstractHorizon
from .._physics.initial import AbstractInitialCondition, batch_length
from .._engine.lanes import distance_from, lane_params, lane_starts, run_lanes, take_lanes
from .._engine.programs import compiled
from .._physics.params import ChainParams
from .._errors import ValidationError

if TYPE_CHECKING:
    import xarray as xr


def ensemble(params: ChainParams, v_d: Float[ArrayLike, " n_vd"],
             ics: AbstractInitialCondition,
             solver: diffrax.AbstractSolver | str | None = None,
             options: AbstractHorizon | None = None, *,
             engine: AbstractEngine | str = "smoothed", schedule: str | None = None,
             progress: bool = True) -> "xr.Dataset":
    """Run every (belt speed, initial condition) pair of a grid, spread over the
    devices (on a CPU, one per core) by `run_lanes`. Trajectories never raise: each
    has a `status` (`Status`), so one failing lane never discards the
    others.

    On a CPU each core integrates one trajectory at a time and takes the next when
    it finishes (a work queue), so an ensemble costs about (total steps) / (cores).
    On a GPU the trajectories are vmapped lanes.

    **Arguments:**

    - `params`: the chain parameters; its `v_d` is replaced by each entry of `v_d`.
    - `v_d`: belt speeds, shape (n_vd,), dimensionless.
    - `ics`: initial conditions batched along the leading axis of their array
        fields, n_ic of them (for example `localized_family(n_osc)` or
        `GivenState(y0)` with y0 of shape (n_ic, 2, n_osc)). They are evaluated at
        each belt speed, so that eq. (8) starts from that speed's steady sliding.
    - `solver`: a diffrax solver, `Ros34PW2()` by default (`DEFAULT_SOLVER`; a
        solver of `SPLIT_SOLVERS` gets the friction force as its stiff term).
    - `options`: `SimulationOptions` (`NonsmoothOptions` for the exact engine).
    - `engine`: "smoothed" (default), "exact" or an engine value, as for `simulate`.
    - `schedule`: "queue" or "vmap" (see `run_lanes`); by default the queue on a CPU
        and vmap elsewhere. The result does not depend on it.
    - `progress`: show a tqdm bar over the trajectories.

    **Returns:**

    An `xarray.Dataset` (see `to_dataset`) with dims (v_d, ic, osc): amplitudes
    has shape (n_vd, n_ic, n_osc), energy (n_vd, n_ic), and so on, with the
    parameters, the engine, its options and solver as attributes.

    **Raises:**

    `ValidationError` for an empty list of belt speeds or of initial conditions, belt
    speeds that are not finite and > 0, initial conditions of the wrong shape, an
    unknown solver name or engine; `TypeError` for arguments of the wrong type.
    """
    params = check_params(params)
    engine = as_engine(engine, solver, options, params)
    v_d = belt_speeds(v_d)
    check_recordable(params)  # before the run, not in to_dataset after it
    if not isinstance(ics, AbstractInitialCondition):
        raise TypeError(f"ics must be initial conditions (jaxchain.localized_family, "
                        f"GivenState, ...), got {type(ics).__name__}")
    n_ic = batch_length(ics)
    if n_ic == 0:
        raise ValidationError("ics must hold at least one initial condition, got 0")
    lanes_vd, lanes_ic = np.repeat(v_d, n_ic), np.tile(np.arange(n_ic), v_d.size)
    lanes = lane_params(params, lanes_vd.size, v_d=lanes_vd)
    # One compiled program (its shape checks raise while it is traced), not one
    # per operation: 2 s of a small run (benchmarks/fixed_cost.py).
    y0, steady = compiled(lane_starts, lanes, take_lanes(ics, lanes_ic))
    obs = run_lanes(lanes, y0, engine=engine, schedule=schedule, progress=progress,
                    costs=distance_from(steady, y0))
    obs = jax.tree_util.tree_map(lambda x: x.reshape(v_d.size, n_ic, *x.shape[1:]), obs)
    from .datasets import to_dataset  # xarray, imported once the run is done

    return to_dataset(obs, params, v_d, ics, engine)



