"""The figures draw where the caller asks, as matplotlib users expect: a one-panel
figure on `ax=`, a figure of several panels on `fig=` (a Figure or a SubFigure),
each on a new figure otherwise."""

import inspect

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402

import jaxchain as jc  # noqa: E402

PLOTS = sorted(name for name in jc.__all__ if name.startswith("plot_"))


@pytest.mark.parametrize("name", PLOTS)
def test_every_plot_function_takes_ax_or_fig(name):
    parameters = inspect.signature(getattr(jc, name)).parameters
    assert ("ax" in parameters) != ("fig" in parameters), parameters
    where = parameters.get("ax") or parameters.get("fig")
    assert where.default is None
    assert "`ax`" in getattr(jc, name).__doc__ or "`fig`" in getattr(jc, name).__doc__


def _states(n_ic=3, n_osc=4):
    """A Dataset of localized states, as `ensemble` gives it: k excited, k on the
    HALC."""
    amplitudes = np.tril(np.ones((n_ic, n_osc)))[None]
    return xr.Dataset(
        {"amplitudes": (("v_d", "ic", "osc"), amplitudes),
         "n_halc": (("v_d", "ic"), amplitudes.sum(-1).astype(int)),
         "energy": (("v_d", "ic"), 0.5 * (amplitudes**2).sum(-1)),
         "status": (("v_d", "ic"), np.zeros((1, n_ic), dtype=int))},
        coords={"v_d": [1.5], "n_excited": ("ic", np.arange(1, n_ic + 1))})


def test_a_one_panel_figure_draws_on_the_given_axes():
    fig, (left, right) = plt.subplots(1, 2)
    assert jc.plot_localized_states(_states(), ax=right) is fig
    assert len(right.collections) == 1 and not left.collections  # the circles, there
    assert "$v_d$" in right.get_title()  # mathtext
    plt.close(fig)
    own = jc.plot_localized_states(_states())
    assert own is not fig and len(own.axes) == 1
    plt.close(own)


def test_a_figure_of_panels_draws_on_the_given_subfigure():
    fig = plt.figure(layout="constrained")
    left, right = fig.subfigures(1, 2)
    rows = [{"scene": "single", "method": "tsit5", "eps": str(e), "rtol": str(r),
             "status": "ok", "wall_s": str(w), "amplitude_error": str(a)}
            for e in (1e-2, 1e-3) for r, w, a in ((1e-4, 0.1, 1e-2), (1e-6, 0.3, 1e-4))]
    assert jc.plot_work_precision(rows, "single", fig=right) is right
    assert len(right.axes) == 2 and not left.axes
    assert len(right.legends) == 1  # one legend for the panels, below them
    plt.close(fig)
