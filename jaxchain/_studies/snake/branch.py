"""A followed branch of the snake (`follow_branch`) as the snake stores it: an
`xarray.Dataset` over its converged points, with its bifurcations, stops and
failed switches as JSON attributes (netCDF attributes hold no nested records), the
form of the stores of earlier releases, which still read back."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from ..._bifurcation.branches import FollowedBranch, LocatedBifurcation, SwitchFailure
from ..._bifurcation.continuation import ContinuationOptions

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


#: Continuation of each branch: far enough each way (150 points) to pass its folds.
SNAKE_CONTINUATION = ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.2,
                                         max_points=150)

#: Part of the key of stored branches, the revision of how a branch is followed
#: and started (`follow_branch`, `start_orbits`): raised whenever it changes, so
#: that a resumed run recomputes the branches of an older revision. Revision 7 is
#: the one whose stores the ring of 8 and the ring of 20 keep.
BRANCH_METHOD = 7


def branch_dataset(branch: FollowedBranch, k: int) -> xr.Dataset:
    """The stored form of a followed branch of start `k` (k excited oscillators):
    variables energy (eq. (9)), period, n_halc, stable, the largest non-trivial
    |multiplier| (`critical_multiplier_abs`), the trivial multiplier's distance
    from 1, amplitudes (point, osc) and the method's unknowns u, over the
    coordinate v_d (dim `point`); attributes `excited`, `phase_oscillator`, `stop`
    (JSON: `branch.stops`), `bifurcations` (JSON list of type, v_d, energy,
    multiplier [re, im], n_halc, after, width), and `failed_switches` (JSON list of
    v_d and reason) or, for a branch switched onto, `switched_from_vd`."""
    import xarray as xr

    attrs = {"excited": k, "phase_oscillator": branch.phase_oscillator,
             "stop": json.dumps(branch.stops),
             "bifurcations": json.dumps([
                 {"type": b.kind, "v_d": b.p, "energy": b.energy,
                  "multiplier": [b.multiplier.real, b.multiplier.imag],
                  "n_halc": b.n_halc, "after": b.after, "width": b.width}
                 for b in branch.bifurcations])}
    if branch.switched_from is None:
        attrs["failed_switches"] = json.dumps([{"v_d": f.p, "reason": f.reason}
                                               for f in branch.failed_switches])
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


def stored_branch(ds: xr.Dataset) -> FollowedBranch:
    """The followed branch that `branch_dataset` stored as `ds` (switched branches
    and failed switches apart from the stored record's own)."""
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
