"""The smoothing's bias of the identification, and the honesty of its standard errors,
on the example rig (examples/records/make_records.py: one oscillator, eq. (1) with
mu_st = 1.1, mu_d = 0.6, v0 = 0.35, xi = 0.04, belt speeds 0.4, 0.7, 1.0).

    python benchmarks/identification_bias.py bias [--eps 1e-3,1e-4,1e-5]
    python benchmarks/identification_bias.py coverage [--draws 26]

`bias`: noise-free records of 60 time units every 0.1 from the non-smooth reference,
fitted at each eps: the relative error of each parameter (the smoothing's bias; the
fit is of the smoothed model, the records of the exact switch model).

`coverage`: records of 20 time units every 0.2 (those of tests/test_identify.py) with
noise of 0.5 % of the amplitude, fitted under `--draws` noise draws: how often the
+-2 standard-error intervals cover the true values (95.4 % expected) and the
z-scores' root mean square (1 expected).
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
from make_records import SPEEDS, TRUE  # noqa: E402


def rig() -> jc.ChainParams:
    law = jc.ExponentialDecay(mu_st=TRUE["mu_st"], mu_d=TRUE["mu_d"], v0=TRUE["v0"])
    return jc.ChainParams(n_osc=1, xi=TRUE["xi"], friction=law)


def fit(records, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return jc.identify(records, jc.ChainParams(n_osc=1),
                           options=jc.IdentifyOptions(**options))


def bias(eps_values) -> None:
    records = [jc.reference_record(rig(), v, 60.0, 0.1) for v in SPEEDS]
    print("| eps | " + " | ".join(TRUE) + " |\n| --- |" + " --- |" * len(TRUE))
    for eps in eps_values:
        result = fit(records, eps=eps)
        errors = [f"{value / TRUE[label] - 1:+.2e}"
                  for label, value in zip(result.labels, result.values)]
        print(f"| {eps:g} | " + " | ".join(errors) + " |", flush=True)


def coverage(draws: int) -> None:
    clean = [jc.reference_record(rig(), v, 20.0, 0.2) for v in SPEEDS]
    rng = np.random.default_rng(1)
    z = []
    for draw in range(draws):
        records = []
        for rec in clean:
            amplitude = 0.5 * (rec.x.max(axis=0) - rec.x.min(axis=0))
            records.append(jc.Record(t=rec.t, x=rec.x + 0.005 * amplitude
                                     * rng.standard_normal(rec.x.shape),
                                     oscillators=rec.oscillators, v=None, v_d=rec.v_d,
                                     source=rec.source))
        t0 = time.perf_counter()
        result = fit(records)
        truth = np.array([TRUE[label] for label in result.labels])
        z.append((result.values - truth) / result.standard_errors)
        print(f"draw {draw}: z = {np.round(z[-1], 2)}, {time.perf_counter() - t0:.1f} s",
              flush=True)
    z = np.asarray(z)
    print(f"covered by +-2 standard errors: {np.sum(np.abs(z) < 2)} of {z.size} "
          f"({np.mean(np.abs(z) < 2):.1%}; 95.4 % expected); root mean square of z "
          f"{np.sqrt(np.mean(z**2)):.2f} (1 expected)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("bias", "coverage"))
    parser.add_argument("--eps", default="1e-3,1e-4,1e-5")
    parser.add_argument("--draws", type=int, default=26)
    args = parser.parse_args()
    jc.configure()
    if args.what == "bias":
        bias([float(e) for e in args.eps.split(",")])
    else:
        coverage(args.draws)


if __name__ == "__main__":
    main()
