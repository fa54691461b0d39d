"""Comparisons 1 and 2 of benchmarks/run.py: one trajectory of the benchmark scene
(N = 20, v_d = 1.5, eq. (8) with k = 5) against scipy's LSODA, and the cost of
one step against hand-written numba loops of the same tableaux."""

import numpy as np
from scipy.integrate import solve_ivp

import jaxchain as jc
from jaxchain._physics.forces import DEFAULT_EPS
from jaxchain._engine.solver.registry import DEFAULT_SOLVER

from _common import Row, Settings, fmt_ratio, fmt_time, scene, simulate_once, timed


def numpy_model(params: jc.ChainParams, eps: float = DEFAULT_EPS):
    """Eq. (5) on the ring with NumPy, vectorised over the oscillators, written here
    independently of jaxchain, smoothed by tanh(v_rel/eps): (rhs(t, y), jac(t, y))
    for the flat state y = (x_1..x_N, x_1'..x_N')."""
    n = params.n_osc
    xi, eta, vd = (float(getattr(params, f)) for f in ("xi", "eta_c", "v_d"))
    eps = float(eps)
    mu_d, mu_st, v0 = (float(getattr(params.friction, f)) for f in ("mu_d", "mu_st", "v0"))
    eye = np.eye(n)
    stiffness = -(1 + 2 * eta) * eye + eta * (np.roll(eye, 1, 0) + np.roll(eye, -1, 0))

    def rhs(t, y):
        x, v = y[:n], y[n:]
        vr = v - vd
        mu = mu_d + (mu_st - mu_d) * np.exp(-np.abs(vr) / v0)
        a = (-2 * xi * v - x - eta * (2 * x - np.roll(x, 1) - np.roll(x, -1))
             - mu * np.tanh(vr / eps))
        return np.concatenate([v, a])

    def jac(t, y):
        vr = y[n:] - vd
        e = np.exp(-np.abs(vr) / v0)
        mu = mu_d + (mu_st - mu_d) * e
        th = np.tanh(vr / eps)
        dmu = -(mu_st - mu_d) / v0 * np.sign(vr) * e
        out = np.zeros((2 * n, 2 * n))
        out[:n, n:] = eye
        out[n:, :n] = stiffness
        out[n:, n:] = np.diag(-2 * xi - dmu * th - mu * (1 - th**2) / eps)
        return out

    return rhs, jac


#: LSODA's tolerances: at jaxchain's rtol 3e-5 its E is 2.8 % off (6.368 against
#: 6.192); at 1e-5 it agrees within 0.6 %, so the comparison is at the same answer.
LSODA_RTOL, LSODA_ATOL = 1e-5, 1e-7


def lsoda(params, y0: np.ndarray, options: jc.SimulationOptions,
          eps: float = DEFAULT_EPS) -> dict:
    """scipy's LSODA on [0, t_end] at `LSODA_RTOL` with the analytic Jacobian and
    dense output, smoothed by `eps`; the amplitudes from the dense output sampled
    every `options.sample_dt` over [transient, t_end], as jaxchain samples."""
    rhs, jac = numpy_model(params, eps)
    sol, wall = timed(solve_ivp, rhs, (0.0, options.t_end), y0, method="LSODA",
                      rtol=LSODA_RTOL, atol=LSODA_ATOL, jac=jac, dense_output=True)
    ts = np.arange(options.transient, options.t_end, options.sample_dt)
    ts = np.append(ts, options.t_end)
    x = sol.sol(ts)[:params.n_osc]
    amplitudes = 0.5 * (x.max(1) - x.min(1))
    return dict(wall=wall, energy=float(0.5 * np.sum(amplitudes**2)), status=sol.status,
                steps=len(sol.t) - 1, nfev=sol.nfev, njev=sol.njev)


