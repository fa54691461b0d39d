"""Ensemble observables as an `xarray.Dataset`, stored with their parameters."""

import dataclasses
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import diffrax
import numpy as np
import xarray as xr
from jaxtyping import ArrayLike

from ._initial import AbstractInitialCondition, OutOfPhaseExcitation
from ._options import SimulationOptions
from ._params import ChainParams
from ._simulate import STATUS, Observables
from ._stick import STICK_BAND

PAPER = ("Multiple spatially localized dynamical states in friction-excited "
         "oscillator chains")


def _package_version() -> str:
    try:
        return version("jaxchain")
    except PackageNotFoundError:
        return "unknown"


def to_dataset(obs: Observables, params: ChainParams, v_d: ArrayLike,
               ics: AbstractInitialCondition, solver: diffrax.AbstractSolver,
               options: SimulationOptions) -> xr.Dataset:
    """Turn batched `Observables` into a self-describing `xarray.Dataset`.

    **Arguments:**

    - `obs`: `Observables` with leading axes (n_vd, n_ic).
    - `params`, `v_d`, `ics`, `solver`, `options`: what produced `obs`.

    **Returns:**

    A Dataset with dims (v_d, ic, osc) and `component` (x, v); `osc` counts 1..N
    as in the paper. Data variables: amplitudes, on_halc, min_slip_speed, x_max,
    x_min, v_max (v_d, ic, osc); y_initial, y_final (v_d, ic, component, osc);
    energy, n_halc, num_steps, status (v_d, ic). When the initial conditions excite oscillators
    (`OutOfPhaseExcitation`), `n_excited` is a coordinate along `ic`. Attributes:
    every field of `params` (but v_d), of `options`, the solver, the type of
    initial condition, the meaning of the status codes, the jaxchain version and
    the paper.
    """
    per_osc = ("v_d", "ic", "osc")
    per_run = ("v_d", "ic")
    states = ("v_d", "ic", "component", "osc")
    data = {name: (per_osc, np.asarray(getattr(obs, name)))
            for name in ("amplitudes", "on_halc", "min_slip_speed", "x_max", "x_min",
                         "v_max")}
    data |= {name: (per_run, np.asarray(getattr(obs, name)))
             for name in ("energy", "n_halc", "num_steps", "status")}
    data |= {name: (states, np.asarray(getattr(obs, name)))
             for name in ("y_initial", "y_final")}
    n_vd, n_ic, n_osc = data["amplitudes"][1].shape
    coords = {"v_d": np.asarray(v_d, dtype=float).reshape(n_vd),
              "ic": np.arange(n_ic), "osc": np.arange(1, n_osc + 1),
              "component": ["x", "v"]}
    if isinstance(ics, OutOfPhaseExcitation):
        excited = np.broadcast_to(np.asarray(ics.excited), (n_ic, n_osc))
        coords["n_excited"] = ("ic", excited.sum(-1))
    ds = xr.Dataset(data, coords=coords)
    ds["amplitudes"].attrs["long_name"] = "half of peak-to-peak of x_n after the transient"
    ds["energy"].attrs["long_name"] = "E = 1/2 sum A_n^2, eq. (9)"
    ds["on_halc"].attrs["long_name"] = ("oscillator on the high-amplitude limit cycle: "
                                        f"it sticks, min_slip_speed <= {STICK_BAND:g} eps")
    ds["min_slip_speed"].attrs["long_name"] = "smallest |x_n' - v_d| after the transient"
    ds["status"].attrs["flag_meanings"] = " | ".join(
        f"{i}: {s}" for i, s in enumerate(STATUS))
    attrs = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)
             if f.name != "v_d"}
    attrs |= {f.name: getattr(options, f.name) for f in dataclasses.fields(options)}
    attrs |= {"solver": type(solver).__name__, "ics": type(ics).__name__,
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
