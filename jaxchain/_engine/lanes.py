"""Independent trajectories spread over the devices (`run_lanes`): as a work queue
of separate tasks, one per device at a time (`on_devices`), or as vmapped lanes
(`jax.vmap` within a device, `jax.shard_map` across devices).

On a CPU, `jaxchain.configure()` exposes one JAX device per core: XLA runs one
compiled integration on one core, so two devices run twice the trajectories in the
same time on 2 cores. The queue suits CPUs: a vmapped lane that finishes early
waits, masked, for the slowest lane of its batch (44 % of the lane-steps of the
Fig. 4 scene), and a vmapped loop is too large for XLA to compile into one kernel.
On a GPU, with one device running thousands of lanes, vmap is the engine."""

import contextlib
import queue
import threading
from collections.abc import Callable, Sequence

import diffrax
import equinox as eqx
import jax
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P
from jaxtyping import ArrayLike, Float

from .progress import tqdm
from .programs import compiled, kept_program
from .._physics.initial import AbstractInitialCondition, initial_states
from .._physics.model import steady_sliding
from .._physics.params import ChainParams, parameter_lens, with_parameter
from .observers.base import AbstractObserver
from .engines import AbstractEngine, as_engine
from .horizon import AbstractHorizon
from .observables import Observables, check_observers
from .._errors import ValidationError


#: How `run_lanes` schedules its lanes: "queue" (each device integrates one block of
#: trajectories at a time, taking the next block when it finishes; the default on
#: CPUs) or "vmap" (all lanes of a batch in lockstep, one vmapped program per
#: device; the default on GPUs).
SCHEDULES = ("queue", "vmap")


def _one(params, y0, engine: AbstractEngine, observers):
    """One lane: the engine's `Observables`, or what `observers` saw."""
    if observers is None:
        return engine.run(params, y0)
    return engine.run_observers(params, y0, observers)


@eqx.filter_jit
def _run_block(params, y0, engine, observers=None):
    """A block of trajectories, one after the other (`lax.map`): no lane waits for
    another, and the step loop stays one small while loop, which XLA's CPU backend
    compiles into one kernel (see `_setup.XLA_FLAGS`)."""
    return jax.lax.map(lambda a: _one(a[0], a[1], engine, observers), (params, y0))


@eqx.filter_jit
def _run_vmapped(params, y0, engine, mesh, observers=None):
    def local(p, y):
        return jax.vmap(lambda a, b: _one(a, b, engine, observers))(p, y)

    # check_vma=False: diffrax's loops carry unsharded initial values (solver state)
    # next to per-device ones, which the varying-axes check rejects.
    return jax.shard_map(local, mesh=mesh, in_specs=P("lanes"), out_specs=P("lanes"),
                         check_vma=False)(params, y0)


def lane_params(params: ChainParams, n_lanes: int, **per_lane) -> ChainParams:
    """The parameters of each lane, as `run_lanes` takes them: every array field of
    the one chain `params` gains a leading lane axis (shape (n_lanes, ...), its own
    shape after it, so that a per-oscillator array stays per oscillator), and the
    parameters named in `per_lane` take one value per lane.

    This is the one route from a chain to lanes; a batch of different chains (for
    example mistuning draws) is made by `stack_chains`. A field of `params` is
    never read as one value per lane because its length happens to be n_lanes.

    **Arguments:**

    - `params`: one chain (v_d and eps scalars).
    - `n_lanes`: the number of lanes.
    - `per_lane`: parameter name (as `with_parameter` takes it) -> values of shape
        (n_lanes,), for example `v_d=np.repeat(v_d, n_ic)`.

    **Raises:**

    `ValidationError` when `params` is already a batch, for an unknown name, or for
    values that are not of shape (n_lanes,) or invalid for the parameter.
    """
    if np.ndim(params.v_d) != 0:
        raise ValidationError("lane_params takes one chain (v_d a scalar); give per-lane values "
                              "by name, for example lane_params(params, n, v_d=values)")
    for name, values in per_lane.items():
        values = np.asarray(values, dtype=float)
        if values.shape != (n_lanes,):
            raise ValidationError(f"{name}: one value per lane, shape ({n_lanes},), got "
                                  f"{values.shape}")
        for value in np.unique(values):  # validated, naming the field
            with_parameter(params, name, value)
    lanes = jax.tree_util.tree_map(
        lambda x: np.broadcast_to(np.asarray(x, dtype=float), (n_lanes,) + np.shape(x)), params)
    for name, values in per_lane.items():
        lanes = eqx.tree_at(parameter_lens(name, params), lanes,
                            np.asarray(values, dtype=float))
    return lanes


