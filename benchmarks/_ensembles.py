"""Comparisons 3, 5 and 6 of benchmarks/run.py: many trajectories over the CPU
devices (one per core), by the work-queue engine against the old vmapped lockstep
engine, and against the size of the ensemble."""

import time

import numpy as np

import jaxchain as jc
from jaxchain._engine.solver.registry import DEFAULT_SOLVER
from jaxchain._engine.lanes import run_lanes

from _common import (N_OSC, PAPER_T_END, PAPER_TRANSIENT, SWEEP_VDS, V_D, Row, Settings, cores,
                     fmt_ratio, fmt_time, progress)


def _fig4(v_d: float, t_end: float, transient: float, engine: str):
    """The Fig. 4 family (eq. (8), k = 1..20) at one belt speed: (dataset, wall)."""
    params = jc.ChainParams(n_osc=N_OSC, v_d=V_D)
    options = jc.SimulationOptions(t_end=t_end, transient=transient)
    start = time.perf_counter()
    ds = jc.ensemble(params, [v_d], jc.localized_family(N_OSC), options=options,
                     schedule=engine, progress=False)
    return ds, time.perf_counter() - start


def _us_per_step(wall: float, steps: int) -> float:
    """Wall time per step per core, in µs: the ensemble's throughput in the units of
    comparison 2."""
    return wall * cores() / steps * 1e6


def compare_engines(settings: Settings, start: float) -> tuple[list[Row], dict]:
    """3. The Fig. 4 ensemble (20 trajectories, v_d = 1.5) by the new queue engine
    against the old vmapped path, both after compilation (first calls reported
    apart), cold and warm calls interleaved. The two must give the same answers: each
    lane is the same compiled integration, only its scheduling differs."""
    t_end, transient = settings.ensemble
    runs = {}
    for phase in ("first", "warm"):
        for engine in ("queue", "vmap"):
            progress(f"  3. {engine} engine, {phase} call, t_end = {t_end:g}", start)
            runs[(engine, phase)] = _fig4(V_D, t_end, transient, engine)
    q, v = runs[("queue", "warm")], runs[("vmap", "warm")]
    steps = int(q[0]["num_steps"].sum())
    same_halc = bool(np.array_equal(q[0]["n_halc"].values, v[0]["n_halc"].values))
    same_steps = bool(np.array_equal(q[0]["num_steps"].values, v[0]["num_steps"].values))
    de = float(np.nanmax(np.abs(q[0]["energy"].values / v[0]["energy"].values - 1)))
    ok = bool(np.all(q[0]["status"].values == 0) and np.all(v[0]["status"].values == 0))
    v_steps = int(v[0]["num_steps"].sum())
    agree = ("bitwise equal" if de == 0 and same_halc and same_steps else
             f"n_HALC {'equal' if same_halc else 'DIFFER'}, max rel. energy diff {de:.1e}, "
             + ("steps equal" if same_steps else
                f"steps differ ({steps:,} queue, {v_steps:,} vmap)"))
    horizon = f"t_end {t_end:g}, transient {transient:g}"
    main = " (the paper's main job)" if t_end == PAPER_T_END else " (--quick horizon)"
    rows = [
        Row("3. Fig. 4 ensemble (20 traj.), wall after compilation",
            f"{fmt_time(v[1])} (vmap)", f"{fmt_time(q[1])} (queue)", fmt_ratio(v[1] / q[1]),
            f"N = 20, v_d = 1.5, eq. (8) k = 1..20, {horizon}{main}; {steps:,} steps "
            f"in all, {_us_per_step(q[1], steps):.2f} µs (queue) / "
            f"{_us_per_step(v[1], steps):.2f} µs (vmap) per step per core on {cores()} "
            f"cores. `run.py --only 3`"),
        Row("3. Fig. 4 ensemble, first call (compile + run)",
            f"{fmt_time(runs[('vmap', 'first')][1])} (vmap)",
            f"{fmt_time(runs[('queue', 'first')][1])} (queue)",
            fmt_ratio(runs[("vmap", "first")][1] / runs[("queue", "first")][1]),
            f"compile about {fmt_time(runs[('vmap', 'first')][1] - v[1])} (vmap), "
            f"{fmt_time(runs[('queue', 'first')][1] - q[1])} (queue)"),
        Row("3. engines agree", "vmap", "queue", "-",
            f"{agree}; n_HALC = {q[0]['n_halc'].values[0].tolist()}"
            + ("" if ok else "; SOME TRAJECTORIES FAILED")),
    ]
    raw = dict(t_end=t_end, transient=transient, steps=steps,
               walls_s={f"{e}_{p}": w for (e, p), (_, w) in runs.items()},
               n_halc=q[0]["n_halc"].values[0].tolist(), max_rel_energy_diff=de,
               same_steps=same_steps, all_ok=ok)
    return rows, raw


