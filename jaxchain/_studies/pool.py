"""Independent computations side by side (the snake's branches from different
starts, the localized ranges' groups of draws): they share nothing, so with
`workers` > 1 each runs in a process of its own (spawned, with jaxchain configured
as in its parent and the parent's compilation cache), on its own core; with 1 each
is computed where its result is first asked for, in the order of the sequential
run. Processes, not threads: XLA's CPU client ran two devices' programs of the
localized ranges one after the other when two threads called them."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor


def _configure_worker(cache: str | None, min_compile_time: float) -> None:
    import jax

    import jaxchain

    jaxchain.configure()
    if cache:
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_time)


#: The environment of a worker that computes on one thread (`Followers`): read by
#: OpenBLAS (NumPy's and SciPy's, which JAX's LU on a CPU calls) as it loads.
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


@contextlib.contextmanager
def _environment(values: dict):
    """This process's environment with `values` set, restored afterwards."""
    before = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


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
    """Where the computations run: `submit(fn, *args, **kwargs)` returns an
    object whose `result()` is fn's value, from a pool of `workers` processes, or,
    with `workers` 1, computed then in this process (nothing ahead of time).

    `one_thread`: each worker computes on one thread (XLA's CPU runtime without its
    Eigen thread pool, OpenBLAS's LU on one thread). Where the workers fill the
    cores, their threads otherwise contend: two workers of the localized ranges took
    2.7 times as long per draw as one process on both cores, and 0.73 times with
    one thread each. The flag changes the compiled programs, so a worker's results
    then agree with this process's to their tolerance, not to the last bit."""

    def __init__(self, workers: int, one_thread: bool = False):
        self.pool, self.one_thread = None, one_thread
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
        if not self.one_thread:
            return self.pool.submit(fn, *args, **kwargs)
        # a worker is spawned within a submit, with this process's environment then
        with _environment(ONE_THREAD | {"XLA_FLAGS": " ".join(
                [os.environ.get("XLA_FLAGS", ""), "--xla_cpu_multi_thread_eigen=false"])}):
            return self.pool.submit(fn, *args, **kwargs)

    def __enter__(self) -> Followers:
        return self

    def __exit__(self, *exc) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