def _as_lanes(params: ChainParams, n_lanes: int) -> ChainParams:
    """`params` as lanes: a batch (from `lane_params` or `stack_chains`, v_d of shape
    (n_lanes,)) as it is, one chain broadcast by `lane_params`.

    **Raises:**

    `ValidationError` when a batch's fields do not lead with n_lanes.
    """
    if np.ndim(params.v_d) == 0:
        return lane_params(params, n_lanes)
    leading = {np.shape(x)[:1] for x in jax.tree_util.tree_leaves(params)}
    if leading != {(n_lanes,)}:
        raise ValidationError(f"lane parameters must lead with the lane axis ({n_lanes},) in "
                              f"every field (lane_params, stack_chains), got leading shapes "
                              f"{sorted(leading)}")
    return params


def take_lanes(tree, index):
    """The lanes `index` of every array leaf of `tree` (other leaves as they are)."""
    return jax.tree_util.tree_map(lambda x: x[index] if eqx.is_array(x) else x, tree)


def _lane_order(n_lanes: int, n_devices: int) -> np.ndarray:
    """Permutation that deals lanes to devices like cards: lane i goes to device
    i % n_devices. Neighbouring lanes of a grid (k and k + 1 excited oscillators,
    close belt speeds) cost about the same, so dealing balances the devices better
    than cutting the list in blocks. The lane count is first padded to a multiple of
    n_devices; padding indices are >= n_lanes."""
    total = n_lanes + (-n_lanes % n_devices)
    return np.argsort(np.arange(total) % n_devices, kind="stable")


