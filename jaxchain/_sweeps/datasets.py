"""Ensemble observables as an `xarray.Dataset`, stored with their parameters."""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import json
from pathlib import Path

import numpy as np
from jaxtyping import ArrayLike

from .atomic import replacing
from .._physics.initial import AbstractInitialCondition, OutOfPhaseExcitation
from .._engine.engines import AbstractEngine
from .._physics.params import ChainParams
from .._physics.record import chain_record
from .._engine.observables import EXACT_FIELDS, Observables
from .._engine.status import flag_attributes
from .._setup import VERSION
from .._physics.stick import STICK_BAND

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

PAPER = ("Multiple spatially localized dynamical states in friction-excited "
         "oscillator chains")


#: Descriptions of the observables, as the `long_name` of their variables.
LONG_NAMES = {
    "amplitudes": "half of peak-to-peak of x_n after the transient",
    "energy": "E = 1/2 sum A_n^2, eq. (9)",
    "on_halc": ("oscillator on the high-amplitude limit cycle: it sticks, "
                f"min_slip_speed <= {STICK_BAND:g} eps"),
    "n_halc_halves": "n_halc over the first and over the second half of the window",
    "min_slip_speed": "smallest |x_n' - v_d| after the transient",
    "n_halc": "number of oscillators on the high-amplitude limit cycle (HALC)",
    "x_max": "largest x_n after the transient",
    "x_min": "smallest x_n after the transient",
    "v_max": "largest x_n' after the transient",
    "y_initial": "state (x_n, x_n') at t = 0",
    "y_final": "state (x_n, x_n') at t_end, or where the run stopped",
    "num_steps": "accepted plus rejected integration steps",
    "status": "how the run ended (jaxchain.Status)",
    "v_d": "belt speed v_d",
    "ic": "initial condition",
    "osc": "oscillator n, from 1",
    "n_excited": "number of oscillators excited by the initial condition",
    "family": "family of initial conditions (eq. (8) or eq. (10))",
    "component": "component of the state: x_n or x_n'",
    "half": "half of the observed window",
}

#: The CF conventions that the netCDF results follow.
CONVENTIONS = "CF-1.11"


def cf_dataset(ds: xr.Dataset) -> xr.Dataset:
    """`ds` with the attributes of the CF conventions (`CONVENTIONS`): on every
    variable a `long_name` (`LONG_NAMES`, else its name in words) and, for numbers
    that are not flags, `units` = "1" (every quantity of jaxchain is
    dimensionless, eqs. (4)-(6)); globally `Conventions`, `title`, `source` (the
    jaxchain version), `history` (the time and the command line) and
    `references` (the paper). Coordinates get no fill value."""
    import sys
    import time

    ds = ds.copy()
    for name, var in ds.variables.items():
        attrs = dict(var.attrs)
        attrs.setdefault("long_name", LONG_NAMES.get(name, name.replace("_", " ")))
        if var.dtype.kind in "biuf" and "flag_values" not in attrs:
            attrs.setdefault("units", "1")
        var.attrs = attrs
        if name in ds.coords and var.dtype.kind in "f":
            var.encoding["_FillValue"] = None
    command = " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "python"
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    ds.attrs = {"Conventions": CONVENTIONS,
                "title": ds.attrs.get("title", "jaxchain results: chains of "
                                      "friction-excited oscillators, eq. (5)"),
                "source": f"jaxchain {VERSION}",
                "history": f"{stamp}: {command}",
                "references": PAPER} | {k: v for k, v in ds.attrs.items()
                                         if k not in ("history", "source", "Conventions")}
    return ds


def observables_variables(obs: Observables, lead: tuple[str, ...]) -> dict:
    """Every field of `obs` as an `xarray.Variable` whose leading dims are `lead`
    (the batch axes of `obs`), then `osc`, `half` or (`component`, `osc`), with its
    `long_name` and, for `status`, its CF flag values and meanings (`Status`)."""
    import xarray as xr

    trailing = {"n_halc_halves": ("half",), "y_initial": ("component", "osc"),
                "y_final": ("component", "osc")}
    out = {}
    for f in dataclasses.fields(obs):
        if f.name in EXACT_FIELDS:  # the exact engine's own: not in the stores
            continue
        value = np.asarray(getattr(obs, f.name))
        dims = lead + trailing.get(f.name, ("osc",) if value.ndim > len(lead) else ())
        attrs = {"long_name": LONG_NAMES[f.name]} if f.name in LONG_NAMES else {}
        if f.name == "status":
            attrs |= flag_attributes()
        out[f.name] = xr.Variable(dims, value, attrs)
    return out