def _lanes(size: int, rng: np.random.Generator) -> np.ndarray:
    """`size` initial states: the Fig. 4 family at v_d = 1.5 tiled, each displacement
    perturbed by N(0, 0.01^2), so that no two lanes are the same trajectory."""
    params = jc.ChainParams(n_osc=N_OSC, v_d=V_D)
    family = jc.localized_family(N_OSC)
    states = np.stack([np.asarray(jc.OutOfPhaseExcitation.eq8(family.excited[k])(params))
                       for k in range(N_OSC)])
    y0 = states[np.arange(size) % N_OSC].copy()
    y0[:, 0] += 0.01 * rng.standard_normal((size, N_OSC))
    return y0


def compare_sizes(settings: Settings, start: float) -> tuple[list[Row], dict]:
    """5. Wall time against the number of trajectories (queue engine, after
    compilation: every size is called twice, the second call timed; a new size may
    compile a new block shape). The baseline of each size is running its steps one
    trajectory at a time at the cost per step of the single trajectory (size 1):
    steps(size) x wall(1) / steps(1), so that the ratio is what spreading the
    trajectories over the cores gains (ideally the number of cores), independent of
    which initial conditions the size happens to contain. The largest size is run
    only in the full run and only if its predicted wall fits the budget; otherwise
    it is extrapolated linearly from the per-trajectory cost of the largest measured
    size, and marked so."""
    t_end, transient = settings.sizes_horizon
    params = jc.ChainParams(n_osc=N_OSC, v_d=V_D)
    options = jc.SimulationOptions(t_end=t_end, transient=transient)
    solver = jc.SOLVERS[DEFAULT_SOLVER]()
    rng = np.random.default_rng(0)
    results = []
    for size in settings.sizes:
        y0 = _lanes(size, rng)
        vd = np.full(size, V_D)
        walls = []
        for _ in range(2):
            t0 = time.perf_counter()
            obs = run_lanes(jc.lane_params(params, size, v_d=vd), y0, solver, options,
                            schedule="queue")
            walls.append(time.perf_counter() - t0)
        failed = int(np.sum(np.asarray(obs.status) != 0))
        results.append(dict(size=size, wall_s=walls[1], first_s=walls[0], measured=True,
                            steps=int(np.sum(obs.num_steps)), failed=failed))
        progress(f"  5. {size:,} trajectories: {fmt_time(walls[1])} (first call "
                 f"{fmt_time(walls[0])})", start)
    per_traj = results[-1]["wall_s"] / results[-1]["size"]
    if settings.big_size:
        size = settings.big_size
        predicted = per_traj * size
        if predicted <= settings.big_size_budget_s:
            y0 = _lanes(size, rng)
            t0 = time.perf_counter()
            obs = run_lanes(params, y0, solver, options, schedule="queue")
            wall = time.perf_counter() - t0
            results.append(dict(size=size, wall_s=wall, first_s=wall, measured=True,
                                steps=int(np.sum(obs.num_steps)),
                                failed=int(np.sum(np.asarray(obs.status) != 0)),
                                note="one call, compilation included (about "
                                     f"{fmt_time(results[-1]['first_s'] - results[-1]['wall_s'])}"
                                     " at the previous size)"))
        else:
            steps = results[-1]["steps"] * size // results[-1]["size"]
            results.append(dict(size=size, wall_s=predicted, measured=False, steps=steps,
                                note=f"extrapolated: predicted {predicted:.0f} s > budget "
                                     f"{settings.big_size_budget_s:.0f} s"))
    per_step = results[0]["wall_s"] / results[0]["steps"]  # one trajectory alone
    rows = []
    for r in results:
        serial = per_step * r["steps"]
        r["serial_s"] = serial
        how = ("measured" if r["measured"] else "EXTRAPOLATED (linear from "
               f"{results[-2]['size']:,})")
        extra = f"; {r['note']}" if r.get("note") else ""
        fails = f"; {r['failed']} FAILED" if r.get("failed") else ""
        rows.append(Row(
            f"5. ensemble of {r['size']:,} trajector{'y' if r['size'] == 1 else 'ies'}, wall",
            f"{fmt_time(serial)} (serial)", f"{fmt_time(r['wall_s'])}",
            fmt_ratio(serial / r["wall_s"]),
            f"{how}; {r['size'] / r['wall_s']:,.0f} traj./s, {r['steps']:,} steps; "
            f"serial = steps x the single trajectory's cost per step (which carries "
            f"its call's fixed overhead alone, so the ratio may exceed the core count); "
            f"queue engine on "
            f"{cores()} cores, t_end {t_end:g}, transient {transient:g}, Fig. 4 family "
            f"tiled + N(0, 0.01²) on x{extra}{fails}. `run.py --only 5`"))
    return rows, dict(t_end=t_end, transient=transient, results=results)


