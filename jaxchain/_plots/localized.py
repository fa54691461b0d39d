"""Fig. 4 of the paper: localized states as rows of circles."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._engine.status import Status
from .canvas import single_axes

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def plot_localized_states(ds: xr.Dataset, v_d: float | None = None, ax=None):
    """Draw the localized states at one belt speed in the manner of Fig. 4 of the
    paper: one row per solution, one circle per oscillator, radius proportional to
    its amplitude. Rows are labelled with the number of excited oscillators (left)
    and with n_HALC and E (right); failed runs are marked. A 2-D lattice (its
    Dataset's `lattice` attribute, rows x cols) is drawn on its grid instead: one
    tile per solution, a circle at each site (row r from the top, column c).

    **Arguments:**

    - `ds`: a Dataset from `to_dataset`, dims (v_d, ic, osc).
    - `v_d`: which belt speed to draw (nearest); the first one if None.
    - `ax`: a matplotlib Axes; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle

    row = ds.isel(v_d=0) if v_d is None else ds.sel(v_d=v_d, method="nearest")
    amps = np.nan_to_num(np.asarray(row["amplitudes"]), nan=0.0)
    n_ic, n_osc = amps.shape
    if "lattice" in ds.attrs:
        return _plot_on_grid(row, amps, tuple(int(v) for v in ds.attrs["lattice"]), ax)
    fig, ax = single_axes(ax, (0.45 * n_osc + 2.5, 0.4 * n_ic + 1.2))
    scale = 0.45 / max(float(amps.max()), 1e-12)
    labels = (np.asarray(row["n_excited"]) if "n_excited" in row.coords
              else np.arange(1, n_ic + 1))
    circles = [Circle((j + 1, -i), max(scale * a, 0.02))
               for i in range(n_ic) for j, a in enumerate(amps[i])]
    ax.add_collection(PatchCollection(circles, facecolor="tab:blue", edgecolor="k",
                                      linewidth=0.4, alpha=0.8))
    for i in range(n_ic):
        ax.text(n_osc + 0.8, -i, _notes(row, i), va="center", fontsize=7)
    ax.set_xlim(0.3, n_osc + 4.5)
    ax.set_ylim(-n_ic + 0.4, 0.6)
    ax.set_aspect("equal")
    ax.set_xticks(np.arange(1, n_osc + 1))
    ax.set_yticks(-np.arange(n_ic), [str(k) for k in labels])
    ax.set_xlabel("oscillator n")
    ax.set_ylabel("oscillators excited")
    ax.set_title(f"Localized states, $v_d$ = {float(row['v_d']):g} "
                 f"(radius ∝ amplitude; cf. Fig. 4)", fontsize=9)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    return fig


def _notes(row, i: int) -> str:
    status = int(row["status"][i])
    return (f"{int(row['n_halc'][i])} on HALC, E={float(row['energy'][i]):.1f}"
            if status == Status.ok else str(Status(status)))


def _plot_on_grid(row, amps: np.ndarray, shape: tuple[int, int], ax):
    """The localized states of a rows x cols lattice, a tile per solution, five
    tiles to a line, each titled with its excited sites, n_HALC and E."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle, Rectangle

    rows, cols = shape
    n_ic = amps.shape[0]
    per_line = min(5, n_ic)
    lines = -(-n_ic // per_line)
    width, height = cols + 1.0, rows + 1.6
    fig, ax = single_axes(ax, (0.42 * per_line * width + 0.6, 0.42 * lines * height + 0.8))
    scale = 0.45 / max(float(amps.max()), 1e-12)
    labels = (np.asarray(row["n_excited"]) if "n_excited" in row.coords
              else np.arange(1, n_ic + 1))
    circles, frames = [], []
    for i in range(n_ic):
        x0, y0 = (i % per_line) * width, -(i // per_line) * height
        frames.append(Rectangle((x0 - 0.55, y0 - rows + 0.45), cols + 0.1, rows + 0.1))
        for site, a in enumerate(amps[i]):
            r, c = divmod(site, cols)
            circles.append(Circle((x0 + c, y0 - r), max(scale * a, 0.02)))
        ax.text(x0 + (cols - 1) / 2, y0 + 0.75, f"{labels[i]} excited: {_notes(row, i)}",
                ha="center", va="bottom", fontsize=6)
    ax.add_collection(PatchCollection(frames, facecolor="none", edgecolor="0.8",
                                      linewidth=0.5))
    ax.add_collection(PatchCollection(circles, facecolor="tab:blue", edgecolor="k",
                                      linewidth=0.4, alpha=0.8))
    ax.set_xlim(-0.8, per_line * width - 0.7)
    ax.set_ylim(-(lines - 1) * height - rows + 0.2, 1.6)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"Localized states on the {rows} x {cols} lattice, $v_d$ = "
                 f"{float(row['v_d']):g} (radius ∝ amplitude; cf. Fig. 4)", fontsize=9)
    return fig
