"""Where a figure draws: on the caller's Axes (one-panel figures, `ax=`) or Figure
(several panels, `fig=`, a `Figure` or a `SubFigure`), as matplotlib users expect,
or on a new figure of the function's own size."""


def single_axes(ax, figsize: tuple[float, float]):
    """(figure, axes) to draw one panel on: `ax` and its figure, or a new figure
    with one Axes (constrained layout) when `ax` is None."""
    import matplotlib.pyplot as plt

    if ax is not None:
        return ax.figure, ax
    return plt.subplots(figsize=figsize, layout="constrained")


def panel_figure(fig, figsize: tuple[float, float]):
    """The figure to draw several panels on: `fig` (a Figure or SubFigure), or a
    new Figure (constrained layout) when it is None."""
    import matplotlib.pyplot as plt

    if fig is not None:
        return fig
    return plt.figure(figsize=figsize, layout="constrained")
