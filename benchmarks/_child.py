"""Subprocess worker of benchmarks/run.py (comparisons 0, 4 and 7): one jaxchain
trajectory in a fresh process, so that its peak memory is its own and its XLA_FLAGS
are those of its environment (jaxchain sets its own only when XLA_FLAGS is unset).

    python benchmarks/_child.py --n-osc 20 --t-end 300 --transient 200 [--repeats 3]

Prints one JSON line: compile (first call minus best), best wall, steps, µs per step,
resident memory after importing jaxchain and the peak resident memory, the XLA_FLAGS
in effect.

With --fig4, it runs the Fig. 4 ensemble instead (eq. (8) k = 1..20 at v_d = 1.5,
`--engine`, `--solver`, `--rtol`, `--atol`, `--controller`; another belt speed
with `--vd`), twice, and prints the first (compiling)
and second wall times, the steps, n_HALC and E of each trajectory.
"""

import argparse
import json
import os
import resource
import time


def _rss_mb() -> float:
    """Current resident memory in MiB (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return 0.0


def _peak_rss_mb() -> float:
    """Peak resident memory of this process in MiB: VmHWM of /proc/self/status,
    which starts afresh at exec (getrusage's ru_maxrss does not: it keeps the
    parent's peak across fork and exec), else ru_maxrss."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n-osc", type=int, default=20)
    p.add_argument("--excited", type=int, default=None,
                   help="oscillators excited by eq. (8) (default n_osc // 4)")
    p.add_argument("--t-end", type=float, default=300.0)
    p.add_argument("--transient", type=float, default=200.0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--solver", default=None, help="a name of jc.SOLVERS (default: "
                   "jaxchain's default solver)")
    p.add_argument("--fig4", action="store_true", help="run the Fig. 4 ensemble")
    p.add_argument("--engine", default=None, help="queue or vmap (with --fig4)")
    p.add_argument("--rtol", type=float, default=None)
    p.add_argument("--atol", type=float, default=None)
    p.add_argument("--controller", default=None, help="a name of CONTROLLERS (with --fig4)")
    p.add_argument("--vd", type=float, default=1.5, help="belt speed (with --fig4)")
    args = p.parse_args()

    import jax

    import jaxchain as jc
    from jaxchain._engine.solver.registry import DEFAULT_SOLVER

    jc.configure()  # float64, one CPU device per core, the XLA flags

    if args.fig4:
        _fig4(args, jc)
        return

    rss_import = _rss_mb()
    k = args.n_osc // 4 if args.excited is None else args.excited
    params = jc.ChainParams(n_osc=args.n_osc, v_d=1.5)
    ic = jc.OutOfPhaseExcitation.eq8(jc.excited_block(args.n_osc, k))
    options = jc.Smoothed(options=jc.SimulationOptions(
        t_end=args.t_end, transient=args.transient)).options  # resolved at the default eps
    name = args.solver or DEFAULT_SOLVER
    solver = jc.SOLVERS[name]()
    walls = []
    for _ in range(args.repeats + 1):
        start = time.perf_counter()
        obs = jax.block_until_ready(jc.simulate(params, ic, solver, options, throw=False))
        walls.append(time.perf_counter() - start)
    best = min(walls[1:])
    steps = int(obs.num_steps)
    print(json.dumps(dict(
        n_osc=args.n_osc, excited=k, t_end=args.t_end, transient=args.transient,
        solver=name, first_s=walls[0], walls_s=walls[1:], best_s=best,
        compile_s=walls[0] - best, steps=steps, us_per_step=best / steps * 1e6,
        status=int(obs.status), energy=float(obs.energy),
        rss_after_import_mb=rss_import,
        peak_rss_mb=_peak_rss_mb(),
        xla_flags=os.environ.get("XLA_FLAGS"))))


def _fig4(args, jc) -> None:
    tols = {k: v for k, v in (("rtol", args.rtol), ("atol", args.atol),
                              ("controller", args.controller)) if v is not None}
    options = jc.Smoothed(options=jc.SimulationOptions(  # tolerances resolved at eps
        t_end=args.t_end, transient=args.transient, **tols)).options
    solver = jc.SOLVERS[args.solver]() if args.solver else jc.Smoothed().solver
    walls = []
    for _ in range(2):
        start = time.perf_counter()
        ds = jc.ensemble(jc.ChainParams(n_osc=args.n_osc, v_d=args.vd), [args.vd],
                         jc.localized_family(args.n_osc), solver, options,
                         schedule=args.engine, progress=False)
        walls.append(time.perf_counter() - start)
    row = ds.isel(v_d=0)
    print(json.dumps(dict(
        solver=type(solver).__name__, engine=args.engine, rtol=options.rtol,
        atol=options.atol, controller=options.controller, v_d=args.vd, first_s=walls[0],
        warm_s=walls[1],
        steps=int(row["num_steps"].sum()), n_halc=row["n_halc"].values.tolist(),
        energy=row["energy"].values.tolist(), status=row["status"].values.tolist(),
        xla_flags=os.environ.get("XLA_FLAGS"))))


if __name__ == "__main__":
    main()
