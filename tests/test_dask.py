"""The Dask route of the batched studies: a sweep, a basin-stability run and a
cross-check on a `LocalCluster` of two spawned worker processes equal the
in-process runs to the last bit; a worker killed in the middle of a sweep is
replaced and its batches run again; a scheduler that goes away leaves a command
that exits 1 in one line and a store that `--resume` finishes in process."""

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import xarray as xr
from distributed.diagnostics.plugin import SchedulerPlugin

import jaxchain as jc
from helpers import (HOLD, JAXCHAIN, SWEEP_RESULTS, batches_done, dask_client, held, hold_env,
                     kill, release, scheduler_workers, small_sweep, sweep_cli)

#: A ring of 3 at 4 belt speeds x eq. (8) with k = 1..3 (`small_sweep`): 12
#: trajectories in 6 batches of 2; a worker or the scheduler is killed in the
#: middle of the sweep at a batch write held by the writers' test hook.
VD = "1.4:1.7:4"
CLI = sweep_cli(VD)
RESULTS = SWEEP_RESULTS


def _api_sweep(**kw):
    return small_sweep(VD, **kw)


@pytest.fixture(scope="module")
def in_process():
    """The sweep run in this process, in memory."""
    return _api_sweep().load()


@pytest.fixture(scope="module")
def client():
    with dask_client("local:2") as c:
        yield c


def _scheduler_address(file, deadline_s=60) -> str:
    """The address in a scheduler file, once the scheduler has written it whole."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        try:
            return json.loads(file.read_text())["address"]
        except (OSError, ValueError, KeyError):
            time.sleep(0.1)
    raise AssertionError("the scheduler wrote no address in time")


@pytest.mark.study
@pytest.mark.long
def test_a_sweep_on_a_local_cluster_equals_the_in_process_sweep(tmp_path, client, in_process):
    """Each batch is a task on one of two spawned worker processes, which writes
    its region of the store: the result equals the in-process sweep bit for bit
    (the same compiled programs), and the batches are all flagged."""
    ds = _api_sweep(store=tmp_path / "s.zarr", client=client).load()
    assert ds.attrs["batches_done"] == ds.attrs["batches_total"] == 6
    ran = client.run(lambda: __import__("jax").device_count())
    assert sorted(ran.values()) == [1, 1], "one JAX device per worker thread"
    xr.testing.assert_equal(ds[RESULTS], in_process[RESULTS])
    xr.testing.assert_equal(jc.open_sweep(tmp_path / "s.zarr").load()[RESULTS],
                            in_process[RESULTS])


class _Attempts(SchedulerPlugin):
    """The transitions of the sweep's tasks as the scheduler makes them: (key, new
    state), a task handed to a worker being "processing"."""

    name = "test-sweep-attempts"

    def __init__(self):
        self.log = []

    def transition(self, key, start, finish, *args, **kwargs):
        if str(key).startswith("sweep-"):
            self.log.append((str(key), finish))


@pytest.mark.study
def test_a_worker_killed_mid_sweep_is_replaced_and_its_batch_is_run_again(
        tmp_path, client, in_process):
    """The workers hold before each batch write (the writers' test hook, on in
    the two worker processes): the first batch held is released, and the worker
    holding the next one is killed (SIGKILL) with its task, that batch unwritten.
    The scheduler's log shows that batch's task processed twice (lost, then run
    again by Dask, on the other worker or the one the nanny restarts) and
    finished once; the result is the uninterrupted sweep."""
    store, hooks = tmp_path / "s.zarr", tmp_path / "hooks"
    hooks.mkdir()
    client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.add_plugin(_Attempts()))
    client.run(lambda: os.environ.__setitem__(HOLD, str(hooks)))  # hold_env, in the workers
    result = {}
    thread = threading.Thread(target=lambda: result.update(
        ds=_api_sweep(store=store, client=client).load()), daemon=True)
    try:
        thread.start()
        first, _ = held(hooks, 1)
        release(hooks, 1)
        victim_batch, victim = held(hooks, 2)
        assert victim_batch != first and victim_batch.startswith("s.zarr batch ")
        os.kill(victim, signal.SIGKILL)
    finally:
        release(hooks)  # every later hold passes
        thread.join(timeout=600)
        client.run(lambda: os.environ.pop(HOLD, None))
        log = client.run_on_scheduler(
            lambda dask_scheduler: dask_scheduler.plugins.pop(_Attempts.name).log)
    assert not thread.is_alive() and "ds" in result
    batch = int(victim_batch.split()[-1])
    states = [finish for key, finish in log if f"-batch-{batch}-" in key]
    assert states.count("processing") == 2 and states.count("memory") == 1, states
    ds = result["ds"]
    assert ds.attrs["batches_done"] == ds.attrs["batches_total"] == 6
    xr.testing.assert_equal(ds[RESULTS], in_process[RESULTS])


@pytest.mark.study
@pytest.mark.long
def test_the_scheduler_going_away_exits_1_in_one_line_and_resume_finishes_in_process(
        tmp_path, in_process):
    """`jaxchain sweep --scheduler ADDRESS` on a scheduler and one worker started
    with Dask's own commands: the scheduler is killed while the worker holds
    before writing its second batch, the first stored (the writers' test hook,
    on in the worker). The command exits 1 with one line on stderr, the store
    keeps the flagged batch alone, and `--resume` without a cluster completes it
    to the uninterrupted sweep."""
    out, file, hooks = tmp_path / "out", tmp_path / "scheduler.json", tmp_path / "hooks"
    started = []

    def start(*args, env=None):
        started.append(subprocess.Popen(args, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL, env=env))
        return started[-1]

    try:
        scheduler = start(sys.executable, "-m", "distributed.cli.dask_scheduler",
                          "--scheduler-file", str(file), "--port", "0", "--no-dashboard")
        address = _scheduler_address(file)
        start(sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file",
              str(file), "--nthreads", "1", "--no-dashboard", "--death-timeout", "5",
              env=hold_env(hooks))
        proc = subprocess.Popen(
            [*JAXCHAIN, *CLI, "--out", str(out),
             "--scheduler", address], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True)
        started.append(proc)
        first = held(hooks, 1, proc)[0]
        release(hooks, 1)
        held(hooks, 2, proc)  # the worker's next batch: the first is flagged
        scheduler.send_signal(signal.SIGKILL)
        _, err = proc.communicate(timeout=300)
    finally:
        for p in started:  # the worker too, still holding its second batch
            kill(p)
    assert proc.returncode == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "scheduler" in lines[0], err
    done = np.array(batches_done(out / "sweep.zarr"))
    assert np.flatnonzero(done).tolist() == [int(first.split()[-1])]

    assert jc.main([*CLI, "--out", str(out), "--resume"]) == 0
    xr.testing.assert_equal(jc.open_sweep(out / "sweep.zarr").load()[RESULTS],
                            in_process[RESULTS])


@pytest.mark.study
@pytest.mark.long
def test_basin_on_a_local_cluster_equals_basin_in_process(tmp_path, client):
    """`jaxchain basin --scheduler ADDRESS`, on the module's cluster of two spawned
    workers, writes the basin.nc of the in-process command, to the last bit. The ring
    and window of notebook 04 (test_examples.py: SMALL), whose kernel then loads
    these programs from the session's cache."""
    args = ["basin", "--n-osc", "3", "--vd", "1.5", "--samples", "8", "--t-end", "300",
            "--transient", "200", "--check", "2", "--no-progress", "--json"]
    assert jc.main([*args, "--out", str(tmp_path / "here")]) == 0
    assert jc.main([*args, "--out", str(tmp_path / "dask"), "--scheduler",
                    client.scheduler.address]) == 0
    here = xr.open_dataset(tmp_path / "here" / "basin.nc").load()
    there = xr.open_dataset(tmp_path / "dask" / "basin.nc").load()
    xr.testing.assert_identical(here.drop_attrs(), there.drop_attrs())


