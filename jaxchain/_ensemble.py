"""Ensembles: `jax.vmap` of the single-trajectory run over belt speeds and initial
conditions, in one compiled function."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import xarray as xr
from jaxtyping import ArrayLike, Float

from ._initial import AbstractInitialCondition
from ._options import SimulationOptions
from ._params import ChainParams
from ._progress import progress_bar
from ._results import to_dataset
from ._simulate import n_ticks, run


@eqx.filter_jit
def _ensemble(params, v_d, ics, solver, options, progress):
    def one(vd, ic):
        p = eqx.tree_at(lambda q: q.v_d, params, vd)
        return run(p, ic(p), solver, options, progress)

    over_ics = eqx.filter_vmap(one, in_axes=(None, eqx.if_array(0)))
    return eqx.filter_vmap(over_ics, in_axes=(0, None))(v_d, ics)


def ensemble(params: ChainParams, v_d: Float[ArrayLike, " n_vd"],
             ics: AbstractInitialCondition,
             solver: diffrax.AbstractSolver = diffrax.Tsit5(),
             options: SimulationOptions = SimulationOptions(), *,
             progress: bool = True) -> xr.Dataset:
    """Run every (belt speed, initial condition) pair of a grid, vmapped, in one
    compiled function. Trajectories never raise: each has a `status` (0 = ok, see
    `STATUS`), so one failing lane never discards the others.

    Under vmap every lane waits for the slowest one within each chunk, so an
    ensemble costs about (number of lanes) x (steps of the slowest lane).

    **Arguments:**

    - `params`: the chain parameters; its `v_d` is replaced by each entry of `v_d`.
    - `v_d`: belt speeds, shape (n_vd,), dimensionless.
    - `ics`: initial conditions batched along the leading axis of their array
        fields, n_ic of them (for example `localized_family(n_osc)` or
        `GivenState(y0)` with y0 of shape (n_ic, 2, n_osc)). They are evaluated at
        each belt speed, so that eq. (8) starts from that speed's steady sliding.
    - `solver`: a diffrax solver, `diffrax.Tsit5()` by default.
    - `options`: `SimulationOptions`.
    - `progress`: show a tqdm bar over the chunks of all trajectories.

    **Returns:**

    An `xarray.Dataset` (see `to_dataset`) with dims (v_d, ic, osc): amplitudes
    has shape (n_vd, n_ic, n_osc), energy (n_vd, n_ic), and so on, with the
    parameters, options and solver as attributes.

    **Raises:**

    `ValueError` for belt speeds that are not finite and > 0, or initial conditions
    of the wrong shape.
    """
    v_d = jnp.atleast_1d(jnp.asarray(v_d, dtype=float))
    if v_d.ndim != 1 or not bool(jnp.all(jnp.isfinite(v_d) & (v_d > 0))):
        raise ValueError(f"v_d must be a 1-d array of finite belt speeds > 0, got {v_d}")
    leaves = [x for x in jax.tree_util.tree_leaves(ics) if eqx.is_array(x)]
    if not leaves:
        raise ValueError("ics must carry a leading batch axis on its array fields")
    n_ic = leaves[0].shape[0]
    ics_first = jax.tree_util.tree_map(lambda x: x[0] if eqx.is_array(x) else x, ics)
    ics_first(eqx.tree_at(lambda q: q.v_d, params, v_d[0]))  # shape check, may raise
    total = len(v_d) * n_ic * n_ticks(options)
    with progress_bar(total, f"{len(v_d)}x{n_ic} trajectories", progress):
        obs = _ensemble(params, v_d, ics, solver, options, progress)
        jax.block_until_ready(obs)
    return to_dataset(obs, params, v_d, ics, solver, options)



