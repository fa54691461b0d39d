"""Ensembles: the single-trajectory run over a grid of belt speeds and initial
conditions, vmapped and spread over the devices (`run_lanes`)."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import xarray as xr
from jaxtyping import ArrayLike, Float

from ._initial import AbstractInitialCondition
from ._lanes import run_lanes
from ._options import SimulationOptions
from ._params import ChainParams, with_parameter
from ._results import to_dataset
from ._solvers import DEFAULT_SOLVER, SOLVERS


@eqx.filter_jit
def _initial_states(params, v_d, ics):
    """The initial state of every (belt speed, initial condition) pair, shape
    (n_vd, n_ic, 2, n_osc): eq. (8) starts from each belt speed's steady sliding."""
    def one(vd, ic):
        return ic(with_parameter(params, "v_d", vd))

    over_ics = eqx.filter_vmap(one, in_axes=(None, eqx.if_array(0)))
    return eqx.filter_vmap(over_ics, in_axes=(0, None))(v_d, ics)


def ensemble(params: ChainParams, v_d: Float[ArrayLike, " n_vd"],
             ics: AbstractInitialCondition,
             solver: diffrax.AbstractSolver = SOLVERS[DEFAULT_SOLVER](),
             options: SimulationOptions = SimulationOptions(), *,
             engine: str | None = None, progress: bool = True) -> xr.Dataset:
    """Run every (belt speed, initial condition) pair of a grid, spread over the
    devices (on a CPU, one per core) by `run_lanes`. Trajectories never raise: each
    has a `status` (0 = ok, see `STATUS`), so one failing lane never discards the
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
    - `options`: `SimulationOptions`.
    - `engine`: "queue" or "vmap" (see `run_lanes`); by default the queue on a CPU
        and vmap elsewhere. The result does not depend on it.
    - `progress`: show a tqdm bar over the trajectories.

    **Returns:**

    An `xarray.Dataset` (see `to_dataset`) with dims (v_d, ic, osc): amplitudes
    has shape (n_vd, n_ic, n_osc), energy (n_vd, n_ic), and so on, with the
    parameters, options and solver as attributes.

    **Raises:**

    `ValueError` for belt speeds that are not finite and > 0, initial conditions
    of the wrong shape, or an unknown engine.
    """
    v_d = jnp.atleast_1d(jnp.asarray(v_d, dtype=float))
    if v_d.ndim != 1 or not bool(jnp.all(jnp.isfinite(v_d) & (v_d > 0))):
        raise ValueError(f"v_d must be a 1-d array of finite belt speeds > 0, got {v_d}")
    leaves = [x for x in jax.tree_util.tree_leaves(ics) if eqx.is_array(x)]
    if not leaves:
        raise ValueError("ics must carry a leading batch axis on its array fields")
    ics_first = jax.tree_util.tree_map(lambda x: x[0] if eqx.is_array(x) else x, ics)
    ics_first(with_parameter(params, "v_d", v_d[0]))  # shape check, may raise
    y0 = _initial_states(params, v_d, ics)
    shape = y0.shape[:2]
    lanes_vd = jnp.broadcast_to(v_d[:, None], shape).reshape(-1)
    obs = run_lanes(with_parameter(params, "v_d", lanes_vd), y0.reshape(-1, *y0.shape[2:]),
                    solver, options, engine=engine, progress=progress)
    obs = jax.tree_util.tree_map(lambda x: x.reshape(*shape, *x.shape[1:]), obs)
    return to_dataset(obs, params, v_d, ics, solver, options)



