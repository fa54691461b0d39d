"""The progress bars of jaxchain, and one fed from inside compiled code, one tick per
integrated chunk.

Every bar is tqdm's text bar (`tqdm.std`) on stderr, in a terminal and in a Jupyter
notebook alike, where Jupyter redraws it in place. `tqdm.auto` would pick the
notebook's widget bar instead, which needs ipywidgets and, without them, prints a
TqdmWarning that names the path of the installed tqdm; the functions of jaxchain
make their bars with the `tqdm` of this module.

Runs compiled with `progress=True` call `tick` (a host callback) after each chunk.
Such programs are compiled apart from those without a bar, and JAX's persistent
compilation cache does not keep them."""

import contextlib

import jax
from tqdm.std import tqdm as tqdm  # the text bar, for every bar of jaxchain

_bar: list = [None]


def _update(n):
    if _bar[0] is not None:
        _bar[0].update(int(n.size) if n.ndim else 1)


def tick(lane):
    """Advance the active bar by one chunk per lane. Call inside jitted code; `lane`
    is any array that carries the batch axes (so that a vmapped call counts each
    trajectory)."""
    jax.debug.callback(_update, lane)


@contextlib.contextmanager
def progress_bar(total: int, desc: str, enabled: bool):
    """Make a tqdm bar of `total` ticks the target of `tick` for the duration."""
    bar = tqdm(total=total, desc=desc, unit="chunk", disable=not enabled, leave=False)
    _bar[0] = bar
    try:
        yield bar
    finally:
        _bar[0] = None
        bar.close()
