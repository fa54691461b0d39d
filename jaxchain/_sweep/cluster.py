"""The Dask route of the batched studies: each batch of a sweep is one task on a
Dask cluster (Dask's distributed scheduler, https://distributed.dask.org), which
integrates its trajectories with the usual engine and writes its own region of the
zarr store. Dask retries the tasks of a lost worker; the store's flags say what is
done, whatever happens to the cluster."""

import concurrent.futures
import contextlib
from collections.abc import Callable, Iterator, Sequence

import dask
import jax
from distributed import Client, LocalCluster, WorkerPlugin, as_completed
from distributed.comm.core import CommClosedError
from tqdm.auto import tqdm

from .._programs import keep_programs, program_folder

#: The scheduler address that starts a cluster on this machine: "local:N", N
#: worker processes of one thread (and one JAX device) each.
LOCAL = "local:"


def local_workers(scheduler: str) -> int | None:
    """N of a "local:N" address, None for the address of a running scheduler.

    **Raises:**

    `ValueError` (naming `scheduler`) for "local:" followed by anything but an
    integer >= 1, or an empty address.
    """
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise ValueError(f"scheduler: expected an address or local:N, got {scheduler!r}")
    if not scheduler.startswith(LOCAL):
        return None
    text = scheduler[len(LOCAL):]
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"scheduler: local:N needs an integer N >= 1, got {scheduler!r}")
    return int(text)


@contextlib.contextmanager
def connect(scheduler: str, timeout: float = 30.0) -> Iterator:
    """A `distributed.Client` of `scheduler`, closed on exit.

    "local:N" starts a `LocalCluster` of N worker processes on this machine, one
    thread each, and closes it on exit. Its processes are spawned (Dask's default
    multiprocessing method, set here explicitly), never forked from this process,
    which has started JAX. Any other text is the address of a running scheduler,
    for example "tcp://10.0.0.1:8786", whose workers were started by `dask worker`,
    `dask-jobqueue` or `dask-cuda`.

    **Raises:**

    `ValueError` for a bad "local:N"; `RuntimeError` (one line) when no scheduler
    answers at the address within `timeout` seconds.
    """
    n = local_workers(scheduler)
    with contextlib.ExitStack() as stack:
        if n is not None:
            with dask.config.set({"distributed.worker.multiprocessing-method": "spawn"}):
                cluster = stack.enter_context(LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True,
                    dashboard_address=None, silence_logs=40))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout=timeout))
            except (OSError, TimeoutError) as err:
                raise RuntimeError(f"no Dask scheduler answers at {scheduler} "
                                   f"({type(err).__name__})") from None
        yield client


class JaxWorker(WorkerPlugin):
    """Sets up JAX in each worker before its first task: float64 and the XLA flags
    of `import jaxchain`, one JAX CPU device per thread the worker is given (`dask
    worker --nthreads`), and the client's compilation cache and traced programs,
    shared through their folder (`JaxWorker.of_this_process`)."""

    name = "jaxchain-jax"

    def __init__(self, cache: str | None, traced: str | None):
        self.cache, self.traced = cache, traced

    @classmethod
    def of_this_process(cls) -> "JaxWorker":
        """The plugin that gives workers this process's cache folders."""
        folder = program_folder()
        return cls(jax.config.jax_compilation_cache_dir or None,
                   None if folder is None else str(folder))

    def setup(self, worker):
        import jaxchain  # noqa: F401  (float64, XLA flags)

        with contextlib.suppress(RuntimeError):  # backends already started
            jax.config.update("jax_num_cpu_devices", max(1, worker.state.nthreads))
        if self.cache:
            jax.config.update("jax_compilation_cache_dir", self.cache)
        keep_programs(self.traced)


def run_tasks(client, task: Callable, arguments: Sequence[tuple], names: Sequence[str],
              bar: tqdm, sizes: Sequence[int] | None = None) -> None:
    """Run `task(*arguments[i])` for every i on the cluster of `client`, each a
    task named `names[i]`, and advance `bar` by `sizes[i]` (1 by default) as each
    finishes, whichever worker ran it. The results stay on the workers: the tasks
    write them to a store.

    A worker that dies takes its running tasks with it, and the scheduler runs them
    again on another worker (up to Dask's `distributed.scheduler.allowed-failures`
    times, then the task fails with `KilledWorker`).

    **Raises:**

    The first exception of a task (the others are cancelled); `RuntimeError` (one
    line) when the scheduler goes away.
    """
    sizes = list(sizes) if sizes is not None else [1] * len(arguments)
    client.register_plugin(JaxWorker.of_this_process())
    futures = [client.submit(task, *args, key=name, pure=False)
               for args, name in zip(arguments, names)]
    size = dict(zip((f.key for f in futures), sizes))
    try:
        for future in as_completed(futures):
            future.result()
            bar.update(size[future.key])
    except (concurrent.futures.CancelledError, CommClosedError, OSError,
            TimeoutError) as err:
        if client.status == "running" and not isinstance(err, (CommClosedError, OSError)):
            raise
        raise RuntimeError(f"the Dask scheduler went away ({type(err).__name__}); the "
                           "finished batches are flagged in the store, and --resume "
                           "(resume=True) runs the others") from None
    finally:
        client.cancel([f for f in futures if not f.done()])
