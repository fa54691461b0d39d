"""The Dask route of the batched studies: each batch of a sweep is one task on a
Dask cluster (Dask's distributed scheduler, https://distributed.dask.org), which
integrates its trajectories with the usual engine and writes its own region of the
zarr store. Dask retries the tasks of a lost worker; the store's flags say what is
done, whatever happens to the cluster."""

import concurrent.futures
import contextlib
import importlib
import logging
import os
import queue
import threading
from collections.abc import Callable, Iterator, Sequence

import dask
import jax
import numpy as np
from distributed import Client, LocalCluster, WorkerPlugin, as_completed
from distributed.comm.core import CommClosedError

from .progress import tqdm
from .programs import keep_programs, program_folder
from .._errors import ValidationError
from .._setup import configure

#: The scheduler address that starts a cluster on this machine: "local:N", N
#: worker processes of one thread (and one JAX device) each.
LOCAL = "local:"
#: The modules of the tasks of the batched studies, imported by each worker as it
#: joins (`JaxWorker`): diffrax, xarray and zarr take seconds to import.
STUDY_MODULES = ("jaxchain._sweeps.sweep", "jaxchain._studies.crosscheck")


def local_workers(scheduler: str) -> int | None:
    """N of a "local:N" address, None for the address of a running scheduler.

    **Raises:**

    `ValidationError` (naming `scheduler`) for "local:" followed by anything but an
    integer >= 1, or an empty address.
    """
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise ValidationError(f"scheduler: expected an address or local:N, got {scheduler!r}")
    if not scheduler.startswith(LOCAL):
        return None
    text = scheduler[len(LOCAL):]
    if not text.isdigit() or int(text) < 1:
        raise ValidationError(f"scheduler: local:N needs an integer N >= 1, got {scheduler!r}")
    return int(text)


@contextlib.contextmanager
def connect(scheduler: str, timeout: float = 30.0) -> Iterator:
    """A `distributed.Client` of `scheduler`, closed on exit.

    "local:N" starts a `LocalCluster` of N worker processes on this machine, one
    thread each, without a memory limit (a worker holds JAX and its compiled
    programs; the batch size sets the rest), and closes it on exit. Its processes,
    and those that replace a lost worker, are spawned (Dask's default
    multiprocessing method, set here for the cluster's life), never forked from
    this process, which has started JAX. Any other text is the address of a running
    scheduler, for example "tcp://10.0.0.1:8786", whose workers were started by
    `dask worker`, `dask-jobqueue` or `dask-cuda`.

    The workers are set up for JAX (`JaxWorker`, with `STUDY_MODULES`) in the
    background while the caller plans its tasks.

    **Raises:**

    `ValidationError` for a bad "local:N"; `RuntimeError` (one line) when no scheduler
    answers at the address within `timeout` seconds.
    """
    n = local_workers(scheduler)
    with contextlib.ExitStack() as stack:
        if n is not None:
            stack.enter_context(dask.config.set(
                {"distributed.worker.multiprocessing-method": "spawn",
                 # Dask's sampling profiler of each worker's threads: a stack
                 # every 10 ms, CPU the integrations need on a small machine
                 "distributed.worker.profile.enabled": False,
                 # a task to a worker only when one of its threads is free: no
                 # task waits behind a long batch until it is stolen
                 "distributed.scheduler.worker-saturation": 1.0}))
            cluster = stack.enter_context(LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, memory_limit=0,
                dashboard_address=None, silence_logs=logging.CRITICAL))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout=timeout))
            except (OSError, TimeoutError) as err:
                raise RuntimeError(f"no Dask scheduler answers at {scheduler} "
                                   f"({type(err).__name__})") from None
        plugin = JaxWorker.of_this_process(client, STUDY_MODULES)
        setup = threading.Thread(target=_register_quietly, args=(client, plugin),
                                 daemon=True)
        setup.start()
        stack.callback(setup.join)  # before the client closes
        yield client


def _register_quietly(client, plugin) -> None:
    """Register `plugin` with the workers of `client`; a failure here shows again
    when `run_tasks` registers it."""
    with contextlib.suppress(Exception):
        client.register_plugin(plugin)


