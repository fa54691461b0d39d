"""The snake: energy of every continued branch of localized periodic states against
the belt speed, over the points of the Fig. 3(b) sweep."""

import numpy as np

from .._bifurcation.branch_file import stored_branch

from .canvas import single_axes
from .bifurcation import _segments

_MARKERS = {"fold": "o", "branch point": "s", "period doubling": "D", "Neimark-Sacker": "^",
            "sliding": "v", "grazing": "P", "multiplier jump": "*",
            "Hopf": "h"}


def plot_snake(datasets: dict, sweep=None, title: str = "", ax=None):
    """Energy E of eq. (9) against v_d for every branch of `localized_branches`:
    stable solid, unstable dashed, each bifurcation marked by its kind, each branch
    coloured by the number of sites k that its start excites (a colour bar when
    there are several k; a switched or deflated branch has its start's); the points
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
    from matplotlib.ticker import MaxNLocator

    fig, ax = single_axes(ax, (8, 5.5))
    if sweep is not None:
        v = np.broadcast_to(sweep["v_d"].values[:, None], sweep["energy"].shape)
        ax.plot(v.ravel(), np.asarray(sweep["energy"].values).ravel(), ".", color="0.6",
                ms=4, label="simulation (Fig. 3(b) sweep)", zorder=1)
    # A branch's colour is the number of sites its start excites (the attribute
    # `excited`; a switched or deflated branch has its start's): with every k of a
    # long ring on one axes, a colour map and its colour bar say more than a legend.
    ks = [int(ds.attrs.get("excited", i + 1)) for i, ds in enumerate(datasets.values())]
    several = len(set(ks)) > 1
    norm = plt.Normalize(min(ks, default=1) - 0.5, max(ks, default=1) + 0.5)
    cmap = plt.get_cmap("viridis" if several else "tab10")
    seen = set()
    for k, ds in zip(ks, datasets.values()):
        c = cmap(norm(k)) if several else cmap(0)
        v, e, st = ds["v_d"].values, ds["energy"].values, ds["stable"].values
        for x, y, stable in _segments(v, e, st):
            style = "stable" if stable else "unstable"
            ax.plot(x, y, "-" if stable else "--", color=c, lw=1.8 if stable else 1.0)
            if style not in seen:  # the legend's entries for the two line styles
                ax.plot([], [], "-" if stable else "--", color="k",
                        lw=1.8 if stable else 1.0, label=style)
                seen.add(style)
        for b in stored_branch(ds).bifurcations:
            kind = b.kind
            ax.plot(b.p, b.energy, _MARKERS.get(kind, "x"), mfc="none", mec="k",
                    ms=7, label=kind if kind not in seen else None, zorder=5)
            seen.add(kind)
    if several:
        bar = ax.figure.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax)
        bar.set_label("sites excited at the start (eq. (8), k)")
        bar.locator = MaxNLocator(integer=True)
        bar.update_ticks()
    ax.set_xlabel("belt speed $v_d$")
    ax.set_ylabel("energy $E = \\frac{1}{2}\\sum A_n^2$ (eq. (9))")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_title(title or "localized periodic states: stable solid, unstable dashed")
    if ax.get_legend_handles_labels()[0]:  # no branch drawn: no legend
        ax.legend(fontsize=8, loc="upper left")
    return fig
