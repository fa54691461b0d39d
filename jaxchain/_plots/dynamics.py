"""Figs. 5-10 of the paper: time series, time delays, 3-D phase plots and orbit
diagrams of the localized states, drawn from the Datasets of
`jaxchain._studies.scenes`."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._analysis.delays import reference_oscillator, time_delays
from .canvas import panel_figure, single_axes
from .localized import plot_localized_states

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Marker colour of each class in the orbit diagrams.
CLASS_COLOURS = {"periodic": "tab:blue", "irregular": "tab:red", "undecided": "tab:orange",
                 "steady sliding": "tab:gray", "failed": "k"}


def _solution_delays(ds: xr.Dataset, i: int):
    """The time delays of solution i (by position) of a classified scene:
    (tau_ref, phi of the HALC oscillators, the reference's own 0 included, their
    1-based numbers, the 1-based reference)."""
    row = ds.isel(solution=i)
    on_halc = np.asarray(row["on_halc"], dtype=bool)
    ref = (int(row["ref"]) - 1 if "ref" in row
           else reference_oscillator(on_halc, ds.attrs.get("boundary", "ring")))
    ref = max(ref, 0)
    tau_ref, phi = time_delays(np.asarray(row["peak_times"]), ref)
    shown = on_halc.copy()
    shown[ref] = True
    return tau_ref, phi[shown], np.flatnonzero(shown) + 1, ref + 1


def _label(row) -> str:
    text = f"{int(row['solution'])} excited"
    if "class" in row:
        text += f": {str(row['class'].values)}"
    return text


def plot_time_series(ds: xr.Dataset, fig=None):
    """Fig. 5: (a) x_n against time, (b) the phase plot x_n' against x_n, (c) x_n'
    against time, one colour per oscillator, for the first solution of a
    `time_series_scene`.

    **Arguments:**

    - `ds`: the Dataset of `time_series_scene`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    import matplotlib.pyplot as plt

    row = ds.isel(solution=0)
    t, series = ds["time"].values, np.asarray(row["series"])
    fig = panel_figure(fig, (13, 3.8))
    axes = fig.subplots(1, 3)
    colours = plt.cm.viridis(np.linspace(0, 1, series.shape[-1]))
    for n in range(series.shape[-1]):
        x, v = series[:, 0, n], series[:, 1, n]
        axes[0].plot(t, x, lw=0.6, color=colours[n])
        axes[1].plot(x, v, lw=0.4, color=colours[n])
        axes[2].plot(t, v, lw=0.6, color=colours[n])
    v_d = float(ds.attrs["v_d"])
    for ax in (axes[1], axes[2]):
        ax.axhline(v_d, color="k", lw=0.6, ls=":")
    axes[0].set(xlabel=r"time $\tau$", ylabel="$x_n$", title="(a) displacement")
    axes[1].set(xlabel="$x_n$", ylabel="$x_n'$", title="(b) phase plot (stick at $x' = v_d$)")
    axes[2].set(xlabel=r"time $\tau$", ylabel="$x_n'$", title="(c) velocity")
    fig.suptitle(f"Time series, $v_d$ = {v_d:g}, {int(row['solution'])} oscillators "
                 f"excited (cf. Fig. 5)", fontsize=10)
    return fig


