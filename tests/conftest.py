import faulthandler
import os
import shutil
import tempfile

# One persistent compilation cache for the whole test session, in a temporary folder:
# the pytest-xdist workers and the subprocesses that the command-line and notebook
# tests start all inherit this variable, so a program compiled by one of them is
# loaded by the others. Set before JAX is imported, which reads it then. The
# controller process makes the folder and removes it at the end (`_CACHE_OWNER`).
_CACHE_OWNER = "JAX_COMPILATION_CACHE_DIR" not in os.environ
if _CACHE_OWNER:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxchain-tests-xla-")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")

# One CPU device in each process of the tests: the two pytest-xdist workers already
# fill the two cores, and XLA compiles a program once for each CPU device that runs
# it, so a second device per process would compile every program of the work queue
# twice (a quarter of the CPU time of the tests that use it, measured). Through the
# environment, so that the command-line, sweep, writer and notebook processes that
# the tests start inherit it; `configure` keeps a count chosen before it. The paths
# over several devices run in fresh processes without it, with the library's own
# count: `test_lanes.py` (tests/lanes_on_every_device.py) and `test_setup.py`; a
# Dask worker sets its own (one device per thread).
os.environ["JAX_NUM_CPU_DEVICES"] = "1"

# Every command that the tests start runs in its own process: no warm process is
# started behind them (jaxchain/_cli/warm.py; test_warm.py starts one of its own).
os.environ["JAXCHAIN_SERVER"] = "0"

import jax  # noqa: E402

# The command line's own persistent compilation cache stays off in the tests (one
# test turns it on in a folder of its own), so that they never write to the user's
# cache; the session's cache above serves them.
os.environ.setdefault("JAXCHAIN_CACHE_DIR", "")

jax.config.update("jax_numpy_rank_promotion", "raise")

import jaxchain  # noqa: E402

jaxchain.configure()  # float64 and the XLA flags, as a user's first call

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from helpers import (  # noqa: E402
    RING_OF_THREE,
    RING_OF_TWO,
    SETTLED,
    SHOOTING_OF_THREE,
    SHOOTING_OF_TWO,
    snake_start,
)


# --- Systems that several test files share, each computed once a process ---------


@pytest.fixture(scope="session")
def branch_point():
    """The ring of two's two-site state simulated from eq. (8), continued up in v_d
    to its first branch point: (its problem, its branch, the branch point), for
    test_branch_switching.py and test_snake.py."""
    # eq. (8) with both sites excited reaches the two-site state at the ring's v_d
    orbit, phase = snake_start(RING_OF_TWO, 2, options=SETTLED)
    y0 = np.asarray(orbit.y0)
    if phase != SHOOTING_OF_TWO.phase_oscillator:  # the copy with the oscillators swapped,
        y0 = y0[:, ::-1]                          # the ring's symmetry: phase on the first
    orbit = jaxchain.periodic_orbit(RING_OF_TWO, (y0, float(orbit.period)), SHOOTING_OF_TWO)
    assert abs(float(orbit.amplitudes[0] - orbit.amplitudes[1])) < 1e-6  # symmetric
    problem = jaxchain.cycle_problem(orbit, SHOOTING_OF_TWO)
    branch = jaxchain.continuation(problem, options=jaxchain.ContinuationOptions(
        ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.0, max_points=12))
    points = [b for b in jaxchain.locate_bifurcations(problem, branch) if b.kind == "branch point"]
    assert points and abs(points[0].multiplier - 1) < 1e-4
    return problem, branch, points[0]


@pytest.fixture(scope="session")
def ring_of_three_states():
    """The states that simulation reaches on the ring of three at v_d 1.5 from eq.
    (8) with k = 1 and 2 excited, refined by shooting: {k: PeriodicOrbit}, for
    test_deflation.py and test_snake.py."""
    states = {k: snake_start(RING_OF_THREE, k, options=SETTLED) for k in (1, 2)}
    # both with the phase condition of the tests' shooting (their oscillator of
    # largest amplitude): a problem built from either starts at a solution
    assert all(phase == SHOOTING_OF_THREE.phase_oscillator for _, phase in states.values())
    return {k: orbit for k, (orbit, _) in states.items()}


#: Seconds after which the pytest-xdist controller prints the stack of each of its
#: threads, and again each time as long: a whole pass takes about 12 minutes, so
#: a run still going then hangs, and the log names where the controller waits (a
#: test that runs too long names its own place: `faulthandler_timeout`).
CONTROLLER_DUMP_S = 2400


def _xdist_controller(config) -> bool:
    return not hasattr(config, "workerinput") and bool(config.getoption("numprocesses", None))


def pytest_configure(config):
    if _xdist_controller(config):  # the workers' own timer is per test (pytest's)
        faulthandler.dump_traceback_later(CONTROLLER_DUMP_S, repeat=True)


def pytest_unconfigure(config):
    if _xdist_controller(config):
        faulthandler.cancel_dump_traceback_later()
    if _CACHE_OWNER and not hasattr(config, "workerinput"):
        shutil.rmtree(os.environ["JAX_COMPILATION_CACHE_DIR"], ignore_errors=True)


def pytest_collection_modifyitems(session, config, items):
    """The notebooks last, the longest first: each runs a scene at the size of the
    test file that runs the same scene (test_examples.py: SMALL), and loads that
    file's programs from the session's compilation cache instead of compiling them
    again, once they are there."""
    items.sort(key=lambda item: item.nodeid.startswith("tests/test_examples.py"))
    # among the notebooks the later ones are the longer (08 the 2-D pad, 07 the snake):
    # the longest first, so that the two workers end together (the longest last
    # would run alone at the end)
    first = next((i for i, item in enumerate(items)
                  if item.nodeid.startswith("tests/test_examples.py")), len(items))
    items[first:] = sorted(items[first:], key=lambda item: item.nodeid, reverse=True)


def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's `--dist loadfile` (pyproject.toml), but each notebook of
    test_examples.py is a scope of its own: a test file stays on one worker, so
    that its tests share the programs they compile and its module fixtures run
    once, while the notebooks (a kernel each, sharing nothing) are shared between
    the workers."""
    from xdist.scheduler import LoadScopeScheduling

    class FileOrNotebook(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            file = nodeid.split("::")[0]
            return nodeid if file.endswith("test_examples.py") else file

    return FileOrNotebook(config, log)