class JaxWorker(WorkerPlugin):
    """Sets up JAX in each worker before its first task: float64 and the XLA flags
    of `import jaxchain`, one JAX CPU device per thread the worker is given (`dask
    worker --nthreads`), the client's compilation cache and traced programs,
    shared through their folder (`JaxWorker.of_this_process`), then imports the
    `modules` of the tasks. On a `LocalCluster` (`pin`), each worker is first
    pinned to as many cores of its own as it has threads."""

    name = "jaxchain-jax"

    def __init__(self, cache: str | None, min_compile_s: float, traced: str | None,
                 modules: tuple[str, ...] = (), pin: bool = False):
        self.cache, self.min_compile_s, self.traced = cache, min_compile_s, traced
        self.modules, self.pin = modules, pin

    @classmethod
    def of_this_process(cls, client, modules: tuple[str, ...] = ()) -> "JaxWorker":
        """The plugin that gives the workers of `client` this process's
        compilation cache (JAX's `jax_compilation_cache_dir`, from
        JAX_COMPILATION_CACHE_DIR or the command line's `compilation_cache`) and
        kept traced programs, as absolute paths, imports `modules`, and on a
        `LocalCluster` pins each worker to cores of its own (`_pin_to_own_cores`)."""
        cache, folder = jax.config.jax_compilation_cache_dir, program_folder()
        return cls(os.path.abspath(cache) if cache else None,
                   jax.config.jax_persistent_cache_min_compile_time_secs,
                   None if folder is None else os.path.abspath(folder), modules,
                   isinstance(getattr(client, "cluster", None), LocalCluster))

    def setup(self, worker):
        if self.pin and isinstance(worker.name, int) and not _worker_devices:
            _pin_to_own_cores(worker.name, max(1, worker.state.nthreads))
        # float64, the XLA flags and one device per thread (once backends run, only
        # float64 changes)
        configure(devices=max(1, worker.state.nthreads))
        if self.cache:
            jax.config.update("jax_compilation_cache_dir", self.cache)
            jax.config.update("jax_persistent_cache_min_compile_time_secs",
                              self.min_compile_s)
        keep_programs(self.traced)
        if not _worker_devices:  # once per worker: a plugin registered again keeps them
            _worker_devices.extend(jax.local_devices())
            for device in _worker_devices:
                _free_devices.put(device)
        for module in self.modules:
            importlib.import_module(module)


def _pin_to_own_cores(index: int, n_threads: int) -> None:
    """Pin this worker process, worker `index` of a cluster on one machine, to
    `n_threads` cores of its own (taken in turn from the cores this process may
    use), before JAX starts. XLA sizes its CPU thread pool by the cores a process
    may use: unpinned, each of N workers keeps a pool as large as the machine, and
    their threads contend for the cores (about 10-15 % of the wall time of a sweep
    on 2 workers and 2 cores)."""
    if not hasattr(os, "sched_setaffinity"):  # Linux only
        return
    cores = sorted(os.sched_getaffinity(0))
    own = {cores[(index * n_threads + j) % len(cores)] for j in range(n_threads)}
    for thread in os.listdir("/proc/self/task"):  # every thread, the later ones inherit
        with contextlib.suppress(OSError):
            os.sched_setaffinity(int(thread), own)


#: The devices of this worker not in use by one of its tasks (`JaxWorker.setup`):
#: a worker of k threads runs up to k tasks at once, each on a device of its own.
_free_devices: queue.Queue = queue.Queue()
_worker_devices: list = []


def _on_a_free_device(task: Callable, *args):
    """`task(*args, devices=[device])` on a device of this worker that no other of
    its tasks is using, waiting for one if all are busy: the body of each task of
    `run_tasks`."""
    device = _free_devices.get()
    try:
        return task(*args, devices=[device])
    finally:
        _free_devices.put(device)


def run_tasks(client, task: Callable, shared, arguments: Sequence[tuple],
              names: Sequence[str], bar: tqdm, costs: Sequence[float] | None = None
              ) -> None:
    """Run `task(shared, *arguments[i], devices=[device])` for every i on the
    cluster of `client`, each on a device of its worker that none of its other
    tasks is using (`_on_a_free_device`), as a task named `names[i]` (unique: the
    scheduler hands back the result of a key it holds without running the task
    again). `shared` (the plan of the whole run) is sent to every worker once, not
    with every task. `bar` advances by one as each task finishes, whichever worker
    ran it. The results stay on the workers: the tasks write them to a store. With
    `costs`, the costliest tasks go first (longest processing time first), so that
    the short ones fill the workers' last gaps.

    A worker that dies takes its running tasks with it, and the scheduler runs them
    again on another worker (up to Dask's `distributed.scheduler.allowed-failures`
    times, then the task fails with `KilledWorker`).

    **Raises:**

    The first exception of a task, as the task raised it (the others are
    cancelled); `RuntimeError` (one line) when the scheduler goes away.
    """
    rank = np.argsort(np.argsort(-np.asarray(costs if costs is not None
                                             else np.zeros(len(arguments)))))
    client.register_plugin(JaxWorker.of_this_process(client, (task.__module__,)))
    plan = client.scatter(shared, broadcast=True, hash=False)
    futures = [client.submit(_on_a_free_device, task, plan, *args, key=name,
                             priority=-int(r))
               for args, name, r in zip(arguments, names, rank)]
    try:
        for future in as_completed(futures):
            if future.status == "error":
                raise future.exception()
            future.result()
            bar.update(1)
    except (concurrent.futures.CancelledError, OSError) as err:
        if client.status == "running" and not isinstance(err, CommClosedError):
            raise
        raise RuntimeError(f"the Dask scheduler went away ({type(err).__name__}); the "
                           "finished batches are flagged in the store, and --resume "
                           "(resume=True) runs the others") from None
    finally:
        client.cancel([f for f in futures if not f.done()])
