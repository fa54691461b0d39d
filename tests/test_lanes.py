"""The lanes of an ensemble (`jc.run_lanes`): they come back in the order given,
each equal to its own `simulate`, and the same on one device or two; the order in
which the queue takes them changes no result; the compiled run holds no host
callback, custom call or scatter, and needs no more memory for a longer t_end.

Besides the public names, this file tests internal units of the lanes' schedule,
and imports them from `jaxchain._engine.lanes`: how lanes are dealt to devices
(`_lane_order`, `block_size`, `on_devices`), their expected cost, and the compiled
block (`_run_block`)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxchain as jc
from helpers import SHORT, TIGHT, assert_within_drift
from lanes_on_every_device import FIELDS
from jaxchain import lane_params, run_lanes
from jaxchain._engine.lanes import _run_block, block_size, expected_cost, _lane_order, on_devices

HERE = Path(__file__).parent


@pytest.fixture(scope="module")
def every_device(tmp_path_factory):
    """`lanes_on_every_device.py` run in a fresh process with the library's own
    device count (the test processes use one device, `conftest.py`)."""
    out = tmp_path_factory.mktemp("lanes") / "runs.npz"
    env = {k: v for k, v in os.environ.items() if k != "JAX_NUM_CPU_DEVICES"}
    run = subprocess.run([sys.executable, str(HERE / "lanes_on_every_device.py"), str(out)],
                         cwd=HERE, capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    return dict(np.load(out))


#: Run in a fresh process by `devices_at_a_barrier`, where `jaxchain.configure()`
#: chooses the device count: the ids of the devices that ran the 7 tasks of
#: `on_devices`, whose first tasks meet at a barrier that opens only if every
#: device runs one of them at once; then the device count.
_BARRIER = """
import sys, threading
import jax, numpy as np
import jaxchain as jc
jc.configure()
from jaxchain._engine.lanes import on_devices
n_dev = len(jax.devices())
barrier, seen = threading.Barrier(n_dev, timeout=30), []
def task(i, device):
    if i < n_dev:
        barrier.wait()
    seen.append(device.id)
    return int(jax.device_put(np.int64(i) ** 2, device))
