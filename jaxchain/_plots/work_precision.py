"""Work-precision diagrams: error against wall time, log-log."""

import numpy as np

from .._engine.status import Status
from .canvas import panel_figure

_MARKERS = {"scipy LSODA": "s", "scipy Radau": "D", "exact": "*"}


def plot_work_precision(rows: list[dict], scene: str, error: str = "amplitude_error",
                        fig=None):
    """One panel per eps, one line per diffrax solver over its rtols (wall time
    against `error`, log-log), and the outside points in black: scipy's LSODA and
    Radau at the same eps, and the exact engine at its own tolerances (rows
    "exact"; black stars joined, in every panel: it has no eps). Failed runs
    are marked x at the top of their panel.

    **Arguments:**

    - `rows`: rows of `work_precision` (dicts of strings).
    - `scene`: which scene to draw.
    - `error`: "amplitude_error", "energy_error" or "trajectory_error".
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """

    rows = [r for r in rows if r["scene"] == scene]
    eps_values = sorted({float(r["eps"]) for r in rows if float(r["eps"]) > 0}, reverse=True)
    fig = panel_figure(fig, (3.6 * max(1, len(eps_values)), 4.6))
    axes = fig.subplots(1, max(1, len(eps_values)), sharex=True, sharey=True, squeeze=False)
    solvers = sorted({r["method"] for r in rows} - set(_MARKERS))
    colors = {s: f"C{i}" for i, s in enumerate(solvers)}
    ok = [r for r in rows if r["status"] == Status.ok.name and r[error] != ""]
    values = [float(r[error]) for r in ok]
    top = 10 ** np.ceil(np.log10(max(values + [1e-1])))
    for ax, eps in zip(axes[0], eps_values):
        for solver in solvers:
            mine = [r for r in rows if r["method"] == solver and float(r["eps"]) == eps]
            good = sorted((r for r in mine if r in ok), key=lambda r: float(r["rtol"]),
                          reverse=True)
            if good:
                ax.plot([float(r["wall_s"]) for r in good],
                        [max(float(r[error]), 1e-16) for r in good], "o-", ms=3,
                        color=colors[solver], label=solver)
            bad = [r for r in mine if r["status"] != Status.ok.name and r["wall_s"] != ""]
            if bad:
                ax.plot([float(r["wall_s"]) for r in bad], [top] * len(bad), "x",
                        color=colors[solver])
        for method, marker in _MARKERS.items():
            pts = [r for r in ok if r["method"] == method
                   and (method == "exact" or float(r["eps"]) == eps)]
            if pts:
                exact = method == "exact"
                if exact:
                    pts.sort(key=lambda r: float(r["rtol"]), reverse=True)
                ax.plot([float(r["wall_s"]) for r in pts],
                        [max(float(r[error]), 1e-16) for r in pts],
                        marker + ("-" if exact else ""), color="k", ms=7 if exact else 4,
                        mfc="k" if exact else "none",
                        label="exact engine" if exact else method)
        ax.axhline(1e-2, color="0.6", lw=0.8, ls="--")
        ax.axhline(1e-3, color="0.6", lw=0.8, ls=":")
        ax.set(xscale="log", yscale="log", title=f"$\\varepsilon$ = {eps:g}",
               xlabel="wall time (s)")
        ax.tick_params(axis="x", which="minor", labelbottom=False)  # no crowded labels
    axes[0, 0].set_ylabel(f"{error.replace('_', ' ')} vs non-smooth")
    handles = {}
    for ax in axes[0]:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    # below the panels, where it covers no data
    fig.legend(handles.values(), handles.keys(), fontsize=7, loc="outside lower center",
               ncols=min(len(handles), 6))
    fig.suptitle(f"work-precision, {scene} scene (x: failed; dashed 1 %, dotted 0.1 %)")
    return fig
