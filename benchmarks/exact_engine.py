"""Both engines on the paper's Fig. 4 scene (N = 20, v_d = 1.5, eq. (8) rows k = 1..20,
t in [0, 15000], observed after 10000), in one run: the smoothed engine at its
defaults and the exact engine at its defaults, each as an ensemble over the CPU
cores, and the non-smooth reference (`NonsmoothOptions.reference`: the exact engine
at rtol = atol = 1e-12), row by row. Each ensemble runs twice, and the second run's
wall time (compiled already) is compared; the first run's, with compilation, is
printed too.

Prints the ratio exact / smoothed of the wall times, each row's n_HALC on the three
runs, and the largest amplitude error of each engine against the reference over
the rows that are periodic (the reference's two halves of the window agree to
1e-6, `half_difference`). Run: `python benchmarks/exact_engine.py [--quick] [--pairs]`
(--quick: t in [0, 3000], observed after 2000; --pairs: first the table of the
exact engine's Runge-Kutta pairs and tolerances, one trajectory of rows k = 1
and 3 over [0, 3000] against Dopri8 at 1e-13, by which its defaults were chosen).
Exits with status 1 if the exact
engine is slower than the smoothed one, or if its n_HALC or periodic amplitudes
differ from the reference's by more than 1e-5.
"""

import argparse
import sys
import time

import numpy as np

import jaxchain as jc

jc.configure()  # float64, one CPU device per core, the XLA flags


def _timed(run):
    start = time.perf_counter()
    run()  # the first run, with compilation
    cold = time.perf_counter() - start
    start = time.perf_counter()
    ds = run()
    return ds, cold, time.perf_counter() - start


#: The pairs and tolerances of the table of `pairs`.
PAIRS = (("dopri8", 1e-12), ("tsit5", 1e-12), ("dopri5", 1e-12), ("dopri5", 1e-8),
         ("dopri5", 1e-7), ("tsit5", 1e-8), ("tsit5", 1e-7))


def pairs() -> None:
    """Largest amplitude error against Dopri8 at 1e-13 and wall time (compiled) of
    one trajectory of rows k = 1 and 3, for each of `PAIRS`."""
    chain = jc.ChainParams()
    for k in (1, 3):
        y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(20, k))
        best = jc.NonsmoothOptions(t_end=3000.0, transient=2000.0, rtol=1e-13, atol=1e-13,
                                   solver="dopri8")
        ref = np.asarray(jc.simulate(chain, y0, engine=jc.Exact(best)).amplitudes)
        for solver, rtol in PAIRS:
            options = jc.NonsmoothOptions(t_end=3000.0, transient=2000.0, rtol=rtol,
                                          atol=rtol, solver=solver)
            _, _, wall = _timed(lambda: jc.simulate(chain, y0, engine=jc.Exact(options)))
            error = np.abs(np.asarray(jc.simulate(chain, y0, engine=jc.Exact(options)).amplitudes)
                           - ref).max()
            print(f"k = {k}: {solver} at {rtol:g}: error {error:.1e}, wall {wall:.3f} s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="t_end 3000, transient 2000")
    parser.add_argument("--pairs", action="store_true",
                        help="first the table of Runge-Kutta pairs and tolerances")
    args = parser.parse_args(argv)
    if args.pairs:
        pairs()
    t_end, transient = (3000.0, 2000.0) if args.quick else (15000.0, 10000.0)
    chain, starts = jc.ChainParams(), jc.localized_family(20)
    smoothed = jc.Smoothed(options=jc.SimulationOptions(t_end=t_end, transient=transient))
    exact = jc.Exact(jc.NonsmoothOptions(t_end=t_end, transient=transient))
    runs = {}
    for name, engine in (("smoothed", smoothed), ("exact", exact)):
        runs[name] = _timed(lambda engine=engine: jc.ensemble(chain, [1.5], starts,
                                                              engine=engine, progress=False))
        ds, cold, warm = runs[name]
        print(f"{name:9s} wall {warm:7.2f} s (first run, with compilation, {cold:.2f} s)")
    options = jc.NonsmoothOptions.reference(t_end=t_end, transient=transient)
    rows = [jc.simulate(chain, jc.OutOfPhaseExcitation.eq8(jc.excited_block(20, k)),
                        engine=jc.Exact(options)) for k in range(1, 21)]
    ref = {"n_halc": np.array([int(r.n_halc) for r in rows]),
           "amplitudes": np.stack([np.asarray(r.amplitudes) for r in rows])}
    periodic = np.array([float(r.half_difference) < 1e-6 for r in rows])
    ok = True
    for name in ("smoothed", "exact"):
        ds = runs[name][0].isel(v_d=0)
        same = ds["n_halc"].values == ref["n_halc"]
        error = np.abs(ds["amplitudes"].values - ref["amplitudes"]).max(-1)
        worst = error[periodic].max() if periodic.any() else np.nan
        print(f"{name:9s} n_HALC {ds['n_halc'].values.tolist()}; rows equal to the "
              f"reference {int(same.sum())}/20; periodic rows {int(periodic.sum())}, "
              f"largest amplitude error there {worst:.2e}")
        if name == "exact":
            ok &= bool(same[periodic].all()) and worst <= 1e-5
    ratio = runs["exact"][2] / runs["smoothed"][2]
    print(f"reference n_HALC {ref['n_halc'].tolist()}; periodic rows (k) "
          f"{(np.flatnonzero(periodic) + 1).tolist()}")
    print(f"exact / smoothed wall time: {ratio:.2f}")
    ok &= ratio <= 1.0
    print("as required" if ok else "NOT AS REQUIRED: exact slower than smoothed, or off "
          "the reference by more than 1e-5 on a periodic row")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