def compare_sweep(settings: Settings, engines_raw: dict | None, run_sweep: bool,
                  start: float) -> tuple[list[Row], dict]:
    """6. The 420-trajectory sweep (21 belt speeds in [1, 2] x eq. (8) k = 1..20, t_end
    15000, transient 10000), estimated from a subsample of belt speeds x all 20
    initial conditions: the mean wall per belt speed times 21 (each speed is one
    20-lane ensemble, as comparison 3, so that no new shape compiles). The --quick
    subsample runs a shorter horizon and is scaled linearly to t_end = 15000. The
    baseline is the old vmap engine's estimate from the same subsample (optimistic
    for vmap: in one 420-lane batch every lane would wait for the slowest of 210).
    With `run_sweep` the sweep is also run directly (queue, compilation included)."""
    t_end, transient = settings.sweep_horizon
    walls = {"queue": [], "vmap": []}
    steps = 0
    same = bool(engines_raw) and (engines_raw["t_end"], engines_raw["transient"]) == (
        t_end, transient)
    compiled = {"queue", "vmap"} if same else set()  # by comparison 3, same shapes
    for vd in settings.sweep_vds:
        for engine in ("queue", "vmap"):
            reuse = same and vd == V_D
            if reuse:  # comparison 3 measured this belt speed already
                wall = engines_raw["walls_s"][f"{engine}_warm"]
                steps += engines_raw["steps"] if engine == "queue" else 0
            else:
                if engine not in compiled:
                    _fig4(vd, t_end, transient, engine)  # compile first, untimed
                    compiled.add(engine)
                ds, wall = _fig4(vd, t_end, transient, engine)
                steps += int(ds["num_steps"].sum()) if engine == "queue" else 0
            walls[engine].append(wall)
            progress(f"  6. v_d = {vd:g}, {engine}: {fmt_time(wall)}"
                     + (" (from comparison 3)" if reuse else ""), start)
    scale = len(SWEEP_VDS) / len(settings.sweep_vds) * PAPER_T_END / t_end
    est = {e: scale * sum(w) for e, w in walls.items()}
    target = 180.0
    met = "meets" if est["queue"] <= target else "MISSES"
    speeds = ", ".join(f"{v:g}" for v in settings.sweep_vds)
    sub = (f"{len(settings.sweep_vds)} belt speeds ({speeds}) x 20 ics at t_end {t_end:g}, "
           f"transient {transient:g}")
    scaled = "" if t_end == PAPER_T_END else f", scaled x{PAPER_T_END / t_end:g} in time"
    rows = [Row("6. sweep 21 v_d x 20 ics (420 traj., t_end 15000), ESTIMATE",
                f"{fmt_time(est['vmap'])} (vmap)", f"{fmt_time(est['queue'])} (queue)",
                fmt_ratio(est["vmap"] / est["queue"]),
                f"estimated from {sub}{scaled}; {met} the target of <= 3 min on "
                f"{cores()} cores; subsample {steps:,} steps. `run.py --only 6`")]
    raw = dict(subsample_vds=list(settings.sweep_vds), t_end=t_end, transient=transient,
               walls_s=walls, estimate_s=est, subsample_steps=steps)
    if run_sweep:
        progress("  6. the full sweep, queue engine (--sweep)", start)
        params = jc.ChainParams(n_osc=N_OSC, v_d=V_D)
        options = jc.SimulationOptions(t_end=PAPER_T_END, transient=PAPER_TRANSIENT)
        t0 = time.perf_counter()
        ds = jc.ensemble(params, SWEEP_VDS, jc.localized_family(N_OSC), options=options,
                         schedule="queue", progress=False)
        wall = time.perf_counter() - t0
        failed = int(np.sum(ds["status"].values != 0))
        rows.append(Row("6. sweep 21 v_d x 20 ics, MEASURED (--sweep)",
                        f"{fmt_time(est['vmap'])} (vmap estimate)", fmt_time(wall),
                        fmt_ratio(est["vmap"] / wall),
                        f"one call, compilation included; {int(ds['num_steps'].sum()):,} "
                        f"steps; {'meets' if wall <= target else 'MISSES'} the target"
                        + (f"; {failed} FAILED" if failed else "")))
        raw["measured_s"] = wall
    return rows, raw
