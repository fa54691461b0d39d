"""An identification as figures: each record against its fit with the residuals, and
the identified friction law with its 95 % band."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .canvas import panel_figure, single_axes


def plot_record_fits(result, records, fig=None):
    """One column per record: (top) the measured displacements as dots and the
    fitted model as a line, (bottom) the residuals, measured minus fitted, with
    +-2 sigma (the record's residual standard deviation, `Identification.noise`).

    **Arguments:**

    - `result`: an `Identification`.
    - `records`: the records it was fitted to, in the same order.
    - `fig`: a Figure or SubFigure to draw on; a new figure if None.

    **Returns:** the matplotlib Figure.
    """
    fig = panel_figure(fig, (4.2 * len(records), 5.0))
    axes = fig.subplots(2, len(records), squeeze=False, sharex="col",
                        gridspec_kw={"height_ratios": (2.5, 1)})
    for j, (rec, fitted) in enumerate(zip(records, result.fits)):
        top, bottom = axes[0, j], axes[1, j]
        for k, n in enumerate(rec.oscillators):
            color = f"C{k}"
            top.plot(rec.t, rec.x[:, k], ".", ms=2, color=color, alpha=0.5,
                     label=f"$x_{{{n}}}$ measured")
            top.plot(rec.t, fitted[:, k], lw=1, color=color,
                     label=f"$x_{{{n}}}$ fitted")
            bottom.plot(rec.t, rec.x[:, k] - fitted[:, k], ".", ms=2, color=color)
        for s in (-2, 2):
            bottom.axhline(s * float(np.max(result.noise[j])), color="0.5", lw=0.8, ls="--")
        top.set(title=f"{Path(rec.source).name}, $v_d$ = {rec.v_d:g}",
                ylabel="x" if j == 0 else None)
        bottom.set(xlabel="t", ylabel="residual" if j == 0 else None)
        if j == 0:
            top.legend(fontsize=7, loc="upper right")
    return fig


def plot_friction_band(result, speeds=None, truth=None, ax=None):
    """The identified friction coefficient mu(v_rel) with its pointwise 95 % band
    (+-1.96 standard errors, by the delta method, `Identification.propagate`).

    **Arguments:**

    - `result`: an `Identification`.
    - `speeds`: the relative speeds |v_rel| drawn, shape (m,); default 0 to 3.
    - `truth`: a friction law to draw for comparison (a test with known
        parameters), or None.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:** the matplotlib Figure.
    """
    fig, ax = single_axes(ax, (5.5, 4.0))
    speeds = np.linspace(0.0, 3.0, 301) if speeds is None else np.asarray(speeds)
    mu, se = result.propagate(lambda p: p.friction(speeds))
    ax.fill_between(speeds, mu - 1.96 * se, mu + 1.96 * se, color="C0", alpha=0.3,
                    label=f"95 % band (half-width up to {1.96 * np.max(se):.2g})")
    ax.plot(speeds, mu, color="C0", label=f"identified ({type(result.chain.friction).__name__})")
    if truth is not None:
        ax.plot(speeds, np.asarray(truth(speeds)), "k--", lw=1, label="true")
    ax.set(xlabel=r"$|v_\mathrm{rel}|$", ylabel=r"$\mu$", title="identified friction law")
    ax.legend()
    return fig
