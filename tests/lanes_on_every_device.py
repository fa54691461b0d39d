"""Run by `test_lanes.py` in a fresh process, where `jaxchain.configure()` chooses
the CPU device count (one per core; the test processes use one, `conftest.py`): the work
queue over every device, and the lanes of `FIVE_LANES` on one device, on two, and
vmapped. Writes `<out>.npz` with the device and core counts, the compilations of
the queue's program for one device and then for two, and every field of the three
runs. Public names only: `test_lanes.py` checks the internal dealing of tasks to
devices in a fresh process of its own."""

import os
import sys

import jax
import numpy as np

import jaxchain as jc

jc.configure()  # as a user's first call: one device per core, float64, the XLA flags

from helpers import TIGHT  # noqa: E402

FIELDS = ("amplitudes", "energy", "n_halc", "y_final", "num_steps", "status")


def five_lanes():
    """5 lanes of a ring of 3 at belt speeds 1.3 to 1.7, 1 to 3 oscillators excited."""
    v_d = np.array([1.3, 1.5, 1.7, 1.5, 1.6])
    y0 = np.stack([jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 1 + k % 3))(
        jc.ChainParams(n_osc=3, v_d=v)) for k, v in enumerate(v_d)])
    return jc.lane_params(jc.ChainParams(n_osc=3), v_d.size, v_d=v_d), y0


def main(out: str) -> None:
    params, y0 = five_lanes()
    solver = jc.SOLVERS["ros34pw2"]()
    devices = jax.devices()
    compiles = []  # XLA compilations (JAX's events), by the program's name
    jax.monitoring.register_event_time_span_listener(
        lambda event, start, end, **kw: compiles.append(kw.get("fun_name", ""))
        if event == "/jax/core/compile/backend_compile_duration" else None)
    runs = {"one": jc.run_lanes(params, y0, solver, TIGHT, schedule="queue", devices=devices[:1])}
    before = len(compiles)
    runs["two"] = jc.run_lanes(params, y0, solver, TIGHT, schedule="queue", devices=devices[:2])
    two_compiles = sum("run_block" in name for name in compiles[before:])
    runs["vmap"] = jc.run_lanes(params, y0, solver, TIGHT, schedule="vmap", devices=devices[:2])
    np.savez(out, n_devices=len(jax.devices("cpu")), cores=len(os.sched_getaffinity(0)),
             two_compiles=two_compiles,
             one_compiles=sum("run_block" in name for name in compiles[:before]),
             **{f"{run}_{f}": np.asarray(getattr(obs, f)) for run, obs in runs.items()
                for f in FIELDS})


if __name__ == "__main__":
    main(sys.argv[1])
