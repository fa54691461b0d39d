"""The figure of the forced mistuned ring's study: the amplitude magnification over
the mistuning strength, with Whitehead's bound."""

import numpy as np

from .canvas import panel_figure


def plot_magnification(ds, fig=None):
    """Two panels from `magnification_study`'s Dataset `ds`: (a) the mean, the 95th
    percentile and the largest magnification over the converged draws against
    sigma / eta_c, one colour per friction coefficient, with Whitehead's bound
    (1 + sqrt(N)) / 2; (b) the distribution of the draws' magnification at the
    strength of the largest mean (the linear ring's where it was run), one
    histogram per friction coefficient.

    Draws on `fig` (a Figure or a SubFigure) when given, on a new figure otherwise.

    **Returns:** the Figure (or SubFigure) drawn on.
    """
    import matplotlib.pyplot as plt

    fig = panel_figure(fig, (11, 4.2))
    a, b = fig.subplots(1, 2)
    ratio = ds["sigma_over_eta_c"].values
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    means = []
    for i, mu in enumerate(ds["mu"].values):
        m = ds["magnification"].sel(mu=mu).values
        ok = ds["converged"].sel(mu=mu).values
        stats = np.array([[np.mean(r[o]), np.percentile(r[o], 95), np.max(r[o])]
                          if o.any() else [np.nan] * 3 for r, o in zip(m, ok)])
        means.append(stats[:, 0])
        c = colours[i % len(colours)]
        label = "linear (mu = 0)" if mu == 0 else f"mu = {mu:g}"
        a.plot(ratio, stats[:, 0], "o-", color=c, label=f"{label}: mean")
        a.plot(ratio, stats[:, 1], "s--", color=c, alpha=0.7, label="95th percentile")
        a.plot(ratio, stats[:, 2], "^:", color=c, alpha=0.7, label="largest")
    a.axhline(ds.attrs["whitehead_bound"], color="k", lw=1)
    a.text(ratio[0], ds.attrs["whitehead_bound"], " Whitehead (1 + sqrt N)/2",
           va="bottom", fontsize=8)
    a.axhline(1.0, color="0.6", lw=0.8)
    a.set_xscale("log")
    a.set_xlabel("mistuning strength sigma / eta_c")
    a.set_ylabel("amplitude magnification")
    a.set_title(f"(a) {ds.sizes['draw']} draws per strength, N = {ds.attrs.get('n_osc', '')}")
    a.legend(fontsize=7, ncol=2)
    j = int(np.nanargmax(means[0]))
    for i, mu in enumerate(ds["mu"].values):
        m = ds["magnification"].sel(mu=mu).values[j]
        ok = ds["converged"].sel(mu=mu).values[j]
        b.hist(m[ok], bins=40, alpha=0.6, color=colours[i % len(colours)],
               label="linear" if mu == 0 else f"mu = {mu:g}")
    b.axvline(ds.attrs["whitehead_bound"], color="k", lw=1)
    b.set_xlabel("amplitude magnification")
    b.set_ylabel("draws")
    b.set_title(f"(b) sigma / eta_c = {ratio[j]:g}")
    b.legend(fontsize=8)
    return fig