assert on_devices(task, 7, "squares") == [i**2 for i in range(7)]
print(sorted(set(seen)), len(jax.devices("cpu")))
"""


@pytest.fixture(scope="module")
def devices_at_a_barrier():
    """(the devices that ran `on_devices`' tasks, the device count) in a fresh
    process with the library's own device count (`_BARRIER`)."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_NUM_CPU_DEVICES"}
    run = subprocess.run([sys.executable, "-c", _BARRIER], cwd=HERE, capture_output=True,
                         text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr
    used, n_devices = run.stdout.strip().splitlines()[-1].rsplit(" ", 1)
    return [int(d) for d in used.strip("[]").split(",")], int(n_devices)


@pytest.mark.study
def test_one_cpu_device_per_core(every_device):
    """`jaxchain.configure()` asks JAX for one CPU device per usable core (nothing
    in that process's environment sets the count)."""
    assert every_device["n_devices"] == every_device["cores"]


@settings(deadline=None)  # no clock: two workers share two cores
@given(st.integers(1, 50), st.integers(1, 8))
def test_lane_order_deals_lanes_like_cards(n_lanes, n_devices):
    order = _lane_order(n_lanes, n_devices)
    assert len(order) % n_devices == 0 and len(order) - n_lanes < n_devices
    assert sorted(order) == list(range(len(order)))  # a permutation
    per_device = order.reshape(n_devices, -1)  # shard_map cuts it in equal blocks
    for d, block in enumerate(per_device):
        assert np.all(block % n_devices == d)


@pytest.mark.numerics
@pytest.mark.study
def test_run_lanes_with_padding_equals_runs_done_one_at_a_time():
    """3 stick-slipping lanes (padded to a multiple of the device count) come back
    in the order given, each equal to its own `simulate`: a different compiled
    program, so to the integration tolerance (`drift_bound`, at `TIGHT`: 0.05 % of
    the amplitudes), and with the same n_HALC."""
    p = jc.ChainParams(n_osc=2)
    v_d = np.array([1.3, 1.5, 1.7])
    y0 = np.stack([jc.OutOfPhaseExcitation.eq8([True, k > 0])(jc.ChainParams(n_osc=2, v_d=v))
                   for k, v in enumerate(v_d)])
    obs = run_lanes(lane_params(p, 3, v_d=v_d), y0, jc.Smoothed().solver, TIGHT)
    assert obs.amplitudes.shape == (3, 2)
    assert np.all(obs.n_halc >= 1)  # every lane sticks: the stick phases are compared
    for i, v in enumerate(v_d):
        single = jc.simulate(jc.ChainParams(n_osc=2, v_d=v), y0[i], options=TIGHT)
        assert np.array_equal(obs.y_initial[i], single.y_initial)
        assert int(obs.n_halc[i]) == int(single.n_halc)
        for field in ("amplitudes", "y_final"):
            assert_within_drift(getattr(obs, field)[i], getattr(single, field), TIGHT,
                                [obs.num_steps[i], single.num_steps], field)


@pytest.mark.numerics
@pytest.mark.study
def test_one_device_two_devices_and_both_engines_give_the_same_results(every_device):
    """5 lanes (`lanes_on_every_device.five_lanes`), with the work queue on one
    device and on two: every field is bitwise equal (each lane is the same compiled
    integration, whichever device takes it). Vmapped in lockstep on two devices,
    the lanes are a different compiled program, whose rounding differs and moves
    the adaptive steps a little: the same states, to the integration tolerance
    (`drift_bound`, at `TIGHT`)."""
    if every_device["n_devices"] < 2:
        pytest.skip("needs two devices (two cores)")
    one, two, vmapped = ({f: every_device[f"{run}_{f}"] for f in FIELDS}
                         for run in ("one", "two", "vmap"))
    assert np.all(one["n_halc"] >= 1)  # every lane sticks
    for field in FIELDS:
        assert np.array_equal(one[field], two[field]), field
    for field in ("n_halc", "status"):
        assert np.array_equal(one[field], vmapped[field]), field
    for field in ("amplitudes", "y_final"):
        assert_within_drift(one[field], vmapped[field], TIGHT,
                            [one["num_steps"], vmapped["num_steps"]], field)


@pytest.mark.study
def test_the_queue_compiles_its_program_once_for_every_cpu_device(every_device):
    """On a CPU the queue's workers all run the program compiled for the first
    device (XLA's CPU client runs it from several threads at once): after the run
    on one device, the run on two compiles nothing more, and its lanes are the
    same bits (above)."""
    if every_device["n_devices"] < 2:
        pytest.skip("needs two devices (two cores)")
    assert every_device["one_compiles"] >= 1  # the events are seen at all
    assert every_device["two_compiles"] == 0


def test_given_costs_only_order_the_lanes():
    """The lanes' costs (`costs=`, as an ensemble computes them with the initial
    states) change the order in which the queue takes the lanes, not their results:
    the same program, bitwise the same fields in the order given. Costs of the
    wrong shape are refused, naming them."""
    p = jc.ChainParams(n_osc=2)
    v_d = np.array([1.3, 1.5, 1.7])
    y0 = np.stack([jc.OutOfPhaseExcitation.eq8([True, k > 0])(jc.ChainParams(n_osc=2, v_d=v))
                   for k, v in enumerate(v_d)])
    lanes, solver = lane_params(p, 3, v_d=v_d), jc.Smoothed().solver
    default = run_lanes(lanes, y0, solver, TIGHT)
    reordered = run_lanes(lanes, y0, solver, TIGHT, costs=[1.0, 3.0, 2.0])
    for field in ("amplitudes", "y_final", "num_steps", "n_halc"):
        assert np.array_equal(getattr(default, field), getattr(reordered, field)), field
    with pytest.raises(jc.ValidationError, match="costs"):
        run_lanes(lanes, y0, solver, TIGHT, costs=[1.0, 2.0])


@pytest.mark.study
def test_compiled_run_holds_no_callback_custom_call_or_scatter():
    """The optimised program of the queue engine's run holds no host callback (it
    could not be cached, and the loop would run op by op), no custom call (LAPACK)
    and no scatter: nothing that keeps XLA's CPU backend from compiling the step
    loop into one kernel."""
    p = jc.ChainParams(n_osc=3)
    y0 = np.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 1))(p))[None]
    for solver in (jc.Smoothed().solver, jc.SOLVERS["bosh3"]()):  # the default, and another
        compiled = _run_block.lower(lane_params(p, 1), y0,
                                    jc.Smoothed(solver, TIGHT)).compile()
        ops = set(re.findall(r" ([a-z][a-z0-9-]*)\(", compiled.compiled.as_text()))
        assert "while" in ops and "tanh" in ops  # the step loop is there
        # a host callback is a custom call on the CPU
        assert not ops & {"custom-call", "scatter", "send", "recv", "infeed", "outfeed"}, type(solver).__name__