@pytest.mark.study
def test_a_crosscheck_on_a_local_cluster_equals_the_in_process_one(tmp_path, client):
    """Each non-smooth reference run is a task that stores its run in the
    checkpoint folder: the cross-check equals the in-process one, wall times aside,
    and the folder holds the same runs. The oscillator and window of
    test_crosscheck's tiny cross-check, whose programs the session's cache may
    hold."""
    kw = {"params": jc.ChainParams(n_osc=1), "v_d": (1.3, 1.5, 1.6, 1.7),
          "ics": (("eq8", 1),),
          "options": jc.SimulationOptions(t_end=600.0, transient=300.0, chunk_length=150.0)}
    here = jc.crosscheck(**kw, checkpoint=tmp_path / "here")
    there = jc.crosscheck(**kw, checkpoint=tmp_path / "dask", client=client)
    xr.testing.assert_equal(there.drop_vars("wall_time_s_reference"),
                            here.drop_vars("wall_time_s_reference"))
    assert (sorted(f.name for f in (tmp_path / "dask").iterdir())
            == sorted(f.name for f in (tmp_path / "here").iterdir()))
    assert len(list((tmp_path / "here").iterdir())) == 4


def test_bad_scheduler_addresses_are_refused():
    for bad in ("local:0", "local:x", "", "local:"):
        with pytest.raises(ValueError, match="scheduler"):
            scheduler_workers(bad)
    assert scheduler_workers("local:3") == 3 and scheduler_workers("tcp://h:8786") is None
    with pytest.raises(ValueError, match="store"):
        _api_sweep(client=object())
    with pytest.raises(ValueError, match="checkpoint"):
        jc.crosscheck(jc.ChainParams(n_osc=1), client=object())
    with pytest.raises(RuntimeError, match="no Dask scheduler answers"), \
            dask_client("tcp://127.0.0.1:9", timeout=1):  # the discard port: nobody listens
        pass


def test_bad_scheduler_option_exits_2_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        jc.main([*CLI, "--out", str(tmp_path), "--scheduler", "local:0"])
    assert exc.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
