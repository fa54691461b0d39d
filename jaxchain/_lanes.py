"""Independent trajectories spread over the devices: as lanes (`jax.vmap` within a
device, `jax.shard_map` across devices), or as separate tasks, one per device at a
time (`on_devices`).

On a CPU, jaxchain exposes one JAX device per core (see `__init__`), because XLA
runs one vmapped integration on one core: two devices run two halves of an
ensemble side by side, about twice as fast on 2 cores. On a GPU there is usually
one device and this is a plain vmap."""

import queue
import threading
from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P
from jaxtyping import ArrayLike, Float
from tqdm.auto import tqdm

from ._options import SimulationOptions
from ._params import ChainParams, with_parameter
from ._simulate import Observables, run


@eqx.filter_jit
def _sharded(params, v_d, y0, solver, options, progress, mesh):
    def local(vd, y):
        def one(a, b):
            return run(with_parameter(params, "v_d", a), b, solver, options, progress)
        return jax.vmap(one)(vd, y)

    # check_vma=False: diffrax's loops carry unsharded initial values (solver state)
    # next to per-device ones, which the varying-axes check rejects.
    return jax.shard_map(local, mesh=mesh, in_specs=P("lanes"), out_specs=P("lanes"),
                         check_vma=False)(v_d, y0)


def lane_order(n_lanes: int, n_devices: int) -> np.ndarray:
    """Permutation that deals lanes to devices like cards: lane i goes to device
    i % n_devices. Neighbouring lanes of a grid (k and k + 1 excited oscillators,
    close belt speeds) cost about the same, so dealing balances the devices better
    than cutting the list in blocks. The lane count is first padded to a multiple of
    n_devices; padding indices are >= n_lanes."""
    total = n_lanes + (-n_lanes % n_devices)
    return np.argsort(np.arange(total) % n_devices, kind="stable")


def run_lanes(params: ChainParams, v_d: Float[ArrayLike, " lanes"],
              y0: Float[ArrayLike, "lanes 2 n_osc"], solver: diffrax.AbstractSolver,
              options: SimulationOptions, progress: bool = False) -> Observables:
    """Run `run` (one trajectory of eq. (5)) for each lane, in parallel over the
    devices of JAX's default backend.

    **Arguments:**

    - `params`: chain parameters; its `v_d` is replaced by each lane's.
    - `v_d`: belt speed of each lane, shape (lanes,), dimensionless.
    - `y0`: initial state of each lane, shape (lanes, 2, n_osc).
    - `solver`, `options`, `progress`: as for `simulate`.

    **Returns:**

    `Observables` whose fields carry a leading (lanes,) axis, in the order given.
    Under vmap a lane that fails keeps its status and does not hold up the others.
    """
    v_d = jnp.asarray(v_d, dtype=float)
    y0 = jnp.asarray(y0, dtype=float)
    n_lanes = v_d.shape[0]
    devices = _devices(n_lanes)
    order = lane_order(n_lanes, len(devices))
    pick = np.minimum(order, n_lanes - 1)  # padding repeats the last lane
    mesh = Mesh(np.array(devices), ("lanes",))
    obs = _sharded(params, v_d[pick], y0[pick], solver, options, progress, mesh)
    back = np.argsort(order)[:n_lanes]
    return jax.tree_util.tree_map(lambda x: x[back], obs)


def padded_lanes(n_lanes: int) -> int:
    """How many lanes `run_lanes` integrates for `n_lanes` (padding included), for
    sizing a progress bar."""
    return len(lane_order(n_lanes, len(_devices(n_lanes))))


def _devices(n_tasks: int) -> list:
    """The devices of JAX's default backend that `n_tasks` tasks or lanes use."""
    return jax.devices()[:max(1, n_tasks)]



def on_devices(task: Callable, n_tasks: int, desc: str, progress: bool = False) -> list:
    """Call `task(i, device)` for i = 0..n_tasks-1, one call at a time per device of
    JAX's default backend, each device taking the next i as soon as it is free (so
    long and short tasks balance). `task` should put its inputs on `device`
    (`jax.device_put`) so that its computation runs there.

    **Returns:**

    The results, in the order of i.

    **Raises:**

    The first exception raised by a task, after the running tasks finish.
    """
    todo: queue.Queue = queue.Queue()
    for i in range(n_tasks):
        todo.put(i)
    results: list = [None] * n_tasks
    errors: list = []
    bar = tqdm(total=n_tasks, desc=desc, disable=not progress, leave=False)
    lock = threading.Lock()

    def worker(device):
        while not errors:
            try:
                i = todo.get_nowait()
            except queue.Empty:
                return
            try:
                results[i] = task(i, device)
            except BaseException as err:  # re-raised in the caller's thread
                errors.append(err)
                return
            with lock:
                bar.update()

    threads = [threading.Thread(target=worker, args=(d,), daemon=True)
               for d in _devices(n_tasks)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    bar.close()
    if errors:
        raise errors[0]
    return results