def test_expected_cost_grows_with_the_excited_block_and_is_zero_at_steady_sliding():
    p = jc.ChainParams(n_osc=6)
    v_d = np.array([1.2, 1.5, 1.5, 1.8])
    y0 = np.stack([np.asarray(jc.Exact().steady_sliding(jc.ChainParams(n_osc=6, v_d=v_d[0])))]
                  + [np.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(6, k))(
                      jc.ChainParams(n_osc=6, v_d=v))) for k, v in zip((1, 3), v_d[1:3])]
                  + [np.asarray(jc.Exact().steady_sliding(jc.ChainParams(n_osc=6, v_d=v_d[3])))])
    cost = expected_cost(lane_params(p, 4, v_d=v_d), y0)
    assert cost[0] == 0 and cost[3] == 0 and 0 < cost[1] < cost[2]


@settings(deadline=None)
@given(st.integers(1, 10**5), st.integers(1, 16))
def test_block_size_keeps_every_device_busy(n_lanes, n_devices):
    size = block_size(n_lanes, n_devices)
    n_blocks = -(-n_lanes // size)
    assert size >= 1 and n_blocks >= min(n_lanes, 16 * n_devices)


def test_on_devices_keeps_order_and_uses_every_device(devices_at_a_barrier):
    """In a fresh process, the first tasks met at a barrier that opens only if
    every device runs one of them at the same time, and every device ran a task."""
    used, n_devices = devices_at_a_barrier
    assert used == list(range(n_devices))


def test_on_devices_raises_the_first_error():
    def task(i, device):
        if i == 2:
            raise ValueError("task 2 failed")
        return i

    with pytest.raises(ValueError, match="task 2 failed"):
        on_devices(task, 5, "failing")


@pytest.mark.study
def test_memory_and_output_do_not_grow_with_t_end():
    """Amplitudes only: a run to t_end = 15000 (the paper's window [10000, 15000])
    keeps the same output and needs the same memory as a run to 1500 (window
    [1000, 1500]): XLA's buffer assignment of the compiled program, arguments,
    outputs and temporaries. Both windows are cut in chunks of 250 time units,
    whose samples are the largest buffer."""
    p = jc.ChainParams(n_osc=3)
    y0 = np.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 1))(p))[None]
    sizes, outputs = [], []
    for t_end in (1500.0, 15000.0):
        options = jc.SimulationOptions(t_end=t_end, transient=t_end * 2 / 3)
        args = (lane_params(p, 1), y0, jc.Smoothed(jc.SOLVERS["ros34pw2"](), options),
                (jc.Extrema(),))
        memory = _run_block.lower(*args).compile().compiled.memory_analysis()
        sizes.append(memory.argument_size_in_bytes + memory.output_size_in_bytes
                     + memory.temp_size_in_bytes)
        out = _run_block(*args)
        outputs.append(sum(np.asarray(v).nbytes for v in out.values()))
        assert out["status"][0] == jc.Status.ok
    assert outputs[0] == outputs[1]
    assert abs(sizes[1] / sizes[0] - 1) < 0.1


@pytest.mark.study
def test_observers_keep_the_compiled_run_free_of_callbacks_and_scatters():
    """With every observer, the tangent vector included, the optimised program holds
    no host callback, custom call or scatter (see test_lanes): the observers reduce
    each chunk with gathers, sorts and selects, outside the step loop."""
    p = jc.ChainParams(n_osc=3)
    y0 = np.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, 1))(p))[None]
    observers = (jc.Extrema(), jc.Energy(), jc.PeakTimes(), jc.TimeSeries(dt=1.0),
                 jc.PoincareSection(), jc.LargestLyapunov())
    compiled = _run_block.lower(lane_params(p, 1), y0,
                                jc.Smoothed(jc.SOLVERS["ros34pw2"](), SHORT),
                                observers).compile()
    ops = set(re.findall(r" ([a-z][a-z0-9-]*)\(", compiled.compiled.as_text()))
    assert "while" in ops and "tanh" in ops and "sort" in ops
    assert not ops & {"custom-call", "scatter", "send", "recv", "infeed", "outfeed"}
