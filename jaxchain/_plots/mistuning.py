"""Figures of `mistuning_study`: what random mistuning does to the localized states
(staircase, basin stability, the edges of the bistable range, localization
lengths), and Fig. 4 for one mistuned draw beside its stiffness deviations."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._studies.mistuning.summary import (edge_correlations, localized_fraction,
                                  neighbour_detuning, staircase_fraction)
from .canvas import panel_figure, single_axes
from .localized import plot_localized_states

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def _errorbars(ax, x, share, labels):
    for j, label in enumerate(labels):
        f = share["fraction"][:, j]
        ax.errorbar(x + 0.03 * (j - 1), f, yerr=[f - share["low"][:, j],
                                                  share["high"][:, j] - f],
                    marker="o", capsize=3, label=label)


def plot_mistuning_study(study: xr.Dataset, fig=None):
    """Four panels over sigma / eta_c: (a) the share of eq. (8) starts with k
    excited that keep n_HALC = k (the Fig. 4 staircase), (b) basin stability of
    the localized states (0 < n_HALC < N), each per belt speed with 95 % Wilson intervals; (c) the
    upper edge of the bistable range of each draw (simulation, and the fold by
    shooting where computed), the Hopf points in the title; (d) the decay per cell of the
    single-site state's amplitudes against the linear predictions.

    **Arguments:**

    - `study`: the Dataset of `mistuning_study`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    s = study["sigma"].values
    labels = [f"$v_d$ = {v:g}" for v in study["v_d"].values]
    fig = panel_figure(fig, (10, 7.5))
    axes = fig.subplots(2, 2)
    ax = axes[0, 0]
    _errorbars(ax, s, staircase_fraction(study), labels)
    ax.set_ylabel(r"share with $n_\mathrm{HALC} = k$")
    ax.set_title("(a) the Fig. 4 staircase:\nk excited gives k on the HALC", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    _errorbars(ax, s, localized_fraction(study), labels)
    ax.set_ylabel("basin stability of localized states")
    ax.set_title(f"(b) random starts ({study.attrs['n_samples']} per draw) ending\n"
                 "localized ($0 < n_\\mathrm{HALC} < N$)", fontsize=9)
    ax = axes[1, 0]
    for i, sigma in enumerate(s):
        edge = study["upper_edge"].values[i]
        edge = edge[np.isfinite(edge)]
        ax.plot(np.full(edge.size, sigma), edge, "o", color="tab:blue", alpha=0.5,
                label="upper edge, simulation" if i == 0 else None)
        fold = study["fold_vd"].values[i]
        fold = fold[np.isfinite(fold)]
        ax.plot(np.full(fold.size, sigma), fold, "x", color="k", ms=8,
                label="fold by shooting" if i == 0 else None)
    hopf = study["hopf_vd"].values
    ax.set_ylabel("$v_d$")
    ax.set_title(f"(c) upper edge of the bistable range, per draw\n(Hopf point of every "
                 f"draw: {np.nanmin(hopf):.5f}-{np.nanmax(hopf):.5f})", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[1, 1]
    decay = study["envelope_decay"].values
    for i, sigma in enumerate(s):
        d = decay[i][np.isfinite(decay[i])]
        ax.plot(np.full(d.size, sigma), d, "o", color="tab:blue", alpha=0.5,
                label="single-site state, fitted" if i == 0 else None)
    ax.axhline(study.attrs["state_damped_decay"], color="k", ls="--", lw=1,
               label="damped homogeneous chain")
    ax.errorbar(s, study["state_gamma"].values, yerr=study["state_gamma_error"].values,
                color="tab:green", marker="s", label="Anderson, at the state's frequency")
    ax.errorbar(s, study["gamma"].values[:, 0], yerr=study["gamma_error"].values[:, 0],
                color="tab:orange", marker="^", label="Anderson, band centre")
    ax.set_ylabel("decay per cell")
    ax.set_title("(d) localization: the state's envelope\nagainst linear chains",
                 fontsize=9)
    ax.legend(fontsize=7)
    for ax in axes.ravel():
        ax.set_xlabel(r"$\sigma / \eta_c$")
    return fig


def plot_site_edges(study: xr.Dataset, ax=None):
    """The largest belt speed at which the single-site state at each oscillator
    survives, against how far that oscillator is tuned from its neighbours
    (`neighbour_detuning`), every draw and sigma.

    **Arguments:**

    - `study`: the Dataset of `mistuning_study`.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig, ax = single_axes(ax, (6, 4.2))
    eta_c = float(study.attrs["eta_c"])
    detuning = neighbour_detuning(study["deviations"].values,
                                  str(study.attrs.get("boundary", "ring"))) / eta_c
    for i, sigma in enumerate(study["sigma"].values):
        if sigma == 0:
            continue
        x, edge = detuning[i].ravel(), study["site_edge"].values[i].ravel()
        keep = np.isfinite(x) & np.isfinite(edge)
        ax.plot(x[keep], edge[keep], ".", alpha=0.6,
                label=f"$\\sigma$ = {sigma:g} $\\eta_c$")
    if 0.0 in study["sigma"]:
        ax.axhline(np.nanmedian(study["site_edge"].sel(sigma=0.0).values), color="k", lw=1,
                   ls="--", label="homogeneous ring")
    r = edge_correlations(study)["neighbour_detuning"]
    ax.set_xlabel(r"$(\delta_n - \bar\delta_\mathrm{neighbours}) / \eta_c$")
    ax.set_ylabel("upper edge of its single-site state, $v_d$")
    ax.set_title("Where a single-site state ends, against its detuning from its "
                 f"neighbours\n(correlation of the edge with |detuning|: {r:.2f})", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def plot_mistuned_states(study: xr.Dataset, sigma: float, draw: int = 0, v_d: float = 1.5,
                         fig=None):
    """Fig. 4 of the paper for one mistuned draw: the states reached from eq. (8)
    with k = 1..N excited, beside the stiffness deviations delta_n / eta_c.

    **Arguments:**

    - `study`: the Dataset of `mistuning_study`.
    - `sigma`: sigma / eta_c of the draw (nearest); `draw`: its index;
        `v_d`: the belt speed (nearest).
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    import xarray as xr

    row = study.sel(sigma=sigma, v_d=v_d, method="nearest").isel(draw=draw)
    amps = row["staircase_amplitudes"].values
    ds = xr.Dataset({"amplitudes": (("v_d", "ic", "osc"), amps[None]),
                     "n_halc": (("v_d", "ic"), row["staircase_n_halc"].values[None]),
                     "status": (("v_d", "ic"), row["staircase_status"].values[None]),
                     "energy": (("v_d", "ic"), 0.5 * np.nansum(amps**2, -1)[None])},
                    coords={"v_d": [float(row["v_d"])], "n_excited": ("ic", row["k"].values)})
    n = amps.shape[-1]
    fig = panel_figure(fig, (0.45 * n + 2.5, 0.4 * n + 3.2))
    top, bottom = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1, 4]}, sharex=True)
    dev = row["deviations"].values / float(study.attrs["eta_c"])
    top.bar(np.arange(1, n + 1), dev, color=np.where(dev > 0, "tab:red", "tab:blue"))
    top.axhline(0, color="k", lw=0.5)
    top.set_ylabel(r"$\delta_n / \eta_c$")
    top.set_title(f"draw {draw} at $\\sigma$ = {float(row['sigma']):g} $\\eta_c$: "
                  "stiffness deviations (red stiffer, blue softer)", fontsize=9)
    plot_localized_states(ds, ax=bottom)
    bottom.set_aspect("auto")
    return fig