def block_size(n_lanes: int, n_devices: int) -> int:
    """Trajectories per task of the queue engine: 1 up to 16 tasks per device, then
    larger blocks so that there are about 16 per device (balance within 1/16 of the
    work of one device, and few dispatches for large ensembles)."""
    return max(1, n_lanes // (16 * n_devices))


def expected_cost(params: ChainParams, y0: Float[ArrayLike, "lanes 2 n_osc"]
                  ) -> Float[np.ndarray, " lanes"]:
    """A proxy of each lane's cost, for ordering the lanes of either engine: the
    distance of its initial state from steady sliding at its belt speed. Lanes that
    start far from it (more oscillators excited) stick and slip more, and take more
    steps. `params` holds each lane's parameters (`lane_params`)."""
    return distance_from(np.asarray(compiled(_lanes_steady_sliding, params)), y0)


def distance_from(steady: Float[ArrayLike, "lanes 2 n_osc"],
                  y0: Float[ArrayLike, "lanes 2 n_osc"]) -> Float[np.ndarray, " lanes"]:
    """`expected_cost` from each lane's steady sliding `steady` and initial state
    `y0`: the Euclidean distance between them (displacements and velocities)."""
    x0, y0 = np.asarray(steady)[:, 0], np.asarray(y0)
    return np.sqrt(np.sum((y0[:, 0] - x0) ** 2 + y0[:, 1] ** 2, -1))


def _lanes_steady_sliding(params: ChainParams) -> Float[jax.Array, "lanes 2 n_osc"]:
    """Steady sliding (`steady_sliding`) of each lane of `params` (`lane_params`)."""
    return eqx.filter_vmap(steady_sliding)(params)


def lane_starts(params: ChainParams, ics: AbstractInitialCondition
                ) -> tuple[Float[jax.Array, "lanes 2 n_osc"], Float[jax.Array, "lanes 2 n_osc"]]:
    """The initial state (`initial_states`) and the steady sliding of each lane, in
    one program (`compiled`): what an ensemble needs before its run, y0 and the
    lanes' `expected_cost` (`distance_from`)."""
    return initial_states(params, ics), _lanes_steady_sliding(params)


def run_lanes(params: ChainParams, y0: Float[ArrayLike, "lanes 2 n_osc"],
              solver: diffrax.AbstractSolver | str | None = None,
              options: AbstractHorizon | None = None, *,
              engine: AbstractEngine | str = "smoothed", schedule: str | None = None,
              devices: Sequence | None = None,
              batch_size: int = 4096, block: int | None = None,
              progress: bool | tqdm = False,
              observers: Sequence[AbstractObserver] | None = None,
              costs: Float[ArrayLike, " lanes"] | None = None
              ) -> Observables | dict:
    """Run one trajectory of eq. (5) for each lane, in parallel over the devices,
    with either engine (`simulate`): its `Observables`, or what the given observers
    saw.

    **Arguments:**

    - `params`: one chain (shared by every lane), or the lanes' chains with a
        leading (lanes,) axis on every field, from `lane_params` (for example
        `lane_params(params, n, v_d=v_d)` for one belt speed per lane) or
        `stack_chains` (one chain per lane).
    - `y0`: initial state of each lane, shape (lanes, 2, n_osc).
    - `solver`, `options`, `engine`: as for `simulate` (`as_engine`); the engine is
        dispatched once, here, and every lane runs it.
    - `schedule`: "queue" or "vmap" (`SCHEDULES`); by default "queue" on a CPU and
        "vmap" on other platforms. The queue keeps no lane waiting: each device
        integrates a block of trajectories one after the other (`block_size`) and
        takes the next block when done, the costliest first (`expected_cost`).
        The vmap schedule integrates the lanes of a batch in lockstep (each waits
        for the slowest), in batches of `batch_size` lanes ordered by
        `expected_cost`, dealt to the devices.
    - `devices`: the devices to use, by default all of this process's devices of
        JAX's default backend (`jax.local_devices()`).
    - `block`: trajectories per task of the queue engine, `block_size` by default.
        Calls with the same block compile the same program.
    - `progress`: a tqdm bar over trajectories, or a tqdm bar to advance (by the
        trajectories of each finished task, or of each vmapped batch).
    - `observers`: what to observe (`run_observers`); None for the `Observables` of `run`.
    - `costs`: each lane's expected cost, shape (lanes,), `expected_cost` by
        default; only the order of the lanes depends on it, not their results.

    **Returns:**

    `Observables` (or the dict of `run_observers`) whose fields carry a leading (lanes,)
    axis, in the order given.
    The device count changes nothing in the queue's result: each lane is the same
    compiled integration, whichever device takes it, for the same `block`. The
    vmap engine, another block or batch size, and `simulate` are other compiled
    programs, whose rounding moves the adaptive steps: they agree to the
    integration tolerance, not to the last bit.

    **Raises:**

    `ValidationError` for an unknown engine or schedule, an empty list of lanes, or lane parameters
    that do not lead with (lanes,); see also `check_observers`.
    """
    engine = as_engine(engine, solver, options)
    if observers is not None:
        observers = check_observers(observers)
    y0 = np.asarray(y0, dtype=float)
    n_lanes = y0.shape[0]
    if n_lanes == 0:
        raise ValidationError("run_lanes needs at least one lane, got 0")
    params = _as_lanes(params, n_lanes)
    devices = list(devices or jax.local_devices())[:n_lanes]
    if schedule is None:
        schedule = "queue" if devices[0].platform == "cpu" else "vmap"
    if schedule not in SCHEDULES:
        raise ValidationError(f"schedule must be one of {SCHEDULES}, got {schedule!r}")
    if schedule == "queue":
        return _run_queue(params, y0, engine, observers, devices, block, progress,
                          _costs(params, y0, costs))
    return _run_vmap(params, y0, engine, observers, devices, batch_size, progress,
                     _costs(params, y0, costs))


def _run_queue(params, y0, engine, observers, devices, block, progress, costs):
    """The queue schedule of `run_lanes`: blocks of lanes, the costliest first, each
    taken by the next free device."""
    n_lanes = y0.shape[0]
    size = block or block_size(n_lanes, len(devices))
    starts = range(0, n_lanes, size)
    # The costliest lanes first (longest processing time first): the short ones
    # at the end then fill the gaps, and no device is left with a long tail.
    by_cost = np.argsort(-costs, kind="stable")

    # Trace once, here: the device threads then find the program traced and only
    # compile it for their device (or load it from the cache), rather than
    # tracing it side by side under the GIL. Where traced programs are kept (the
    # command line), a warm start reads it back instead (`kept_program`).
    first = np.minimum(np.arange(size), n_lanes - 1)
    example = (take_lanes(params, first), y0[first], engine, observers)
    program = kept_program(_run_block, *example)
    if program is None:
        _run_block.lower(*example)
        program = _run_block
    home = _shared_device(devices)

    def task(i, device):
        pick = by_cost[np.minimum(np.arange(starts[i], starts[i] + size), n_lanes - 1)]
        inputs = jax.device_put((take_lanes(params, pick), y0[pick]), home(device))
        out = program(*inputs, engine, observers)
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[:len(pick)], out)

    blocks = on_devices(task, len(starts), "trajectories", progress, devices=devices,
                        sizes=[min(size, n_lanes - s) for s in starts])
    obs = jax.tree_util.tree_map(lambda *x: np.concatenate(x)[:n_lanes], *blocks)
    return jax.tree_util.tree_map(lambda x: x[np.argsort(by_cost)], obs)


