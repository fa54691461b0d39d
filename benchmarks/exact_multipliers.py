"""The exact Floquet multipliers of the one-site localized state of the N = 20 ring at
v_d = 1.5 (eq. (8) with one oscillator excited), and those of the smoothed model at
eps 1e-3, 1e-4 and 1e-5 approaching them.

The start is the landed snake's (`start_orbits`: simulation of the smoothed model,
then shooting); the exact orbit is solved by shooting on the exact engine from it
(`periodic_orbit` with `Shooting(Exact().for_orbits())`), and the smoothed orbits by
shooting at each eps (`Shooting` on `Smoothed(Kvaerno5(), eps=eps)`), each from the
orbit at the eps before, the first from the exact orbit. Prints the exact orbit
(period, n_HALC, how many multipliers are zero from stick), the multipliers of
largest modulus other than the trivial one for each model, and the distance of each
smoothed set from the exact one (each exact multiplier matched to the nearest
smoothed one, among those of modulus above 1e-3). Run:
`python benchmarks/exact_multipliers.py`.
"""

import time

import diffrax
import numpy as np

import jaxchain as jc
from jaxchain._studies.snake.starts import start_orbits  # the landed snake's starts

jc.configure()  # float64, one CPU device per core, the XLA flags

EPS = (1e-3, 1e-4, 1e-5)


def _leading(multipliers, trivial: int, count: int = 4) -> np.ndarray:
    """The `count` multipliers of largest modulus other than the trivial one."""
    m = np.delete(np.asarray(multipliers), trivial)
    return m[np.argsort(-np.abs(m))][:count]


def _distance(exact: np.ndarray, smoothed: np.ndarray) -> float:
    """Largest distance from a non-zero exact multiplier to its nearest smoothed
    one."""
    exact = exact[np.abs(exact) > 1e-3]
    return float(max(np.min(np.abs(smoothed - e)) for e in exact))


def main() -> None:
    params = jc.ChainParams(n_osc=20, v_d=1.5)
    start = time.perf_counter()
    orbit, sim, reason = start_orbits(params, sites=(1,))[1]
    if orbit is None:
        raise SystemExit(f"no one-site start: {reason}")
    n = int(np.argmax(np.asarray(orbit.amplitudes)))
    exact = jc.periodic_orbit(params, (orbit.y0, float(orbit.period)),
                              jc.Shooting(jc.Exact().for_orbits(), phase_oscillator=n))
    if not bool(exact.converged):
        raise SystemExit(f"exact shooting did not converge (residual {float(exact.residual):.2g})")
    exact_m = np.asarray(exact.multipliers)
    print(f"exact one-site orbit: period {float(exact.period):.10f}, n_HALC "
          f"{int(exact.n_halc)}, energy {float(exact.energy):.8f}, residual "
          f"{float(exact.residual):.1e}; {int(exact.zero_multipliers)} multipliers at zero "
          f"(stick), trivial {exact_m[int(exact.trivial)]:.10f}")
    print("leading exact:", np.array2string(_leading(exact_m, int(exact.trivial)),
                                            precision=8))
    # each eps from the orbit at the one before (the first from the exact orbit), with
    # an implicit solver (eps 1e-5 is too stiff for shooting's explicit Tsit5), at
    # shooting's tolerances; Newton's method alone (no damped fallback), as before
    flow = jc.SimulationOptions(rtol=1e-10, atol=1e-12, max_steps=1_000_000)
    previous = exact
    for eps in EPS:
        shooting = jc.Shooting(jc.Smoothed(diffrax.Kvaerno5(), flow, eps=eps),
                               phase_oscillator=n, damped_steps=0)
        smoothed = jc.periodic_orbit(params, (previous.y0, float(previous.period)), shooting,
                                     throw=False)
        previous = smoothed
        m = np.asarray(smoothed.multipliers)
        trivial = int(np.argmin(np.abs(m - 1)))
        distance = _distance(np.delete(exact_m, int(exact.trivial)), np.delete(m, trivial))
        print(f"eps {eps:g}: period {float(smoothed.period):.10f} (exact "
              f"{float(smoothed.period) - float(exact.period):+.1e}), converged "
              f"{bool(smoothed.converged)}; leading "
              f"{np.array2string(_leading(m, trivial), precision=8)}; distance from the "
              f"exact set {distance:.2e}")
    print(f"wall {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
