"""Basin stability: the probability of each state against the belt speed, and the
distribution of n_HALC at one belt speed, with their 95 % intervals."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .canvas import single_axes

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def _shown(ds: xr.Dataset) -> list[int]:
    """The classes that any belt speed reaches."""
    return [c for c in range(ds.sizes["class"]) if ds["counts"].values[:, c].any()]


def plot_basin_stability(ds: xr.Dataset, ax=None):
    """The fraction of initial states that end in each class (`basin_stability`)
    against v_d, as stacked areas, with each class's 95 % Wilson interval as an
    error bar at the top of its band.

    **Arguments:**

    - `ds`: the Dataset of `basin_stability`.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:**

    The matplotlib `Figure`.
    """
    import matplotlib.pyplot as plt

    v_d, fraction = ds["v_d"].values, ds["fraction"].values
    classes = _shown(ds)
    fig, ax = single_axes(ax, (7, 4.2))
    colours = plt.get_cmap("viridis", max(2, len(classes)))
    bottom = np.zeros(v_d.size)
    for i, c in enumerate(classes):
        top = bottom + fraction[:, c]
        name = str(ds["class"].values[c])
        colour = "0.6" if name == "failed" else colours(i)
        ax.fill_between(v_d, bottom, top, color=colour, alpha=0.75, label=name, step=None)
        low = ds["ci_low"].values[:, c] - fraction[:, c]
        high = ds["ci_high"].values[:, c] - fraction[:, c]
        ax.errorbar(v_d, top, yerr=np.abs(np.stack([low, high])), fmt="none",
                    ecolor="k", elinewidth=0.8, capsize=2)
        bottom = top
    ax.set(xlabel="belt speed $v_d$", ylabel="basin stability (fraction of samples)",
           ylim=(0, 1.02), xlim=(v_d.min(), v_d.max()) if v_d.size > 1 else None,
           title=f"N = {ds.sizes['osc']}, {ds.attrs['n_samples']} samples, x in "
                 f"{ds.attrs['box_x']}, x' in {ds.attrs['box_v']}")
    ax.legend(fontsize=7, ncol=2 if len(classes) > 8 else 1, loc="center left",
              bbox_to_anchor=(1.01, 0.5))
    return fig


def plot_halc_histogram(ds: xr.Dataset, v_d: float, ax=None):
    """The distribution of n_HALC at the belt speed nearest `v_d`: the fraction of
    samples in each class with its 95 % Wilson interval.

    **Arguments:**

    - `ds`: the Dataset of `basin_stability`; `v_d`: the belt speed (nearest).
    - `ax`: a matplotlib Axes to draw on; a new figure if None.


    **Returns:**

    The matplotlib `Figure`.
    """

    i = int(np.argmin(np.abs(ds["v_d"].values - v_d)))
    row = ds.isel(v_d=i)
    k = np.arange(ds.sizes["class"])
    fraction = row["fraction"].values
    err = np.abs(np.stack([row["ci_low"].values - fraction, row["ci_high"].values - fraction]))
    fig, ax = single_axes(ax, (7, 3.6))
    ax.bar(k, fraction, color="tab:blue", alpha=0.8)
    ax.errorbar(k, fraction, yerr=err, fmt="none", ecolor="k", capsize=2)
    labels = [str(c).replace("n_HALC = ", "") for c in ds["class"].values]
    labels = ["0" if s == "steady sliding" else s for s in labels]
    ax.set_xticks(k, labels, fontsize=7)
    ax.set(xlabel=r"$n_\mathrm{HALC}$ (oscillators on the high-amplitude limit cycle)",
           ylabel="fraction of samples",
           title=f"v_d = {row['v_d'].item():g}: {ds.attrs['n_samples']} samples, "
                 "95 % Wilson intervals")
    return fig
