"""Ensemble observables as an `xarray.Dataset`, stored with their parameters."""

import dataclasses
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import diffrax
import numpy as np
import xarray as xr
from jaxtyping import ArrayLike

from ._options import SimulationOptions
from ._params import ChainParams
from ._simulate import STATUS, Observables

PAPER = ("Multiple spatially localized dynamical states in friction-excited "
         "oscillator chains")


def _package_version() -> str:
    try:
        return version("jaxchain")
    except PackageNotFoundError:
        return "unknown"


def to_dataset(obs: Observables, params: ChainParams, v_d: ArrayLike,
               solver: diffrax.AbstractSolver, options: SimulationOptions, *,
               n_excited: ArrayLike | None = None, ics: str = "") -> xr.Dataset:
    """Turn the output of `ensemble` into a self-describing `xarray.Dataset`.

    **Arguments:**

    - `obs`: `Observables` with leading axes (n_vd, n_ic).
    - `params`, `solver`, `options`: what produced `obs`; stored as attributes.
    - `v_d`: the belt speeds, shape (n_vd,).
    - `n_excited`: optional number of excited oscillators of each initial
        condition, shape (n_ic,), stored as a coordinate along `ic`.
    - `ics`: optional name of the initial-condition family (e.g. "eq8").

    **Returns:**

    A Dataset with dims (v_d, ic, osc); `osc` counts 1..N as in the paper. Data
    variables: amplitudes, on_halc, x_max, x_min, v_max (v_d, ic, osc); energy,
    n_halc, num_steps, status (v_d, ic). Attributes: every field of `params` (but
    v_d), of `options`, the solver, the meaning of the status codes, the jaxchain
    version and the paper.
    """
    per_osc = ("v_d", "ic", "osc")
    per_run = ("v_d", "ic")
    data = {
        name: (per_osc, np.asarray(getattr(obs, name)))
        for name in ("amplitudes", "on_halc", "x_max", "x_min", "v_max")
    } | {
        name: (per_run, np.asarray(getattr(obs, name)))
        for name in ("energy", "n_halc", "num_steps", "status")
    }
    n_vd, n_ic, n_osc = data["amplitudes"][1].shape
    coords = {"v_d": np.asarray(v_d, dtype=float).reshape(n_vd),
              "ic": np.arange(n_ic), "osc": np.arange(1, n_osc + 1)}
    if n_excited is not None:
        coords["n_excited"] = ("ic", np.asarray(n_excited))
    ds = xr.Dataset(data, coords=coords)
    ds["amplitudes"].attrs["long_name"] = "half of peak-to-peak of x_n after the transient"
    ds["energy"].attrs["long_name"] = "E = 1/2 sum A_n^2, eq. (9)"
    ds["on_halc"].attrs["long_name"] = "oscillator on the high-amplitude limit cycle"
    ds["status"].attrs["flag_meanings"] = " | ".join(
        f"{i}: {s}" for i, s in enumerate(STATUS))
    attrs = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)
             if f.name != "v_d"}
    attrs |= {f.name: getattr(options, f.name) for f in dataclasses.fields(options)}
    attrs |= {"solver": type(solver).__name__, "ics": ics,
              "jaxchain_version": _package_version(), "paper": PAPER,
              "units": "dimensionless, eqs. (4)-(6) of the paper"}
    ds.attrs = {k: (float(v) if not isinstance(v, (str, int)) else v)
                for k, v in attrs.items()}
    return ds


def save_dataset(ds: xr.Dataset, path: str | Path) -> Path:
    """Write `ds` to netCDF (h5netcdf engine), creating the parent folder.

    **Returns:**

    The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(path, engine="h5netcdf")
    return path
