"""A tqdm progress bar fed from inside compiled code, one tick per integrated chunk.

Runs compiled with `progress=True` call `tick` (a host callback) after each chunk.
Such programs are compiled apart from those without a bar, and JAX's persistent
compilation cache does not keep them."""

import contextlib

import jax
from tqdm.auto import tqdm

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
