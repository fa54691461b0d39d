"""The cross-check of smoothed against non-smooth, as a figure."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .canvas import panel_figure

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def plot_crosscheck(ds: xr.Dataset, fig=None):
    """Two panels: (a) every oscillator's amplitude, smoothed against non-smooth,
    on the diagonal when they agree; (b) the amplitude error of each case against
    v_d, filled for periodic states (of the reference), open for irregular ones,
    each family shifted a little along v_d so that none hides another, a red cross
    where n_HALC disagrees, and the 1 % line.

    **Arguments:**

    - `ds`: a Dataset from `crosscheck`.
    - `fig`: a matplotlib Figure or SubFigure to draw the panels on; a new figure
        if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig = panel_figure(fig, (11, 4.5))
    left, right = fig.subplots(1, 2)
    s = ds.attrs.get("engine", "smoothed")  # the suffix of the tested engine's variables
    a_r = ds["amplitudes_reference"].values.ravel()
    a_s = ds[f"amplitudes_{s}"].values.ravel()
    top = np.nanmax(np.concatenate([a_r, a_s, [1.0]])) * 1.05
    left.plot([0, top], [0, top], color="0.7", lw=1)
    left.scatter(a_r, a_s, s=10, alpha=0.6)
    # eps is the smoothed engine's (its attribute); the exact engine has none
    setting = (f"$\\varepsilon$ = {ds.attrs['eps']:g}" if "eps" in ds.attrs
               else f"{s} engine")
    left.set(xlabel="amplitude, non-smooth reference", ylabel=f"amplitude, {s}",
             title=f"(a) all oscillators, {setting}", xlim=(0, top), ylim=(0, top))

    error = 100 * ds["amplitude_error"].values
    periodic = np.array(["periodic" in c for c in ds["state_class_reference"].values])
    families = ds["family"].values
    shown = np.maximum(error, 1e-4)
    x = ds["v_d"].values.astype(float)
    for i, (family, color) in enumerate(zip(sorted(set(families)), ("C0", "C1", "C2"))):
        x = np.where(families == family, ds["v_d"].values + 0.008 * (i - 0.5), x)
        for is_periodic, label in ((True, "periodic"), (False, "irregular")):
            m = (families == family) & (periodic == is_periodic)
            if m.any():
                right.scatter(x[m], shown[m], s=40,
                              facecolors=color if is_periodic else "none",
                              edgecolors=color, label=f"{family}, {label}")
    wrong = ~ds["n_halc_agrees"].values
    if wrong.any():
        right.scatter(x[wrong], shown[wrong], marker="x", s=80, color="red",
                      label=r"$n_\mathrm{HALC}$ disagrees")
    right.axhline(1.0, color="k", lw=1, ls="--", label="1 %")
    right.set(yscale="log", xlabel="belt speed $v_d$",
              ylabel="amplitude error, % of max(1, largest amplitude)",
              title=f"(b) {s} vs non-smooth, per case")
    right.legend(fontsize=8)
    return fig
