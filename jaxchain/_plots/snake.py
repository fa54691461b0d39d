"""The snake: energy of every continued branch of localized periodic states against
the belt speed, over the points of the Fig. 3(b) sweep."""

import json

import numpy as np

from .canvas import single_axes
from .bifurcation import _segments

_MARKERS = {"fold": "o", "branch point": "s", "period doubling": "D", "Neimark-Sacker": "^",
            "sliding": "v", "grazing": "P", "multiplier jump": "*"}


def plot_snake(datasets: dict, sweep=None, title: str = "", ax=None):
    """Energy E of eq. (9) against v_d for every branch of `localized_branches`:
    stable solid, unstable dashed, each bifurcation marked by its kind; the points
    of a Fig. 3(b) sweep (`open_sweep` or `sweep`) in grey underneath when given.

    **Arguments:**

    - `datasets`: label -> a joined branch (the datasets of `localized_branches`), dims
        (point,).
    - `sweep`: an `xarray.Dataset` of a sweep (dims (v_d, ic)) or None.
    - `title`: the axes' title.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    fig, ax = single_axes(ax, (8, 5.5))
    if sweep is not None:
        v = np.broadcast_to(sweep["v_d"].values[:, None], sweep["energy"].shape)
        ax.plot(v.ravel(), np.asarray(sweep["energy"].values).ravel(), ".", color="0.6",
                ms=4, label="simulation (Fig. 3(b) sweep)", zorder=1)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    seen = set()
    for i, (label, ds) in enumerate(datasets.items()):
        c = colours[i % len(colours)]
        v, e, st = ds["v_d"].values, ds["energy"].values, ds["stable"].values
        for x, y, stable in _segments(v, e, st):
            ax.plot(x, y, "-" if stable else "--", color=c, lw=1.8 if stable else 1.0,
                    label=(f"{label}" if "switched" in label else f"{label} excited")
                    if stable and label not in seen else None)
            seen.add(label) if stable else None
        for b in json.loads(ds.attrs["bifurcations"]):
            kind = b["type"]
            ax.plot(b["v_d"], b["energy"], _MARKERS.get(kind, "x"), mfc="none", mec="k",
                    ms=7, label=kind if kind not in seen else None, zorder=5)
            seen.add(kind)
    ax.set_xlabel("belt speed $v_d$")
    ax.set_ylabel("energy $E = \\frac{1}{2}\\sum A_n^2$ (eq. (9))")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_title(title or "localized periodic states: stable solid, unstable dashed")
    if ax.get_legend_handles_labels()[0]:  # nothing stable and no bifurcation: no legend
        ax.legend(fontsize=8, loc="upper left")
    return fig
