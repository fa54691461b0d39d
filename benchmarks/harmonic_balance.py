"""Harmonic balance against shooting on the single oscillator's stick-slip cycle
(v_d 1.5): amplitude and period error against the number of harmonics H, and the
time of one orbit solve by each method, measured in the same run.

    python benchmarks/harmonic_balance.py [--eps 1e-2,1e-3] [--harmonics 16,32,64,128]
    python benchmarks/harmonic_balance.py --ring [--harmonics 32,64]
    python benchmarks/harmonic_balance.py --coulomb [--harmonics 32,64,128]
    python benchmarks/harmonic_balance.py --jacobian [--harmonics 1,3,8]

--ring: the one-site state of the paper's ring of 20 at v_d 1.5, eps 1e-3 (the
snake's start for k = 1: eq. (8) simulated, then shot, `localized_branches`); the
largest amplitude error over the ring against shooting's, and the times as above.
--coulomb: the forced oscillator with Coulomb friction (xi 0.05, mu 0.3, F 1, v_d
0, eps 1e-4, M = 64 H) at Omega 0.6, 0.9, 1.0, 1.1, 1.5, and with stops (F 0.35)
at 0.6, 1.0, 1.5, against the exact motion by event-driven integration
(tests/test_forced.py, `coulomb_motion`): the amplitude's relative error.
--jacobian: the Jacobian of the residual on 256 forced mistuned rings of 20 with
friction dampers (`jaxchain magnification`'s chain, M = 64), vmapped: assembled
(`HarmonicBalance.jacobian`) against `jax.jacfwd` through the FFTs, the best of 3
after one that compiles, and their largest difference.

For each eps, shooting (`Shooting(Smoothed(eps).for_orbits())`, the reference) and
harmonic balance at each H solve the orbit from the same guess: shooting's orbit,
its state and period moved by 1e-3 relative. Errors are relative to shooting's
orbit (the largest amplitude error over the chain, relative to the largest
amplitude; a row that did not converge says so); times are the best of 3 solves
(1 on the ring) after one that compiles (`method.solve` on `method.unknowns`, the
guess's projection included for harmonic balance). Prints a Markdown table; the
ratio is shooting's time over harmonic balance's.
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


def _compared(label: str, params, reference, methods: dict, repeats: int = 3) -> list[str]:
    """Rows of the table: shooting (`methods["shooting"]`) and each other method solved
    from `reference` moved by 1e-3 relative; the largest amplitude error over the
    chain relative to the reference's largest amplitude, the period's relative
    error, the best time of `repeats` solves after one that compiles."""
    guess = (reference.y0 * (1 + 1e-3), reference.period * (1 + 1e-3))
    scale = float(np.max(reference.amplitudes))

    def solve(method):
        return lambda: method.solve(params, method.unknowns(params, *guess))[0]

    base = _best_time(solve(methods["shooting"]), repeats)
    out = [f"| {label} | shooting | yes | - | - | {base * 1e3:.1f} | 1 |"]
    for name, method in methods.items():
        if name == "shooting":
            continue
        orbit = jc.periodic_orbit(params, guess, method, throw=False)
        amplitude = float(np.max(np.abs(orbit.amplitudes - reference.amplitudes))) / scale
        period = abs(float(orbit.period / reference.period) - 1)
        seconds = _best_time(solve(method), repeats)
        out.append(f"| {label} | {name} | {'yes' if bool(orbit.converged) else 'no'} | "
                   f"{amplitude:.1e} | {period:.1e} | {seconds * 1e3:.1f} | "
                   f"{base / seconds:.3f} |")
    return out


def _harmonic_methods(shooting, harmonics: list[int], eps: float, **fields) -> dict:
    methods = {"shooting": shooting}
    for h in harmonics:
        for solver in ("blocks", "ring", "lu") if fields else ("blocks",):
            method = jc.HarmonicBalance(eps=eps, harmonics=h, linear_solver=solver, **fields)
            methods[f"H = {h} (M = {method.time_samples}), {solver}"] = method
    return methods


def rows(eps: float, harmonics: list[int]) -> list[str]:
    params = jc.ChainParams(n_osc=1, v_d=1.5)
    shooting = jc.Shooting(jc.Smoothed(eps=eps).for_orbits())
    reference = jc.periodic_orbit(params, (jc.Exact().steady_sliding(params) + 1.0, 6.3),
                                  shooting)
    return _compared(f"single, eps {eps:g}", params, reference,
                     _harmonic_methods(shooting, harmonics, eps))


def ring_rows(harmonics: list[int]) -> list[str]:
    params = jc.ChainParams(n_osc=20, v_d=1.5)
    found = jc.localized_branches(
        params, (1,), start_options=jc.SimulationOptions(t_end=3000.0, transient=2000.0),
        switch=False, simulation_check=False, continuation_options=jc.ContinuationOptions(
            ds=0.02, max_points=2, p_min=1.45, p_max=1.55))
    ds = found["datasets"]["k=1"]
    phase = int(ds.attrs["phase_oscillator"])
    (start,) = np.flatnonzero(ds["v_d"].values == ds.attrs["start_vd"])
    u = ds["u"].values[start]
    shooting = jc.Shooting(jc.Smoothed(eps=1e-3).for_orbits(), phase_oscillator=phase)
    reference = jc.periodic_orbit(params, (u[:-1].reshape(2, -1), float(u[-1])), shooting)
    return _compared("ring of 20, one site", params, reference,
                     _harmonic_methods(shooting, harmonics, 1e-3, phase_oscillator=phase),
                     repeats=1)


def coulomb_rows(harmonics: list[int]) -> list[str]:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import test_forced as forced  # the exact motion's construction

    out = []
    for force, omegas in ((1.0, (0.6, 0.9, 1.0, 1.1, 1.5)), (0.35, (0.6, 1.0, 1.5))):
        for omega in omegas:
            exact, stops = forced.coulomb_motion(omega, force)
            params = jc.ChainParams(n_osc=1, xi=forced.XI, v_d=0.0,
                                    friction=jc.Coulomb(forced.MU),
                                    forcing=jc.Forcing(force, omega))
            errors = []
            for h in harmonics:
                method = jc.HarmonicBalance(eps=1e-4, harmonics=h, time_samples=64 * h)
                orbit = jc.periodic_orbit(params, (np.zeros((2, 1)), 1.0), method, throw=False)
                errors.append(f"{abs(float(orbit.amplitudes[0]) / exact - 1):.1e}"
                              + ("" if bool(orbit.converged) else " (not converged)"))
            out.append(f"| F = {force:g}, Omega = {omega:g} | {exact:.6f} | "
                       f"{'yes' if stops else 'no'} | " + " | ".join(errors) + " |")
    return out


def jacobian_rows(harmonics: list[int]) -> list[str]:
    from jaxchain._studies.magnification import mistuned_lanes

    params = jc.ChainParams(n_osc=20, xi=2e-3, eta_c=0.01, v_d=0.0, friction=jc.Coulomb(mu=1e-3),
                            forcing=jc.Forcing.engine_order(20, 3, 4e-3, 1.0))
    chains = mistuned_lanes(params, 0.01, 255)
    out = []
    for h in harmonics:
        hb = jc.HarmonicBalance(eps=0.05, harmonics=h, time_samples=64, linear_solver="lu")
        u = jax.numpy.asarray(np.random.default_rng(0).standard_normal(
            (256, 20 * (2 * h + 1) + 1)) * 0.3).at[:, -1].set(2 * np.pi)
        assembled = jax.jit(jax.vmap(hb.jacobian))
        autodiff = jax.jit(jax.vmap(jax.jacfwd(hb._balance)))
        a = _best_time(lambda: assembled(u, chains))
        b = _best_time(lambda: autodiff(u, chains))
        gap = float(np.max(np.abs(assembled(u, chains) - autodiff(u, chains))))
        out.append(f"| {h} | {20 * (2 * h + 1) + 1} | {a * 1e3 / 256:.3f} | "
                   f"{b * 1e3 / 256:.3f} | {b / a:.2f} | {gap:.1e} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--eps", default="1e-2,1e-3", help="smoothings, comma-separated")
    parser.add_argument("--harmonics", default="16,32,64,128", help="H values")
    parser.add_argument("--ring", action="store_true", help="the ring of 20's one-site state")
    parser.add_argument("--coulomb", action="store_true",
                        help="the forced oscillator with Coulomb friction")
    parser.add_argument("--jacobian", action="store_true",
                        help="the assembled Jacobian against jax.jacfwd, vmapped")
    args = parser.parse_args()
    jc.configure()
    harmonics = [int(h) for h in args.harmonics.split(",")]
    orbit_columns = ["orbit", "method", "converged", "amplitude error", "period error",
                     "ms per orbit", "ratio"]
    if args.jacobian:
        _table(["H", "unknowns", "assembled, ms per ring", "jax.jacfwd, ms per ring", "ratio",
                "largest difference"], jacobian_rows(harmonics))
    elif args.coulomb:
        _table(["case", "exact amplitude", "stops", *(f"error at H = {h}" for h in harmonics)],
               coulomb_rows(harmonics))
    elif args.ring:
        _table(orbit_columns, ring_rows(harmonics))
    else:
        _table(orbit_columns, (row for eps in (float(e) for e in args.eps.split(","))
                               for row in rows(eps, harmonics)))


def _table(columns: list[str], rows) -> None:
    """A Markdown table: its header, then each row as it is computed."""
    print("| " + " | ".join(columns) + " |")
    print("|---" * len(columns) + "|")
    for row in rows:
        print(row, flush=True)

if __name__ == "__main__":
    main()