def _grid(fig, n: int):
    """(figure, axes) of a grid of n panels, three per row."""
    cols = min(3, n)
    rows = -(-n // cols)
    fig = panel_figure(fig, (4.2 * cols, 2.9 * rows))
    return fig, fig.subplots(rows, cols, squeeze=False)


def plot_time_delays(ds: xr.Dataset, fig=None):
    """Fig. 6: for each solution of a `time_delay_scene`, the time delays phi_i =
    tau_peak,i - tau_peak,ref of its HALC oscillators against time, with the start
    of the classification window marked.

    **Arguments:**

    - `ds`: the Dataset of `time_delay_scene`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig, axes = _grid(fig, ds.sizes["solution"])
    start = ds.attrs.get("classify_from")
    for i, ax in enumerate(axes.flat):
        if i >= ds.sizes["solution"]:
            ax.set_visible(False)
            continue
        tau, phi, numbers, ref = _solution_delays(ds, i)
        for row, n in zip(phi, numbers):
            ax.plot(tau, row, ".", ms=0.8, label=str(n))
        if start is not None:
            ax.axvline(start, color="k", lw=0.6, ls=":")
        ax.set_title(f"({chr(97 + i)}) {_label(ds.isel(solution=i))}", fontsize=9)
        ax.set(xlabel=r"time $\tau$",
               ylabel=f"$\\varphi_i = \\tau_i - \\tau_{{{ref}}}$")
    fig.suptitle(f"Time delays of the HALC oscillators, $v_d$ = "
                 f"{float(ds.attrs['v_d']):g} (cf. Fig. 6)", fontsize=10)
    return fig


def plot_phase_portraits(ds: xr.Dataset, fig=None):
    """Fig. 7: for each solution of a `phase_portrait_scene`, the 3-D phase plot of
    the displacements of its three oscillators over the observed window.

    **Arguments:**

    - `ds`: the Dataset of `phase_portrait_scene`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    n = ds.sizes["solution"]
    cols = min(3, n)
    rows = -(-n // cols)
    fig = panel_figure(fig, (4 * cols, 3.6 * rows))
    numbers = ds["series_osc"].values
    for i in range(n):
        ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
        x = np.asarray(ds["series"].isel(solution=i))[:, 0]
        ax.plot(x[:, 0], x[:, 1], x[:, 2], lw=0.3)
        ax.set_title(f"({chr(97 + i)}) {_label(ds.isel(solution=i))}", fontsize=9)
        ax.set_xlabel(f"$x_{{{numbers[0]}}}$", fontsize=8)
        ax.set_ylabel(f"$x_{{{numbers[1]}}}$", fontsize=8)
        ax.set_zlabel(f"$x_{{{numbers[2]}}}$", fontsize=8)
        ax.tick_params(labelsize=6)
    t = ds["time"].values
    fig.suptitle(f"Phase plots over $\\tau$ in [{t[0]:g}, {t[-1]:g}], $v_d$ = "
                 f"{float(ds.attrs['v_d']):g} (cf. Fig. 7)", fontsize=10)
    return fig


def plot_orbit_diagram(ds: xr.Dataset, ax=None):
    """Figs. 8, 9(b) and 10(b): the orbit diagram, every time delay phi of the HALC
    oscillators over the observed window against the solution number, coloured by
    class (`CLASS_COLOURS`; a periodic state shows a few dots, an irregular one a
    smear).

    **Arguments:**

    - `ds`: a classified Dataset of `orbit_diagram_scene`.
    - `ax`: a matplotlib Axes; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig, ax = single_axes(ax, (8, 4))
    start = float(ds.attrs.get("classify_from", ds.attrs["transient"]))
    for i in range(ds.sizes["solution"]):
        row = ds.isel(solution=i)
        tau, phi, _, _ = _solution_delays(ds, i)
        values = phi[:, tau >= start].ravel()
        values = values[np.isfinite(values)]
        colour = CLASS_COLOURS.get(str(row["class"].values), "k")
        ax.plot(np.full(values.size, int(row["solution"])), values, ".", ms=1.5,
                color=colour, alpha=0.5)
    for name, colour in CLASS_COLOURS.items():
        if name in set(np.asarray(ds["class"]).tolist()):
            ax.plot([], [], ".", color=colour, label=name)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_xticks(ds["solution"].values)
    ax.set(xlabel="solution (oscillators excited)", ylabel=r"time delay $\varphi$")
    ax.set_title(f"Orbit diagram, $v_d$ = {float(ds.attrs['v_d']):g}, $\\tau$ in "
                 f"[{start:g}, {float(ds.attrs['t_end']):g}] (cf. Figs. 8-10)", fontsize=9)
    return fig


def plot_states_and_orbits(ds: xr.Dataset, fig=None):
    """Figs. 9 and 10: (a) the localized states as circles (`plot_localized_states`)
    and (b) the orbit diagram (`plot_orbit_diagram`) of an `orbit_diagram_scene`.

    **Arguments:**

    - `ds`: a classified Dataset of `orbit_diagram_scene`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    n_sol, n_osc = ds.sizes["solution"], ds.sizes["osc"]
    fig = panel_figure(fig, (0.45 * n_osc + 10, max(4.0, 0.4 * n_sol + 1.2)))
    ax_a, ax_b = fig.subplots(1, 2, gridspec_kw={"width_ratios": [0.45 * n_osc + 4, 7]})
    states = (ds[["amplitudes", "n_halc", "energy", "status"]]
              .rename(solution="ic").expand_dims(v_d=[float(ds.attrs["v_d"])])
              .assign_coords(n_excited=("ic", ds["solution"].values)))
    plot_localized_states(states, ax=ax_a)
    ax_a.set_title("(a) " + ax_a.get_title(), fontsize=9)
    plot_orbit_diagram(ds, ax=ax_b)
    ax_b.set_title("(b) " + ax_b.get_title(), fontsize=9)
    return fig
