"""Propagating fronts: states in which stick-slip invades the sliding oscillators,
or recedes from them, instead of staying localized (Section 3.2 of the paper, the
red dashed lines of Fig. 3(b))."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._engine.status import Status

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def propagating_fronts(ds: xr.Dataset) -> xr.DataArray:
    """Flag the propagating fronts of a sweep or an ensemble: +1 where stick-slip
    invades the sliding part of the chain, -1 where it recedes, 0 where the state
    stays localized (or the run failed). A front is seen as

    - n_HALC differing between the two halves of the observed window
        (`n_halc_halves`): the direction is the sign of the change; or else
    - n_HALC differing from the number of oscillators excited at t = 0
        (`n_excited`, where the initial conditions have one): the direction is the
        sign of n_HALC - n_excited.

    **Arguments:**

    - `ds`: a Dataset with `n_halc`, `n_halc_halves` (dim `half`), `status` and,
        optionally, the coordinate `n_excited` (-1 where undefined).

    **Returns:**

    An int8 DataArray with the dims of `ds["n_halc"]`.
    """
    import xarray as xr

    early, late = ds["n_halc_halves"].isel(half=0), ds["n_halc_halves"].isel(half=1)
    within = np.sign(late - early)
    if "n_excited" in ds.coords:
        excited = ds["n_excited"]
        since_start = xr.where(excited >= 0, np.sign(ds["n_halc"] - excited), 0)
    else:
        since_start = xr.zeros_like(within)
    front = xr.where(within != 0, within, since_start)
    front = xr.where(ds["status"] == Status.ok, front, 0).astype(np.int8)
    front.attrs = {"long_name": "propagating front: +1 stick-slip invades the sliding "
                                "oscillators, -1 it recedes, 0 localized",
                   "flag_values": [-1, 0, 1]}
    return front


def front_ranges(values, has_front) -> list[tuple[float, float]]:
    """The ranges of a swept parameter in which fronts occur: the runs of
    consecutive values (in increasing order) at which `has_front` is True.

    **Arguments:**

    - `values`: the parameter values, shape (n,).
    - `has_front`: whether any front occurs at each value, shape (n,).

    **Returns:**

    A list of (first value, last value) of each run.
    """
    order = np.argsort(values)
    values, has_front = np.asarray(values)[order], np.asarray(has_front)[order]
    ranges, start = [], None
    for i, flag in enumerate(has_front):
        if flag and start is None:
            start = i
        if start is not None and (not flag or i == len(values) - 1):
            stop = i if flag else i - 1
            ranges.append((float(values[start]), float(values[stop])))
            start = None
    return ranges


def front_fractions(ds: xr.Dataset) -> xr.DataArray:
    """The fraction of the initial conditions (of those whose run succeeded) that
    make an invading (+1) and a receding (-1) front at each value of the swept
    parameter.

    **Arguments:**

    - `ds`: a Dataset from `sweep`, with `front` and `status` along (name, ic).

    **Returns:**

    A DataArray of dims (name, direction), direction = [1, -1]; 0 where every run
    failed.
    """
    import xarray as xr

    ok = ds["status"] == Status.ok
    count = ok.sum("ic")
    out = [((ds["front"] == sign) & ok).sum("ic") / count.where(count > 0)
           for sign in (1, -1)]
    return xr.concat(out, dim=xr.DataArray([1, -1], dims="direction")).fillna(0.0)
