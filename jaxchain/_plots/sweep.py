"""Fig. 3(b) of the paper: the energy of every state found, against the swept
parameter, with the ranges of propagating fronts shaded."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._analysis.fronts import front_fractions, front_ranges
from .._engine.status import Status
from .canvas import panel_figure

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Colours of invading (+1) and receding (-1) fronts.
FRONT_COLOURS = {1: "tab:red", -1: "tab:blue"}
FRONT_NAMES = {1: "stick-slip invades", -1: "stick-slip recedes"}


def plot_bifurcation_diagram(ds: xr.Dataset, fig=None, *, hopf_vd: float | None = None):
    """Draw a sweep in the manner of Fig. 3(b) of the paper.

    - Upper panel: the energy E of eq. (9) of every (value, initial condition) as a
        dot coloured by n_HALC. The fully stick-slipping chain (n_HALC = N) is
        joined by a line. Steady sliding (E = 0) is drawn, for a sweep over v_d
        given `hopf_vd`, stable above that Hopf point and unstable below; otherwise
        where it was found. Propagating fronts (`propagating_fronts`)
        are ringed, red where stick-slip invades the sliding oscillators and blue
        where it recedes; each value is shaded in proportion to the fraction of its
        initial conditions that made a front, and dashed lines bound the ranges of
        `front_ranges` of each kind, halfway to the nearest value without (the grid
        resolves them no better).
    - Lower panel: that fraction against the swept parameter, for both kinds.

    Failed runs are left out and counted in the title. A sweep converted by
    `to_physical` is drawn in its units (v_d and the Hopf point in m/s).

    **Arguments:**

    - `ds`: a Dataset from `sweep` (dims (name, ic), with `energy`, `n_halc`,
        `status` and `front`), dimensionless or in SI units (`to_physical`).
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.
    - `hopf_vd`: the Hopf point of steady sliding of the swept chain, dimensionless
        (`hopf_speed(params)`; drawn in m/s on a sweep in SI units); None or NaN
        where there is none.

    **Returns:**

    The matplotlib Figure.
    """
    name = ds.attrs.get("swept", "v_d")
    ds = ds.sortby(name).transpose(name, "ic", ...)
    values = np.asarray(ds[name], dtype=float)
    ok = np.asarray(ds["status"]) == Status.ok
    fig = panel_figure(fig, (7.5, 6))
    ax, low = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    _draw_fronts(ax, low, values, front_fractions(ds))
    hopf = (float(hopf_vd) if name == "v_d" and hopf_vd is not None and np.isfinite(hopf_vd)
            else None)
    _draw_lines(ax, ds, values, ok, hopf)
    _draw_states(fig, ax, low, ds, values, ok)
    _label(ax, low, ds, name, ok)
    return fig


def _draw_fronts(ax, low, values, fractions) -> None:
    """The shading of each value by its fraction of fronts of each kind, the dashed
    bounds of their ranges (upper panel), and the fractions as bars (lower panel)."""
    cells = _cells(values)
    for sign, colour in FRONT_COLOURS.items():
        share = fractions.sel(direction=sign).values
        for (lo, hi), f in zip(cells, share):
            if f > 0:
                ax.axvspan(lo, hi, color=colour, alpha=0.2 * f, lw=0)
        for lo, hi in front_ranges(values, share > 0):
            for edge in _edges(values, lo, hi, cells):
                ax.axvline(edge, color=colour, ls="--", lw=1)
        low.bar(values, share, width=0.8 * np.diff(cells, axis=1)[:, 0], color=colour,
                bottom=fractions.sel(direction=1).values if sign == -1 else 0)


def _draw_lines(ax, ds, values, ok, hopf) -> None:
    """The fully stick-slipping chain's line, and steady sliding: stable above the
    Hopf point `hopf` (dimensionless, None where not drawn) and unstable below, or
    where it was found."""
    energy = np.asarray(ds["energy"], dtype=float)
    n_halc = np.asarray(ds["n_halc"])
    n_osc = int(ds.sizes["osc"])
    full = ok & (n_halc == n_osc)
    has_full = full.any(1)
    if has_full.any():
        ax.plot(values[has_full], [energy[i][full[i]].mean() for i in np.flatnonzero(has_full)],
                "-", color="k", lw=1, zorder=1,
                label=f"fully stick-slipping chain ({n_osc} on the HALC)")
    si = ds.attrs.get("units") == "SI"  # converted by to_physical
    if hopf is not None and si:
        hopf *= float(ds.attrs["scale_velocity"])
    if hopf is not None:  # steady sliding, stable above the Hopf point
        span = (min(values[0], hopf), max(values[-1], hopf))
        ax.plot([span[0], hopf], [0, 0], ":", color="0.4", lw=2, zorder=1,
                label="steady sliding, unstable")
        ax.plot([hopf, span[1]], [0, 0], "-", color="0.4", lw=3, alpha=0.5, zorder=1,
                label=f"steady sliding, stable above v_d,H = {hopf:.4g}"
                      f"{' m/s' if si else ''} (Hopf)")
    else:
        has_sliding = (ok & (n_halc == 0)).any(1)
        if has_sliding.any():
            ax.plot(values[has_sliding], np.zeros(has_sliding.sum()), "-", color="0.4",
                    lw=3, alpha=0.5, zorder=1, label="steady sliding")


def _draw_states(fig, ax, low, ds, values, ok) -> None:
    """Every run that did not fail as a dot coloured by n_HALC, ringed where it made
    a front, and the colour bar."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm

    energy = np.asarray(ds["energy"], dtype=float)
    n_halc = np.asarray(ds["n_halc"])
    front = np.where(ok, np.asarray(ds["front"]), 0)
    n_osc = int(ds.sizes["osc"])
    x = np.broadcast_to(values[:, None], energy.shape)
    norm = BoundaryNorm(np.arange(-0.5, n_osc + 1.5), plt.get_cmap("viridis").N)
    ring = np.array([FRONT_COLOURS.get(int(f), "none") for f in front[ok]], dtype=object)
    dots = ax.scatter(x[ok], energy[ok], c=n_halc[ok], cmap="viridis", norm=norm, s=18,
                      zorder=2, edgecolors=ring, linewidths=1.2)
    bar = fig.colorbar(dots, ax=[ax, low], pad=0.02, fraction=0.05)
    bar.set_label(r"oscillators on the HALC, $n_\mathrm{HALC}$")
    bar.set_ticks(np.unique(np.linspace(0, n_osc, min(n_osc, 10) + 1).round().astype(int)))


