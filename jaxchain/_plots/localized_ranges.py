"""The figure of the localized-ranges study: the one-site state's stable range in
v_d over mistuning draws, its two ends and its width."""

import numpy as np

from .canvas import panel_figure


def plot_localized_ranges(ds, fig=None):
    """Three panels from `localized_ranges`'s Dataset `ds`, one colour per mistuning
    strength: (a) the distribution of the lower end (Neimark-Sacker point or fold)
    over the draws, (b) of the upper end (the fold), each with the tuned ring's end
    by the driver as a black line, and (c) each draw's range as a horizontal bar,
    the draws sorted by their lower end, one block per strength.

    Draws on `fig` (a Figure or a SubFigure) when given, on a new figure otherwise.

    **Returns:** the Figure (or SubFigure) drawn on.
    """
    import matplotlib.pyplot as plt

    fig = panel_figure(fig, (14, 4.4))
    a, b, c = fig.subplots(1, 3)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    offset = 0
    for i, s in enumerate(ds["sigma"].values):
        part = ds.sel(sigma=s)
        ok = part["found"].values
        low, high = part["low"].values[ok], part["high"].values[ok]
        colour = colours[i % len(colours)]
        label = f"sigma = {float(part['sigma_over_eta_c']):g} eta_c ({ok.sum()} draws)"
        for ax, values in ((a, low), (b, high)):
            if values.size:
                ax.hist(values, bins=30, histtype="step", lw=1.5, color=colour, label=label)
        order = np.argsort(low)
        rows = offset + np.arange(order.size)
        c.hlines(rows, low[order], high[order], color=colour, lw=0.8)
        offset += order.size + 10
    for ax, end, title in ((a, "tuned_low", "(a) lower end"), (b, "tuned_high", "(b) upper end")):
        ax.axvline(ds.attrs[end], color="k", lw=1, label="tuned ring")
        ax.set_xlabel("v_d")
        ax.xaxis.set_major_locator(plt.MaxNLocator(5))
        ax.set_ylabel("draws")
        ax.set_title(title)
        ax.legend(fontsize=7)
    for end in ("tuned_low", "tuned_high"):
        c.axvline(ds.attrs[end], color="k", lw=1)
    c.set_xlabel("v_d")
    c.set_ylabel("draws, by lower end")
    c.set_yticks([])
    c.set_title("(c) each draw's stable range")
    return fig
