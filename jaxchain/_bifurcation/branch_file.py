"""A followed branch on disk: its stored form, an `xarray.Dataset` over its
converged points with its bifurcations, stops and failed switches as JSON
attributes (netCDF attributes hold no nested records), and the files that
`follow_branch(..., store=...)` resumes from: the branch and each branch switched
onto from it, written whole when the branch is done with the key of every setting
that shaped it, and read back only for an equal key."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING

from .branches import FollowedBranch, LocatedBifurcation, SwitchFailure
from .._sweeps.result_store import read_dataset, write_dataset

if TYPE_CHECKING:  # heavy: imported where it is used
    import xarray as xr

#: What a followed branch's files are, in their key.
KIND = "followed branch"


def followed_dataset(branch: FollowedBranch, **attrs) -> xr.Dataset:
    """The stored form of `branch` (its switched branches apart): variables energy
    (eq. (9)), period, n_halc, stable, the largest non-trivial |multiplier|
    (`critical_multiplier_abs`), the trivial multiplier's distance from 1, amplitudes
    (point, osc) and the method's unknowns u, over the coordinate v_d (dim `point`);
    attributes `phase_oscillator`, `stop` (JSON: `branch.stops`), `bifurcations`
    (JSON: `bifurcation_records`), and `failed_switches` (JSON:
    `failed_switch_records`) or, for a branch switched onto, `switched_from_vd`;
    and `attrs`."""
    import xarray as xr

    attrs = {**attrs, "phase_oscillator": branch.phase_oscillator,
             "stop": json.dumps(branch.stops),
             "bifurcations": json.dumps(bifurcation_records(branch))}
    if branch.switched_from is None:
        attrs["failed_switches"] = json.dumps(failed_switch_records(branch))
    else:
        attrs["switched_from_vd"] = branch.switched_from
    return xr.Dataset(
        {"energy": ("point", branch.energy), "period": ("point", branch.period),
         "n_halc": ("point", branch.n_halc), "stable": ("point", branch.stable),
         "critical_multiplier_abs": ("point", branch.critical_multiplier_abs),
         "trivial_multiplier_error": ("point", branch.trivial_multiplier_error),
         "amplitudes": (("point", "osc"), branch.amplitudes),
         "u": (("point", "unknown"), branch.u)},
        coords={"v_d": ("point", branch.p)}, attrs=attrs)


def bifurcation_records(branch: FollowedBranch) -> list[dict]:
    """The branch's bifurcations as JSON-ready records, as stored and summarised:
    type, v_d, energy, multiplier [re, im], n_halc, after, width."""
    return [{"type": b.kind, "v_d": b.p, "energy": b.energy,
             "multiplier": [b.multiplier.real, b.multiplier.imag],
             "n_halc": b.n_halc, "after": b.after, "width": b.width}
            for b in branch.bifurcations]


def failed_switch_records(branch: FollowedBranch) -> list[dict]:
    """The branch points where switching failed, as JSON-ready records: v_d and
    reason."""
    return [{"v_d": f.p, "reason": f.reason} for f in branch.failed_switches]


def stored_branch(ds: xr.Dataset) -> FollowedBranch:
    """The followed branch that `followed_dataset` stored as `ds` (without the
    branches switched onto from it, and without `pieces`)."""
    attrs = ds.attrs
    return FollowedBranch(
        p=ds["v_d"].values, u=ds["u"].values, energy=ds["energy"].values,
        period=ds["period"].values, n_halc=ds["n_halc"].values, stable=ds["stable"].values,
        critical_multiplier_abs=ds["critical_multiplier_abs"].values,
        trivial_multiplier_error=ds["trivial_multiplier_error"].values,
        amplitudes=ds["amplitudes"].values,
        bifurcations=tuple(LocatedBifurcation(b["type"], b["v_d"], b["energy"],
                                              complex(*b["multiplier"]), b["n_halc"],
                                              b["after"], b["width"])
                           for b in json.loads(attrs["bifurcations"])),
        stops=json.loads(attrs["stop"]), phase_oscillator=int(attrs["phase_oscillator"]),
        switched_from=attrs.get("switched_from_vd"),
        failed_switches=tuple(SwitchFailure(f["v_d"], f["reason"])
                              for f in json.loads(attrs.get("failed_switches", "[]"))))


def write_followed(path: Path, branch: FollowedBranch, **key) -> None:
    """Store `branch` at `path` (netCDF) and each branch switched onto from it at
    `<stem>_switched<j>.nc` beside it, each under `key` and its number j; the
    branch's file last, so that a branch read back has all its switched ones."""
    path = Path(path)
    for j, sw in enumerate(branch.switched, start=1):
        write_dataset(followed_dataset(sw), _switched_path(path, j), KIND, switched=j, **key)
    write_dataset(followed_dataset(branch, switched=len(branch.switched)), path, KIND,
                  switched=0, **key)


def read_followed(path: Path, **key) -> FollowedBranch | None:
    """The branch that `write_followed` stored at `path` under `key`, with its
    switched branches (without `pieces`), or None where any of its files is missing
    or was stored under another key."""
    first = read_dataset(Path(path), KIND, switched=0, **key)
    if first is None:
        return None
    switched = [read_dataset(_switched_path(path, j), KIND, switched=j, **key)
                for j in range(1, int(first.attrs["switched"]) + 1)]
    if any(ds is None for ds in switched):
        return None
    return dataclasses.replace(stored_branch(first),
                               switched=tuple(stored_branch(ds) for ds in switched))


def _switched_path(path: Path, j: int) -> Path:
    """The file of the j-th branch switched onto from the branch stored at `path`."""
    path = Path(path)
    return path.with_name(f"{path.stem}_switched{j}.nc")
