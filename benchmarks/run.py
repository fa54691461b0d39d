"""Benchmarks of jaxchain, each as a ratio against a baseline measured in the same run
on the same machine (timings on a shared machine are noisy; ratios of interleaved or
best-of-k measurements are what carry over).

    python benchmarks/run.py [--quick] [--out DIR] [--sweep] [--only 1,3,cli]

Comparisons (the scene is N = 20, v_d = 1.5, eq. (8) with k = 5 excited, the package's
default solver, eps and tolerances, unless stated):

0. the Fig. 4 ensemble as jaxchain ran it before the fast engine (Bosh3 at rtol 1e-6,
   vmapped lockstep, no XLA flag) against its defaults now, in separate processes;
1. one trajectory against scipy's LSODA (NumPy right-hand side), and their energies;
2. µs per step against numba loops of the same tableau and step-size controller
   (ROS34PW2 and Bosh3; skipped with a note if numba is not installed);
3. the Fig. 4 ensemble by the new queue engine against the old vmapped path;
4. time per step and peak memory against n_osc = 20, 100, 1000 (own processes);
5. wall time against the number of trajectories, 1 to 10^4;
6. the 21 x 20 belt-speed sweep, estimated from a subsample (or run, --sweep);
7. XLA flag check: jaxchain's flag against none (exit status 1 if < 1.3x faster);
8. the targets of issue 24 against the previous defaults (ROS34PW2, diffrax's
   integral controller, rtol 1e-5) in the same run: steps and wall time of the
   Fig. 4 scene, the sweep estimate, and `import jaxchain` against `import jax,
   diffrax`;
9. cost per step on a coupling graph: the 4 x 5 lattice (and with masses and a
   friction table) against the ring of 20;
cli. cold and warm start of `jaxchain localized` with a fresh JAXCHAIN_CACHE_DIR,
   and in the full run the main job's second run at the previous defaults.

Writes DIR/benchmarks.md (table and machine), DIR/benchmarks.json (raw numbers),
DIR/scaling_n_osc.png and DIR/scaling_ensemble.png, and prints the table.
Exit status: 0, 1 if the flag check fails, 2 if a comparison crashed (its row says
how).
"""

import os

#: The environment before jaxchain's import adds XLA_FLAGS: children get this one.
ORIGINAL_ENV = dict(os.environ)

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from _common import FULL, QUICK, REPO, Row, machine_info, progress  # noqa: E402

COMPARISONS = ("0", "1", "2", "3", "4", "5", "6", "7", "8", "9", "cli")

EPILOG = """\
timing:
  --quick takes about 3-5 minutes on 2 idle cores: comparisons 1, 2 and 7 on
  t in [0, 300] (LSODA is slow), the Fig. 4 ensembles and the sweep subsample
  on [0, 3000] (the sweep then scaled x5 in time to t_end 15000), ensemble
  sizes up to 1000 on [0, 100] (10^4 not run), n_osc scaling on [0, 100]. The
  full run takes about 20-25 minutes: [0, 1500] for 1, 2 and 7, the paper's
  horizon (15000, transient 10000) for 3 and 6, sizes on [0, 200] with 10^4
  trajectories if predicted under 5 minutes (else extrapolated, and marked so),
  n_osc on [0, 300], and the CLI's main job. --quick writes to the same
  default folder as the full run: give it another --out to keep both.

numba:
  comparison 2 needs numba (pip install numba); without it that comparison is
  skipped with a note and everything else runs.

exit status:
  0 on success, 1 if the XLA flag check (7) finds less than a 1.3x speed-up,
  2 if a comparison crashed (its row in the table carries the error).
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python benchmarks/run.py", description=__doc__.split("\n\n")[0],
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help="short horizons and sizes (about 3-5 min on 2 cores)")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "benchmarks", metavar="DIR",
                   help="folder for benchmarks.md, benchmarks.json and the PNGs "
                        "(default: docs/benchmarks/ of the repository)")
    p.add_argument("--sweep", action="store_true",
                   help="also run the 420-trajectory sweep of comparison 6 at t_end "
                        "15000 (a few minutes), not only estimate it")
    p.add_argument("--only", default=",".join(COMPARISONS), metavar="LIST",
                   help="comma-separated comparisons to run, of "
                        f"{','.join(COMPARISONS)} (default: all)")
    return p


def _table(rows: list[Row]) -> str:
    def cell(s: str) -> str:
        return str(s).replace("|", "\\|").replace("\n", " ")

    lines = ["| measure | baseline | jaxchain | ratio | command / notes |",
             "|---|---|---|---|---|"]
    lines += [f"| {cell(r.measure)} | {cell(r.baseline)} | {cell(r.jaxchain)} | "
              f"{cell(r.ratio)} | {cell(r.notes)} |" for r in rows]
    return "\n".join(lines)


def _markdown(rows, info, settings, args, wall, figures) -> str:
    mode = "--quick" if args.quick else "full run"
    machine = "\n".join(f"- {k}: {v}" for k, v in info.items())
    figs = "\n".join(f"![{f.stem}]({f.name})" for f in figures)
    return f"""# jaxchain benchmarks ({mode})