def field_values(obj, prefix: str = "") -> dict:
    """The fields of a dataclass (options) by name, with `prefix`, as netCDF
    attributes keep them: strings and whole numbers as they are, tuples as JSON
    lists, other numbers as floats; those that are None, and nested dataclasses (an
    orbit method's engine), left out (netCDF attributes have no None)."""
    def plain(v):
        if isinstance(v, (str, int)):
            return v
        return json.dumps(list(v)) if isinstance(v, tuple) else float(v)

    return {prefix + f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
            if getattr(obj, f.name) is not None
            and not dataclasses.is_dataclass(getattr(obj, f.name))}


def run_attributes(params: ChainParams, engine: AbstractEngine, ics: str,
                   varying: str) -> dict:
    """The attributes of a Dataset of runs: the whole chain (`chain_record`: the
    boundary, the friction law and its parameters, per-oscillator arrays as lists,
    the mistuning record) but `varying` (the parameter along a dim of the
    Dataset), the fields of the engine's options and its settings
    (`AbstractEngine.attributes`: its name, the smoothed engine's solver), the
    initial conditions, the jaxchain version and the paper, as plain numbers,
    lists and strings (netCDF and zarr keep them)."""
    attrs = {k: v for k, v in chain_record(params).items() if k != varying}
    attrs |= field_values(engine.options)
    attrs |= engine.attributes()
    attrs |= {"ics": ics, "jaxchain_version": VERSION, "paper": PAPER,
              "units": "dimensionless, eqs. (4)-(6) of the paper"}
    return attrs


def to_dataset(obs: Observables, params: ChainParams, v_d: ArrayLike,
               ics: AbstractInitialCondition, engine: AbstractEngine) -> xr.Dataset:
    """Turn batched `Observables` into a self-describing `xarray.Dataset`.

    **Arguments:**

    - `obs`: `Observables` with leading axes (n_vd, n_ic).
    - `params`, `v_d`, `ics`, `engine`: what produced `obs` (the engine value,
        `Smoothed` or `Exact`, with its settings).

    **Returns:**

    A Dataset with dims (v_d, ic, osc), `half` and `component` (x, v); `osc` counts
    1..N as in the paper. Data variables: amplitudes, on_halc, min_slip_speed,
    x_max, x_min, v_max (v_d, ic, osc); n_halc_halves (v_d, ic, half); y_initial,
    y_final (v_d, ic, component, osc); energy, n_halc, num_steps, status (v_d, ic).
    When the initial conditions excite oscillators (`OutOfPhaseExcitation`),
    `n_excited` is a coordinate along `ic`. Attributes: every field of `params`
    (but v_d), the engine and its options (the smoothed engine's solver), the type
    of initial condition, the
    meaning of the status codes, the jaxchain version and the paper.
    """
    import xarray as xr

    data = observables_variables(obs, ("v_d", "ic"))
    n_vd, n_ic, n_osc = data["amplitudes"].shape
    coords = {"v_d": np.asarray(v_d, dtype=float).reshape(n_vd),
              "ic": np.arange(n_ic), "osc": np.arange(1, n_osc + 1),
              "component": ["x", "v"]}
    if isinstance(ics, OutOfPhaseExcitation):
        excited = np.broadcast_to(np.asarray(ics.excited), (n_ic, n_osc))
        coords["n_excited"] = ("ic", excited.sum(-1))
    attrs = run_attributes(params, engine, type(ics).__name__, "v_d")
    return xr.Dataset(data, coords=coords, attrs=attrs)


def save_dataset(ds: xr.Dataset, path: str | Path) -> Path:
    """Write `ds` to netCDF (h5netcdf engine), with the attributes of the CF
    conventions (`cf_dataset`), creating the parent folder. The file
    is written whole or not at all: to a temporary file beside `path`, renamed
    into place, so that a run killed while it writes leaves the previous file
    intact.

    **Returns:**

    The path written.
    """
    with replacing(path) as partial:
        cf_dataset(ds).to_netcdf(partial, engine="h5netcdf")
    return Path(path)