def compare_scipy(settings: Settings) -> tuple[list[Row], dict]:
    """1. One trajectory, jaxchain (default solver, after compilation, best of
    `settings.repeats`) against scipy's LSODA (best of 2, interleaved with jaxchain),
    at the same eps and tolerances. Also checks that both give the same energy E =
    1/2 sum A_n^2 (within 2 %): the speed is worth nothing if the answer differs."""
    t_end, transient = settings.single
    params, ic, options = scene(t_end, transient)
    solver = jc.SOLVERS[DEFAULT_SOLVER]()
    y0 = np.asarray(ic(params)).reshape(-1)
    obs, first = simulate_once(params, ic, solver, options)
    jax_walls, scipy_runs = [], []
    for r in range(max(settings.repeats, 2)):
        jax_walls.append(simulate_once(params, ic, solver, options)[1])
        if r < 2:
            scipy_runs.append(lsoda(params, y0, options))
    best = min(jax_walls)
    ref = min(scipy_runs, key=lambda d: d["wall"])
    rel = abs(float(obs.energy) / ref["energy"] - 1)
    horizon = f"t in [0, {t_end:g}], observed after {transient:g}"
    agree = "OK" if rel <= 0.02 else "DIFFERS (> 2 %)"
    rows = [
        Row("1. one trajectory, wall (after compilation)",
            f"{fmt_time(ref['wall'])} (scipy LSODA, {ref['steps']:,} steps)",
            f"{fmt_time(best)} ({DEFAULT_SOLVER}, {int(obs.num_steps):,} steps)",
            fmt_ratio(ref["wall"] / best),
            f"N = 20, v_d = 1.5, eq. (8) k = 5, {horizon}; jaxchain at rtol "
            f"{options.rtol:g}, atol {options.atol:g}, LSODA at rtol {LSODA_RTOL:g}, atol "
            f"{LSODA_ATOL:g} (the same E), eps {DEFAULT_EPS:g}. LSODA with a "
            f"vectorised NumPy RHS and its analytic Jacobian (without it about 3x "
            f"slower); best of 2 vs best of {len(jax_walls)}; target >= 600x: "
            f"{'met' if ref['wall'] / best >= 600 else 'MISSED'}. `run.py --only 1`"),
        Row("1. one trajectory, first call (compile + run)", "-", fmt_time(first), "-",
            f"jaxchain compile time about {fmt_time(first - best)}"),
        Row("1. energy E = 1/2 sum A_n^2", f"{ref['energy']:.5f}", f"{float(obs.energy):.5f}",
            f"rel. diff {rel:.2e}",
            f"{agree}; scipy amplitudes from its dense output every "
            f"{options.sample_dt:g}; jaxchain n_HALC = {int(obs.n_halc)}"),
    ]
    raw = dict(t_end=t_end, transient=transient, jax_first_s=first, jax_walls_s=jax_walls,
               jax_steps=int(obs.num_steps), jax_energy=float(obs.energy),
               scipy=scipy_runs, energy_rel_diff=rel)
    return rows, raw


def compare_numba(settings: Settings) -> tuple[list[Row], dict]:
    """2. The cost of one step: jaxchain's compiled diffrax loop (wall / num_steps,
    after compilation) against numba loops of the same tableau and the same step-size
    controller (`_numba_solvers`) on the same trajectory, for ROS34PW2 and Bosh3.
    Both sides are timed alternately, best of `settings.repeats`. This isolates the
    overhead of diffrax/XLA per step from the number of steps."""
    try:
        import _numba_solvers as nb
    except ImportError:
        note = "skipped: numba is not installed (pip install numba)"
        print(f"  {note}")
        return [Row("2. cost per step vs numba", "-", "-", "-", note)], dict(skipped=note)
    t_end, transient = settings.single
    params, ic, options = scene(t_end, transient)
    y0 = np.asarray(ic(params)).reshape(-1)
    tiny = jc.SimulationOptions(t_end=2.0, transient=1.0)
    rows, raw = [], {}
    for name in ("ros34pw2", "bosh3"):
        _, numba_compile = timed(nb.integrate, name, y0, params, tiny)
        solver = jc.SOLVERS[name]()
        obs, first = simulate_once(params, ic, solver, options)
        nb_runs, jax_walls = [], []
        for _ in range(settings.repeats):
            out, wall = timed(nb.integrate, name, y0, params, options)
            nb_runs.append((wall, out))
            jax_walls.append(simulate_once(params, ic, solver, options)[1])
        nb_wall, nb_out = min(nb_runs, key=lambda r: r[0])
        jax_wall = min(jax_walls)
        nb_us = nb_wall / nb_out["num_steps"] * 1e6
        jax_us = jax_wall / int(obs.num_steps) * 1e6
        rows.append(Row(
            f"2. µs per step, {name}",
            f"{nb_us:.2f} µs (numba, {nb_out['num_steps']:,} steps)",
            f"{jax_us:.2f} µs ({int(obs.num_steps):,} steps)",
            fmt_ratio(nb_us / jax_us),
            f"same tableau and I-controller, t in [0, {t_end:g}]; numba: extrema at "
            f"step ends only (E = {nb_out['energy']:.4f} vs {float(obs.energy):.4f}), "
            f"scalar libm exp/tanh; first call {fmt_time(numba_compile)} (numba, "
            f"compiled or loaded from its disk cache), {fmt_time(first)} (jaxchain"
            f"{', compiled by 1 already' if first < 2 * jax_wall + 0.5 else ''}). "
            f"`run.py --only 2`"))
        raw[name] = dict(numba_walls_s=[w for w, _ in nb_runs], numba_steps=nb_out["num_steps"],
                         numba_energy=nb_out["energy"], numba_status=nb_out["status"],
                         numba_compile_s=numba_compile, jax_walls_s=jax_walls,
                         jax_first_s=first, jax_steps=int(obs.num_steps),
                         jax_energy=float(obs.energy), numba_us=nb_us, jax_us=jax_us)
    return rows, raw