def _label(ax, low, ds, name, ok) -> None:
    """The axes' labels and limits, the title (with the count of failed runs) and
    the legend."""
    from matplotlib.patches import Patch

    energy = np.asarray(ds["energy"], dtype=float)
    label = {"v_d": "belt speed $v_d$"}.get(name, name)
    ax.set_ylabel(r"$\tilde E = \frac{1}{2}\sum_n A_n^2$, eq. (9)")
    failed = int((~ok).sum())
    note = f"; {failed} failed run(s) not shown" if failed else ""
    ax.set_title(f"Bifurcation diagram, N = {int(ds.sizes['osc'])} (cf. Fig. 3(b)){note}",
                 fontsize=10)
    handles, _ = ax.get_legend_handles_labels()
    handles += [Patch(color=c, alpha=0.5, label=f"front: {FRONT_NAMES[s]}")
                for s, c in FRONT_COLOURS.items()]
    ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.9, ncols=2)
    ax.set_ylim(top=1.3 * max(float(np.nanmax(energy[ok], initial=0.0)), 1e-9))
    low.set_ylim(0, 1)
    low.set_ylabel("fronts\n(fraction of ics)")
    unit = ds[name].attrs.get("units", "1")
    low.set_xlabel(f"{label} ({'dimensionless' if unit == '1' else unit})")
    for a in (ax, low):
        for side in ("top", "right"):
            a.spines[side].set_visible(False)


def _cells(values) -> np.ndarray:
    """The interval of each sorted value: halfway to its neighbours, and as far
    again beyond the ends; shape (n, 2)."""
    if len(values) == 1:
        return np.array([[values[0] - 0.5, values[0] + 0.5]])
    mids = 0.5 * (values[1:] + values[:-1])
    lo = np.concatenate([[values[0] - (mids[0] - values[0])], mids])
    hi = np.concatenate([mids, [values[-1] + (values[-1] - mids[-1])]])
    return np.stack([lo, hi], 1)


def _edges(values, lo, hi, cells) -> list[float]:
    """Where the dashed lines of the range [lo, hi] go: halfway to the neighbouring
    values; none beyond the ends of the grid."""
    i, j = np.searchsorted(values, lo), np.searchsorted(values, hi)
    return ([cells[i, 0]] if i > 0 else []) + ([cells[j, 1]] if j + 1 < len(values) else [])