def plot_mistuning_design(result: dict, fig=None):
    """The designs of `design_study` against the A-B pattern and random draws of the
    same budget: the highest single-site fold on the design's ring (shooting),
    and the upper edge of the patterns tiled on the longer ring (simulation).

    **Arguments:**

    - `result`: the dict of `design_study`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig = panel_figure(fig, (10, 4.2))
    left, right = fig.subplots(1, 2, sharey=True)
    hom = result["homogeneous_fold"]
    names = ["homogeneous"] + list(result["designs"]) + ["ab"]
    values = [hom] + [d["edge"] for d in result["designs"].values()] + [result["ab"]["edge"]]
    left.plot(range(len(names)), values, "o", color="tab:blue", ms=8)
    rand = [r["edge"] for r in result["random"] if r["edge"] is not None]
    left.plot(np.full(len(rand), len(names)), rand, "x", color="tab:gray")
    left.set_xticks(range(len(names) + 1), names + ["random"], rotation=20)
    left.axhline(hom, color="k", lw=0.6, ls="--")
    left.set_ylabel("highest fold of the single-site states, $v_d$")
    left.set_title(f"ring of {result['n_osc']} (period of the pattern), shooting,\n"
                   f"$|\\delta_n| \\leq$ {result['budget']:g}", fontsize=9)
    edges = result["chain_edges"]["edge"]
    fixed = [k for k in edges if not k.startswith("random")]
    right.plot(range(len(fixed)), [edges[k] for k in fixed], "o", color="tab:green", ms=8)
    rand = [v for k, v in edges.items() if k.startswith("random")]
    right.plot(np.full(len(rand), len(fixed)), rand, "x", color="tab:gray")
    right.set_xticks(range(len(fixed) + 1), fixed + ["random"], rotation=20)
    right.axhline(edges["homogeneous"], color="k", lw=0.6, ls="--")
    right.set_title(f"tiled on the ring of {result['chain_edges']['n_osc']}: upper edge\n"
                    f"by simulation ($\\pm$ {result['chain_edges']['resolution'] / 2:.4f})",
                    fontsize=9)
    return fig