Generated by `python benchmarks/run.py{' --quick' if args.quick else ''}` in
{wall / 60:.1f} min. Every ratio is baseline / jaxchain measured in this one run on
this one machine (> 1: jaxchain faster or smaller), unless its cell says otherwise;
"after compilation" means the best of repeated calls after a first, compiling one.
Timings on a shared machine are noisy: the load average is given below.

{_table(rows)}

## Machine

{machine}

{figs}
"""


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = only - set(COMPARISONS)
    if unknown:
        _parser().error(f"--only: unknown comparison(s) {sorted(unknown)}; choose from "
                        f"{','.join(COMPARISONS)}")
    settings = QUICK if args.quick else FULL
    args.out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()

    import _ensembles
    import _graphs
    import _plots
    import _processes
    import _single
    import _targets

    try:
        import numba  # noqa: F401
    except ImportError:
        print("note: numba is not installed, comparison 2 is skipped (pip install numba)")

    info = machine_info()
    progress(f"jaxchain benchmarks, {settings.name} run, {info['cores (usable)']} cores, "
             f"{info['CPU']}", start)
    rows, raw, figures = [], {"settings": dataclasses.asdict(settings), "machine": info}, []
    flag_ok, crashed = True, False

    def attempt(key: str, title: str, fn, *a):
        nonlocal crashed
        if key not in only:
            return None
        progress(f"{key}. {title}", start)
        try:
            out = fn(*a)
        except Exception as err:  # keep going; the row says what broke
            crashed = True
            traceback.print_exc()
            first_line = (str(err).splitlines() or [""])[0]
            rows.append(Row(f"{key}. {title}", "-", "-", "-",
                            f"CRASHED: {type(err).__name__}: {first_line}"))
            return None
        rows.extend(out[0])
        raw[key] = out[1]
        return out

    attempt("0", "the Fig. 4 ensemble before and now", _processes.compare_before_after,
            settings, ORIGINAL_ENV, start)
    attempt("1", "one trajectory against scipy LSODA", _single.compare_scipy, settings)
    attempt("2", "cost per step against numba", _single.compare_numba, settings)
    eng = attempt("3", "queue engine against the old vmap path",
                  _ensembles.compare_engines, settings, start)
    out = attempt("4", "time and memory against n_osc", _processes.compare_n_osc,
                  settings, ORIGINAL_ENV, start)
    if out:
        figures.append(_plots.plot_n_osc(out[1], args.out / "scaling_n_osc.png"))
    out = attempt("5", "time against ensemble size", _ensembles.compare_sizes, settings,
                  start)
    if out:
        figures.append(_plots.plot_sizes(out[1], args.out / "scaling_ensemble.png"))
    attempt("6", "sweep estimate", _ensembles.compare_sweep, settings,
            eng[1] if eng else None, args.sweep, start)
    out = attempt("7", "XLA flag check", _processes.flag_check, settings, ORIGINAL_ENV,
                  start)
    if out:
        flag_ok = out[2]
    attempt("8", "issue 24 targets against the previous defaults",
            _targets.compare_targets, settings, ORIGINAL_ENV, start)
    attempt("9", "cost per step on a coupling graph", _graphs.compare_graphs, settings)
    attempt("cli", "command line cold and warm start", _processes.compare_cli, settings,
            ORIGINAL_ENV, start)

    wall = time.perf_counter() - start
    info["load average at end (1, 5, 15 min)"] = ", ".join(
        f"{x:.2f}" for x in os.getloadavg())
    info["benchmark wall time"] = f"{wall / 60:.1f} min"
    (args.out / "benchmarks.md").write_text(
        _markdown(rows, info, settings, args, wall, figures))
    raw["wall_s"] = wall
    (args.out / "benchmarks.json").write_text(
        json.dumps(raw, indent=1, default=lambda o: o.tolist() if isinstance(
            o, np.ndarray) else str(o)))
    print()
    print(_table(rows))
    print()
    for k, v in info.items():
        print(f"{k}: {v}")
    print(f"\nwrote {args.out / 'benchmarks.md'}, benchmarks.json"
          + "".join(f", {f.name}" for f in figures))
    if not flag_ok:
        print("FAIL: jaxchain's XLA flag speeds the step loop up by less than 1.3x")
        return 1
    return 2 if crashed else 0


if __name__ == "__main__":
    sys.exit(main())
