import os
import threading

import jax
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import jaxchain as jc
from helpers import SHORT
from jaxchain._lanes import lane_order, on_devices, run_lanes
from jaxchain._solvers import DEFAULT_SOLVER, SOLVERS


def test_one_cpu_device_per_core():
    """jaxchain asks JAX for one CPU device per usable core (nothing in the test
    environment sets the count)."""
    assert len(jax.devices("cpu")) == len(os.sched_getaffinity(0))


@given(st.integers(1, 50), st.integers(1, 8))
def test_lane_order_deals_lanes_like_cards(n_lanes, n_devices):
    order = lane_order(n_lanes, n_devices)
    assert len(order) % n_devices == 0 and len(order) - n_lanes < n_devices
    assert sorted(order) == list(range(len(order)))  # a permutation
    per_device = order.reshape(n_devices, -1)  # shard_map cuts it in equal blocks
    for d, block in enumerate(per_device):
        assert np.all(block % n_devices == d)


def test_run_lanes_with_padding_equals_runs_done_one_at_a_time():
    """3 lanes (padded to a multiple of the device count) come back in the order
    given, each equal to its own `simulate`."""
    p = jc.ChainParams(n_osc=2)
    v_d = np.array([1.3, 1.5, 1.7])
    y0 = np.stack([jc.OutOfPhaseExcitation.eq8([True, k > 0])(jc.ChainParams(n_osc=2, v_d=v))
                   for k, v in enumerate(v_d)])
    obs = run_lanes(p, v_d, y0, SOLVERS[DEFAULT_SOLVER](), SHORT)
    assert obs.amplitudes.shape == (3, 2)
    for i, v in enumerate(v_d):
        single = jc.simulate(jc.ChainParams(n_osc=2, v_d=v), y0[i], options=SHORT)
        assert np.allclose(obs.amplitudes[i], single.amplitudes, rtol=1e-9)
        assert int(obs.num_steps[i]) == int(single.num_steps)


def test_on_devices_keeps_order_and_uses_every_device():
    """The first tasks meet at a barrier: it opens only if every device runs one of
    them at the same time."""
    seen = []
    n_dev = len(jax.devices())
    barrier = threading.Barrier(n_dev, timeout=30)

    def task(i, device):
        if i < n_dev:
            barrier.wait()
        seen.append(device)
        return int(jax.device_put(np.int64(i) ** 2, device))

    assert on_devices(task, 7, "squares") == [i**2 for i in range(7)]
    assert set(seen) == set(jax.devices())


def test_on_devices_raises_the_first_error():
    def task(i, device):
        if i == 2:
            raise ValueError("task 2 failed")
        return i

    with pytest.raises(ValueError, match="task 2 failed"):
        on_devices(task, 5, "failing")
