"""The single oscillator's bifurcation diagram (Fig. 3(a) of the paper) and the
bistable region against a design parameter."""

import numpy as np

from .canvas import panel_figure, single_axes


def _segments(x, y, flags):
    """Split a curve into runs of equal flag, each run sharing its end point with
    the next so that the curve is unbroken."""
    start = 0
    for i in range(1, len(x) + 1):
        if i == len(x) or flags[i] != flags[start]:
            end = min(i + 1, len(x))
            yield x[start:end], y[start:end], flags[start]
            start = i


def plot_limit_cycle_branch(branch, hopf_vd: float, fold_vd: float, fold_energy: float,
                            simulations=None, v_range=(0.5, 2.3), title: str = "",
                            ax=None):
    """Fig. 3(a) of the paper: energy E = A^2/2 (eq. (9)) of the single oscillator
    against v_d. Steady sliding (E = 0) and the limit-cycle branch of the
    continuation, stable solid and unstable dashed; the Hopf and fold points
    marked; simulation results as dots.

    **Arguments:**

    - `branch`: the limit-cycle `Branch` from the Hopf point.
    - `hopf_vd`, `fold_vd`, `fold_energy`: the Hopf and fold points.
    - `simulations`: (v_d of shape (n,), energy of shape (n, n_ic)) or None.
    - `v_range`: the v_d axis; `title`: the axes' title.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """

    fig, ax = single_axes(ax, (7, 4.5))
    ax.plot([v_range[0], hopf_vd], [0, 0], "k--", lw=1.5)
    ax.plot([hopf_vd, v_range[1]], [0, 0], "k-", lw=1.5, label="steady sliding")
    ok = np.asarray(branch.converged)
    p = np.asarray(branch.p)[ok]
    energy = np.asarray(branch.records.energy)
    stable = np.asarray(branch.records.stable)
    labelled = set()
    for x, y, s in _segments(p, energy, stable):
        label = "stable limit cycle" if s else "unstable limit cycle"
        ax.plot(x, y, "-" if s else "--", color="C0" if s else "C3", lw=1.5,
                label=None if label in labelled else label)
        labelled.add(label)
    ax.plot([hopf_vd], [0], "o", color="C1", ms=8, label=f"Hopf, $v_d$ = {hopf_vd:.4f}")
    ax.plot([fold_vd], [fold_energy], "s", color="C2", ms=8,
            label=f"fold, $v_d$ = {fold_vd:.4f}")
    if simulations is not None:
        v, e = simulations
        for j in range(e.shape[1]):
            ax.plot(v, e[:, j], "k.", ms=7, label="simulation" if j == 0 else None)
    ax.set(xlabel="belt speed $v_d$", ylabel=r"energy $\tilde E = A^2 / 2$", xlim=v_range,
           title=title or "single oscillator (Fig. 3(a))")
    ax.legend(fontsize=8, loc="upper left")
    return fig


def plot_bistable_region(curves_xi, curves_ratio, mu_d: float | None, design=None,
                         limits=None, fig=None, fold_label: str = "fold of limit cycles"):
    """The bistable range of belt speeds (between the Hopf point and the fold)
    against the damping ratio xi and, for eq. (1), against mu_st/mu_d. The fold is
    drawn along its continued branch, with markers at the requested values.

    **Arguments:**

    - `curves_xi`, `curves_ratio`: `BoundaryCurves` in xi and in mu_st (None for
        another friction law: one panel only).
    - `mu_d`: the dynamic friction coefficient (to turn mu_st into the ratio).
    - `design`: a `DampingDesign` to mark, or None.
    - `limits`: the non-smooth existence limits at the values of each curve, two
        sequences, or None.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.
    - `fold_label`: the legend of the upper edge (the exact model's is grazing).

    **Returns:**

    The matplotlib Figure.
    """
    panels = [(curves_xi, 1.0, r"damping ratio $\xi$")]
    if curves_ratio is not None:
        panels.append((curves_ratio, 1 / mu_d, r"$\mu_{st} / \mu_d$"))
    fig = panel_figure(fig, (5.5 * len(panels), 4.5))
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (curves, scale, name) in zip(axes, panels):
        x = np.asarray(curves.values) * scale
        hopf, fold = np.asarray(curves.hopf_vd), np.asarray(curves.fold_vd)
        ax.fill_between(x, hopf, fold, color="C0", alpha=0.25,
                        label="bistable: steady sliding and stick-slip")
        ax.plot(x, hopf, "o-", color="C1", label=r"Hopf $v_{d,H}$")
        for i, branch in enumerate(curves.branches):
            # the fold curve's unknowns are (u, fold v_d, w), u and w of one size
            ok = np.asarray(branch.converged)
            on = np.asarray(branch.p)[ok] * scale
            fold_vd = np.asarray(branch.u)[ok, (branch.u.shape[1] - 1) // 2]
            ax.plot(on, fold_vd, "-", color="C2", lw=1,
                    label="fold, continued" if i == 0 else None)
        ax.plot(x, fold, "s", color="C2", label=fold_label)
        if limits is not None:
            ax.plot(x, limits[ax is not axes[0]], "x", color="k",
                    label="non-smooth existence limit")
        pad = 0.03 * (x.max() - x.min()) or 0.05 * max(abs(x.max()), 1e-3)  # one value
        ax.set(xlabel=name, ylabel="belt speed $v_d$", xlim=(x.min() - pad, x.max() + pad))
    if design is not None:
        axes[0].plot([design.xi, design.xi], [design.hopf_vd, design.fold_vd], "k-", lw=2,
                     label=f"design: $\\xi$ = {design.xi:.4f}, window {design.window:.3f}")
    axes[0].set_title("(a) against damping")
    if len(axes) > 1:
        axes[1].set_title("(b) against the friction ratio")
    for ax in axes:
        ax.legend(fontsize=8)
    return fig
