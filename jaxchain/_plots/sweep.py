"""Fig. 3(b) of the paper: the energy of every state found, against the swept
parameter, with the ranges of propagating fronts shaded."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._bifurcation.hopf import hopf_speed
from .._physics.record import chain_from_record, chain_settings
from .._analysis.fronts import front_fractions, front_ranges
from .._engine.status import Status
from .canvas import panel_figure

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Colours of invading (+1) and receding (-1) fronts.
FRONT_COLOURS = {1: "tab:red", -1: "tab:blue"}
FRONT_NAMES = {1: "stick-slip invades", -1: "stick-slip recedes"}


def plot_bifurcation_diagram(ds: xr.Dataset, fig=None):
    """Draw a sweep in the manner of Fig. 3(b) of the paper.

    - Upper panel: the energy E of eq. (9) of every (value, initial condition) as a
        dot coloured by n_HALC. The fully stick-slipping chain (n_HALC = N) is
        joined by a line. Steady sliding (E = 0) is drawn, for a sweep over v_d,
        stable above the Hopf point of `hopf_vd_analytic` and unstable below; for
        another parameter, where it was found. Propagating fronts (`propagating_fronts`)
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

    **Returns:**

    The matplotlib Figure.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm
    from matplotlib.patches import Patch

    name = ds.attrs.get("swept", "v_d")
    ds = ds.sortby(name).transpose(name, "ic", ...)
    values = np.asarray(ds[name], dtype=float)
    energy = np.asarray(ds["energy"], dtype=float)
    n_halc = np.asarray(ds["n_halc"])
    ok = np.asarray(ds["status"]) == Status.ok
    front = np.where(ok, np.asarray(ds["front"]), 0)
    n_osc = int(ds.sizes["osc"])
    fractions = front_fractions(ds)
    fig = panel_figure(fig, (7.5, 6))
    ax, low = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})

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

    full = ok & (n_halc == n_osc)
    has_full = full.any(1)
    if has_full.any():
        ax.plot(values[has_full], [energy[i][full[i]].mean() for i in np.flatnonzero(has_full)],
                "-", color="k", lw=1, zorder=1,
                label=f"fully stick-slipping chain ({n_osc} on the HALC)")
    hopf = _hopf_vd(ds) if name == "v_d" else None
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

    x = np.broadcast_to(values[:, None], energy.shape)
    norm = BoundaryNorm(np.arange(-0.5, n_osc + 1.5), plt.get_cmap("viridis").N)
    ring = np.array([FRONT_COLOURS.get(int(f), "none") for f in front[ok]], dtype=object)
    dots = ax.scatter(x[ok], energy[ok], c=n_halc[ok], cmap="viridis", norm=norm, s=18,
                      zorder=2, edgecolors=ring, linewidths=1.2)
    bar = fig.colorbar(dots, ax=[ax, low], pad=0.02, fraction=0.05)
    bar.set_label(r"oscillators on the HALC, $n_\mathrm{HALC}$")
    bar.set_ticks(np.unique(np.linspace(0, n_osc, min(n_osc, 10) + 1).round().astype(int)))

    label = {"v_d": "belt speed $v_d$"}.get(name, name)
    ax.set_ylabel(r"$\tilde E = \frac{1}{2}\sum_n A_n^2$, eq. (9)")
    failed = int((~ok).sum())
    note = f"; {failed} failed run(s) not shown" if failed else ""
    ax.set_title(f"Bifurcation diagram, N = {n_osc} (cf. Fig. 3(b)){note}", fontsize=10)
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
    return fig


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


def _hopf_vd(ds: xr.Dataset) -> float | None:
    """The Hopf point of steady sliding for the chain of `ds` (its attributes,
    `chain_record`): the closed form of eq. (1) where it holds, else Newton's
    method on the Jacobian's eigenvalues (`hopf_speed`); None where there is none
    (xi = 0, mu_st = mu_d, or Newton's method fails)."""
    record = {k: v for k, v in ds.attrs.items() if k in chain_settings(ds.attrs)}
    try:
        params = chain_from_record(record)
    except (KeyError, ValueError, TypeError):
        return None
    value = hopf_speed(params)
    return value if np.isfinite(value) else None
