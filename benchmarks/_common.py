"""What the comparisons of benchmarks/run.py share: the settings of a quick or full
run, the benchmark scene, timing helpers, result rows and machine information."""

import dataclasses
import os
import platform
import sys
import time
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import jax
import numpy as np

import jaxchain as jc
from jaxchain._physics.forces import DEFAULT_EPS
from jaxchain._engine.solver.registry import DEFAULT_SOLVER

jc.configure()  # float64, one CPU device per core, the XLA flags

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent

#: The scene of comparisons 1, 2 and 7: N = 20, v_d = 1.5, eq. (8) with k = 5
#: excited, the package's default eps, solver and tolerances.
N_OSC, V_D, K_EXCITED = 20, 1.5, 5

#: The paper's horizon (Section 3.2), the "main job" of Fig. 4.
PAPER_T_END, PAPER_TRANSIENT = 15000.0, 10000.0


@dataclasses.dataclass(frozen=True)
class Settings:
    """Horizons and sizes of one benchmark run (`QUICK` or `FULL`)."""

    name: str
    single: tuple[float, float]  # (t_end, transient) of comparisons 1, 2 and 7
    ensemble: tuple[float, float]  # comparison 3 (Fig. 4 family, both engines)
    sizes_horizon: tuple[float, float]  # comparison 5
    sizes: tuple[int, ...]  # ensemble sizes actually run
    big_size: int | None  # run if it fits in big_size_budget_s, else extrapolated
    big_size_budget_s: float
    n_osc_horizon: tuple[float, float]  # comparison 4
    n_oscs: tuple[int, ...]
    sweep_vds: tuple[float, ...]  # comparison 6 subsample of belt speeds
    sweep_horizon: tuple[float, float]
    repeats: int  # best-of for the short single-trajectory timings
    cli_main_job: bool  # also time the default `jaxchain localized`


QUICK = Settings(
    name="quick", single=(300.0, 200.0), ensemble=(3000.0, 2000.0),
    sizes_horizon=(100.0, 50.0), sizes=(1, 10, 100, 1000), big_size=None,
    big_size_budget_s=0.0, n_osc_horizon=(100.0, 50.0), n_oscs=(20, 100, 1000),
    sweep_vds=(1.0, 1.5, 2.0), sweep_horizon=(3000.0, 2000.0), repeats=3,
    cli_main_job=False)

FULL = Settings(
    name="full", single=(1500.0, 1000.0), ensemble=(PAPER_T_END, PAPER_TRANSIENT),
    sizes_horizon=(200.0, 100.0), sizes=(1, 10, 100, 1000), big_size=10_000,
    big_size_budget_s=300.0, n_osc_horizon=(300.0, 200.0), n_oscs=(20, 100, 1000),
    sweep_vds=(1.0, 1.5, 2.0), sweep_horizon=(PAPER_T_END, PAPER_TRANSIENT), repeats=3,
    cli_main_job=True)

#: The sweep of comparison 6: 21 belt speeds x 20 initial conditions.
SWEEP_VDS = np.round(np.linspace(1.0, 2.0, 21), 10)


@dataclasses.dataclass
class Row:
    """One line of the results table. `ratio` is baseline / jaxchain unless the notes
    say otherwise (> 1: jaxchain is faster or smaller)."""

    measure: str
    baseline: str
    jaxchain: str
    ratio: str
    notes: str


def scene(t_end: float, transient: float, n_osc: int = N_OSC, k: int | None = K_EXCITED):
    """(params, eq. (8) initial condition, options) of a single trajectory, with the
    package defaults for everything not named."""
    params = jc.ChainParams(n_osc=n_osc, v_d=V_D)
    ic = jc.OutOfPhaseExcitation.eq8(jc.excited_block(n_osc, k))
    # the tolerances as the smoothed engine resolves them at the default eps
    return params, ic, jc.Smoothed(options=jc.SimulationOptions(
        t_end=t_end, transient=transient)).options


def timed(fn: Callable, *args, **kwargs):
    """(result, wall seconds) of fn(*args, **kwargs), JAX results waited for."""
    start = time.perf_counter()
    out = jax.block_until_ready(fn(*args, **kwargs))
    return out, time.perf_counter() - start


def simulate_once(params, ic, solver, options):
    """One jaxchain trajectory: (observables with NumPy leaves, wall seconds)."""
    obs, wall = timed(jc.simulate, params, ic, solver, options, throw=False)
    return jax.tree_util.tree_map(np.asarray, obs), wall


def fmt_time(seconds: float) -> str:
    if not np.isfinite(seconds):
        return "-"
    if seconds >= 100:
        return f"{seconds:.0f} s"
    if seconds >= 1:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.1f} ms"
    return f"{seconds * 1e6:.1f} µs"


def fmt_ratio(ratio: float) -> str:
    return "-" if not np.isfinite(ratio) else f"{ratio:.2f}x" if ratio < 10 else f"{ratio:.0f}x"


def _version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cores() -> int:
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _commit() -> str:
    """The git commit of the measured code, marked "+ changes" when the work tree
    differs from it; "unknown" outside a git checkout."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (" + changes" if dirty else "")


def machine_info() -> dict:
    """What the timings depend on: CPU, cores, JAX devices, library versions, the
    XLA flags in effect and the load when the run started (other processes on the
    same cores make every timing noisy; ratios are measured side by side)."""
    info = {
        "CPU": cpu_model(),
        "cores (usable)": cores(),
        "JAX devices": f"{len(jax.devices())} x {jax.devices()[0].platform}",
        "python": sys.version.split()[0],
        "XLA_FLAGS": os.environ.get("XLA_FLAGS", ""),
        "load average at start (1, 5, 15 min)":
            ", ".join(f"{x:.2f}" for x in os.getloadavg()),
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "commit": _commit(),
    }
    for pkg in ("jaxchain", "jax", "jaxlib", "diffrax", "equinox", "numpy", "scipy",
                "numba"):
        info[pkg] = _version(pkg)
    info["jaxchain default solver"] = DEFAULT_SOLVER
    defaults = jc.Smoothed().options  # the tolerances resolved at the default eps
    info["jaxchain defaults"] = (f"eps = {DEFAULT_EPS:g}, rtol = "
                                 f"{defaults.rtol:g}, atol = {defaults.atol:g}, "
                                 f"sample_dt = {defaults.sample_dt:g}, chunk_length = "
                                 f"{defaults.chunk_length:g}")
    return info


def progress(message: str, start: float) -> None:
    """One progress line with the time since the run started."""
    print(f"[{time.perf_counter() - start:6.0f} s] {message}", flush=True)
