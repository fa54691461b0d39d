"""Independent computations side by side (the snake's branches from different
starts, the localized ranges' groups of draws): they share nothing, so with
`workers` > 1 each runs in a process of its own (spawned, with jaxchain configured
as in its parent and the parent's compilation cache), on its own core; with 1 each
is computed where its result is first asked for, in the order of the sequential
run. Processes, not threads: XLA's CPU client ran two devices' programs of the
localized ranges one after the other when two threads called them."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor


def _configure_worker(cache: str | None, min_compile_time: float) -> None:
    import jax

    import jaxchain

    jaxchain.configure()
    if cache:
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_time)


class _Later:
    """`fn(*args, **kwargs)`, computed at the first `result()`."""

    def __init__(self, fn, args, kwargs):
        self._call, self._done, self._value = (fn, args, kwargs), False, None

    def result(self):
        if not self._done:
            fn, args, kwargs = self._call
            self._value, self._done = fn(*args, **kwargs), True
        return self._value


class Followers:
    """Where the branches are followed: `submit(fn, *args, **kwargs)` returns an
    object whose `result()` is fn's value, from a pool of `workers` processes, or,
    with `workers` 1, computed then in this process (nothing ahead of time)."""

    def __init__(self, workers: int):
        self.pool = None
        if workers > 1:
            import jax

            self.pool = ProcessPoolExecutor(
                workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=_configure_worker,
                initargs=(jax.config.jax_compilation_cache_dir,
                          jax.config.jax_persistent_cache_min_compile_time_secs))

    def submit(self, fn, *args, **kwargs):
        if self.pool is None:
            return _Later(fn, args, kwargs)
        return self.pool.submit(fn, *args, **kwargs)

    def __enter__(self) -> Followers:
        return self

    def __exit__(self, *exc) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
