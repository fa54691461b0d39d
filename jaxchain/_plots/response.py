"""The frequency-response curve of a forced chain."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .bifurcation import _segments
from .canvas import single_axes

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def plot_frequency_response(ds: xr.Dataset, ax=None):
    """The largest amplitude over the chain against the forcing frequency Omega
    (`frequency_response`'s Dataset): stable orbits solid, unstable dashed, the
    folds marked.

    **Arguments:**

    - `ds`: the Dataset of `frequency_response`.
    - `ax`: a matplotlib Axes to draw on; a new figure if None.

    **Returns:**

    The matplotlib Figure.
    """
    fig, ax = single_axes(ax, (7, 4.5))
    omega = np.asarray(ds["frequency"])
    amplitude = np.asarray(ds["max_amplitude"])
    labelled = set()
    for x, y, s in _segments(omega, amplitude, np.asarray(ds["stable"])):
        label = "stable" if s else "unstable"
        ax.plot(x, y, "-" if s else "--", color="C0" if s else "C3", lw=1.5,
                label=None if label in labelled else label)
        labelled.add(label)
    for i, f in enumerate(ds.attrs.get("fold_frequencies", [])):
        j = int(np.argmin(np.abs(omega - f)))
        ax.plot([f], [amplitude[j]], "s", color="C2", ms=7,
                label="fold" if i == 0 else None)
    ax.set(xlabel=r"forcing frequency $\Omega$", ylabel=r"largest amplitude $\max_n A_n$",
           title=f"frequency response ({ds.attrs.get('method', '')}, N = {ds.sizes['osc']})")
    ax.legend(fontsize=8)
    return fig