def _run_vmap(params, y0, engine, observers, devices, batch_size, progress, costs):
    """The vmap schedule of `run_lanes`: batches of lanes in lockstep, ordered by
    cost, each dealt to the devices."""
    n_lanes = y0.shape[0]
    by_cost = np.argsort(costs, kind="stable")
    mesh = Mesh(np.array(devices), ("lanes",))
    parts = []
    with _bar(progress, n_lanes, "trajectories") as bar:
        for s in range(0, n_lanes, batch_size):
            batch = by_cost[s:s + batch_size]
            order = _lane_order(len(batch), len(devices))
            pick = batch[np.minimum(order, len(batch) - 1)]  # padding repeats a lane
            out = _run_vmapped(take_lanes(params, pick), y0[pick], engine, mesh, observers)
            back = np.argsort(order)[:len(batch)]
            parts.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[back], out))
            bar.update(len(batch))
    obs = jax.tree_util.tree_map(lambda *x: np.concatenate(x), *parts)
    return jax.tree_util.tree_map(lambda x: x[np.argsort(by_cost)], obs)


def _shared_device(devices: Sequence) -> Callable:
    """Where the queue's worker for each device runs its tasks: on a CPU, every
    worker on the first device; elsewhere each on its own.

    XLA's CPU client runs executions of one compiled program from several threads
    at once, each on the thread that calls it, so the cores are kept busy by the
    workers whichever CPU device they name. One device then needs the program
    compiled, or read from the persistent cache, once instead of once per device
    (a compiled program is bound to its device; `benchmarks/fixed_cost.py`). The
    result is the same program's, bitwise."""
    first = devices[0]
    if first.platform == "cpu":
        return lambda device: first
    return lambda device: device


def _costs(params, y0, costs) -> np.ndarray:
    """`costs` checked against the lanes, or `expected_cost` when None.

    **Raises:** `ValidationError` when `costs` is not of shape (lanes,)."""
    if costs is None:
        return expected_cost(params, y0)
    costs = np.asarray(costs, dtype=float)
    if costs.shape != (len(y0),):
        raise ValidationError(f"costs: one value per lane, shape ({len(y0)},), got "
                              f"{costs.shape}")
    return costs


@contextlib.contextmanager
def _bar(progress: bool | tqdm, total: int, desc: str):
    """A new tqdm bar of `total` (hidden unless `progress`), closed at the end; or
    the bar `progress` itself, left open for its owner."""
    if isinstance(progress, tqdm):
        yield progress
        return
    bar = tqdm(total=total, desc=desc, disable=not progress, leave=False)
    try:
        yield bar
    finally:
        bar.close()


def on_devices(task: Callable, n_tasks: int, desc: str, progress: bool | tqdm = False, *,
               devices: Sequence | None = None, sizes: Sequence[int] | None = None
               ) -> list:
    """Call `task(i, device)` for i = 0..n_tasks-1, one call at a time per device
    (this process's devices of JAX's default backend, or `devices`), each device
    taking the next i as soon as it is free (so long and short tasks balance).
    `task` should put its inputs on `device` (`jax.device_put`) so that its
    computation runs there. The progress bar (a new one if `progress` is True, or
    the tqdm bar `progress`) counts tasks, or `sizes[i]` for task i.

    **Returns:**

    The results, in the order of i.

    **Raises:**

    The first exception raised by a task, after the running tasks finish. When the
    caller is interrupted (Ctrl-C) while it waits, no further task is started.
    """
    todo: queue.Queue = queue.Queue()
    for i in range(n_tasks):
        todo.put(i)
    results: list = [None] * n_tasks
    errors: list = []
    sizes = list(sizes) if sizes is not None else [1] * n_tasks
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
                bar.update(sizes[i])

    with _bar(progress, sum(sizes), desc) as bar:
        threads = [threading.Thread(target=worker, args=(d,), daemon=True)
                   for d in list(devices or jax.local_devices())[:max(1, n_tasks)]]
        for t in threads:
            t.start()
        try:
            for t in threads:
                t.join()
        except BaseException as err:  # interrupted: the workers take no further task
            errors.append(err)
            raise
    if errors:
        raise errors[0]
    return results
