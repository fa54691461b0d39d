"""The window length of the identification's multiple shooting, chosen by measurement:
the example rig's three records (examples/records: one oscillator, eq. (1) with
mu_st = 1.1, mu_d = 0.6, v0 = 0.35, xi = 0.04, 60 time units every 0.1, 0.5 % noise)
fitted with windows of several lengths, from the default starting values and from
starts perturbed by -40 % and +60 % on every parameter.

    python benchmarks/identification_windows.py [--windows 2.5,5,10,20,60] [--out DIR]

A start counts as found when Levenberg-Marquardt converges and every parameter lies
within 3 standard errors of the truth. Prints a table (found starts, the largest
relative error, iterations and wall time per window length, compilation included
in the first start of each) and writes DIR/identification_windows.md.
"""

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import jaxchain as jc

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "records"))
from make_records import TRUE  # noqa: E402

STARTS = {"default": None, "-40 %": 0.6, "+60 %": 1.6}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--windows", default="2.5,5,10,20,60")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks")
    args = parser.parse_args()
    jc.configure()
    records = [jc.read_record(p) for p in sorted((ROOT / "examples" / "records").glob("*.csv"))]
    chain = jc.ChainParams(n_osc=1)
    rows = []
    for window in (float(w) for w in args.windows.split(",")):
        found, errors, iterations, walls = 0, [], [], []
        for name, factor in STARTS.items():
            start = None if factor is None else {k: v * factor for k, v in TRUE.items()}
            if start is not None:  # keep mu_st above mu_d
                start["mu_st"] = max(start["mu_st"], 1.2 * start["mu_d"])
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = jc.identify(records, chain, start=start,
                                  options=jc.IdentifyOptions(window=window))
            walls.append(time.perf_counter() - t0)
            truth = np.array([TRUE[label] for label in fit.labels])
            z = np.abs(fit.values - truth) / fit.standard_errors
            found += bool(fit.converged and np.all(z < 3))
            errors.append(float(np.max(np.abs(fit.values / truth - 1))))
            iterations.append(fit.iterations)
            print(f"window {window:g}, start {name}: converged {fit.converged}, max |z| "
                  f"{z.max():.2f}, max error {errors[-1]:.2%}, {fit.iterations} iterations, "
                  f"{walls[-1]:.1f} s", flush=True)
        rows.append((window, found, max(errors), iterations, walls))
    lines = ["| window | starts found (of 3) | largest error | iterations | wall time (s) |",
             "| --- | --- | --- | --- | --- |"]
    for window, found, error, iterations, walls in rows:
        lines.append(f"| {window:g} | {found} | {error:.2%} | "
                     f"{', '.join(map(str, iterations))} | "
                     f"{', '.join(f'{w:.1f}' for w in walls)} |")
    table = "\n".join(lines)
    print(table)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "identification_windows.md").write_text(
        "# Window length of the identification\n\n"
        "Written by `python benchmarks/identification_windows.py` (see its docstring).\n\n"
        + table + "\n")


if __name__ == "__main__":
    main()
