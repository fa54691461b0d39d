"""Harmonic balance against shooting on the single oscillator's stick-slip cycle
(v_d 1.5): amplitude and period error against the number of harmonics H, and the
time of one orbit solve by each method, measured in the same run.

    python benchmarks/harmonic_balance.py [--eps 1e-2,1e-3] [--harmonics 16,32,64,128]

For each eps, shooting (`Shooting(Smoothed(eps).for_orbits())`, the reference) and
harmonic balance at each H solve the orbit from the same guess: shooting's orbit,
its state and period moved by 1e-3 relative. Errors are relative to shooting's
orbit (a row that did not converge says so); times are the best of 3 solves after one that compiles (`method.solve` on
`method.unknowns`, the guess's projection included for harmonic balance). Prints
a Markdown table; the ratio is shooting's time over harmonic balance's.
"""

import argparse
import time

import jax
import numpy as np

import jaxchain as jc


def _best_time(fn, repeats: int = 3) -> float:
    jax.block_until_ready(fn())  # compiles
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return min(times)


def rows(eps: float, harmonics: list[int]) -> list[str]:
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    shooting = jc.Shooting(jc.Smoothed(eps=eps).for_orbits())
    reference = jc.periodic_orbit(params, (jc.Exact().steady_sliding(params) + 1.0, 6.3),
                                  shooting)
    guess = (reference.y0 * (1 + 1e-3), reference.period * (1 + 1e-3))

    def solve(method):
        return lambda: method.solve(params, method.unknowns(params, *guess))[0]

    base = _best_time(solve(shooting))
    out = [f"| {eps:g} | shooting | yes | - | - | {base * 1e3:.1f} | 1 |"]
    for h in harmonics:
        method = jc.HarmonicBalance(eps=eps, harmonics=h)
        orbit = jc.periodic_orbit(params, guess, method, throw=False)
        amplitude = abs(float(orbit.amplitudes[0] / reference.amplitudes[0]) - 1)
        period = abs(float(orbit.period / reference.period) - 1)
        seconds = _best_time(solve(method))
        converged = "yes" if bool(orbit.converged) else "no"
        out.append(f"| {eps:g} | H = {h} (M = {method.time_samples}) | {converged} | "
                   f"{amplitude:.1e} | {period:.1e} | {seconds * 1e3:.1f} | "
                   f"{base / seconds:.2f} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--eps", default="1e-2,1e-3", help="smoothings, comma-separated")
    parser.add_argument("--harmonics", default="16,32,64,128", help="H values")
    args = parser.parse_args()
    jc.configure()
    print("| eps | method | converged | amplitude error | period error | ms per orbit | "
          "ratio |")
    print("|---|---|---|---|---|---|---|")
    for eps in (float(e) for e in args.eps.split(",")):
        for row in rows(eps, [int(h) for h in args.harmonics.split(",")]):
            print(row, flush=True)


if __name__ == "__main__":
    main()
