"""Comparison 8 of benchmarks/run.py: the targets of issue 24 (fewer steps, less
fixed cost), each against the previous defaults or a bare import measured in the
same run."""

import subprocess
import sys
import time

from _common import PAPER_T_END, Row, Settings, fmt_ratio, fmt_time, progress
from _processes import _child, _without_xla_flags

#: the previous defaults: ROS34PW2 with diffrax's integral controller at rtol 1e-5.
OLD_DEFAULTS = ("--rtol", "1e-5", "--atol", "1e-7", "--controller", "diffrax")
#: Belt speeds of the Fig. 3(b) sweep (21 in [1, 2]).
N_SWEEP_VDS = 21


def _import_time(code: str, env: dict, repeats: int = 3) -> float:
    """Best wall time of a fresh `python -c code`."""
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], env=env, check=True, timeout=300)
        walls.append(time.perf_counter() - t0)
    return min(walls)


def compare_targets(settings: Settings, env: dict, start: float) -> tuple[list[Row], dict]:
    """8. The Fig. 4 scene and the sweep subsample of comparison 6 (belt speeds
    `settings.sweep_vds`, 20 trajectories each, the horizon `settings.sweep_horizon`)
    at the previous defaults and at today's, each belt speed in its own process
    (compiled by a first call, then timed); steps at v_d = 1.5 are the Fig. 4 scene's.
    The sweep estimate is the sum over the subsample times 21 / (its size), scaled
    linearly to t_end 15000 in --quick. Then `import jaxchain` against `import jax,
    diffrax` (best of 3 fresh processes)."""
    t_end, transient = settings.sweep_horizon
    base_env = _without_xla_flags(env)
    common = ("--fig4", "--n-osc", "20", "--t-end", str(t_end), "--transient", str(transient))
    runs = {"old": {}, "new": {}}
    for vd in settings.sweep_vds:
        for name, extra in (("old", OLD_DEFAULTS), ("new", ())):
            runs[name][vd] = _child(base_env, *common, "--vd", str(vd), *extra, timeout=3600)
            progress(f"  8. v_d = {vd:g}, {name} defaults: "
                     f"{fmt_time(runs[name][vd]['warm_s'])}, {runs[name][vd]['steps']:,} steps",
                     start)
    old, new = runs["old"][1.5], runs["new"][1.5]
    expected = list(range(1, 19)) + [20, 20]
    stairs = {k: r["n_halc"] == expected for k, r in (("old", old), ("new", new))}
    horizon = f"t_end {t_end:g}, transient {transient:g}"
    steps_target = old["steps"] / 2
    scale = N_SWEEP_VDS / len(settings.sweep_vds) * PAPER_T_END / t_end
    sweep = {k: scale * sum(r["warm_s"] for r in runs[k].values()) for k in runs}
    rows = [
        Row("8. steps of the Fig. 4 scene (20 traj.)",
            f"{old['steps']:,} (rtol 1e-5, diffrax's controller)",
            f"{new['steps']:,} (rtol {new['rtol']:g}, {new['controller']})",
            fmt_ratio(old["steps"] / new["steps"]),
            f"{horizon}; target <= half the baseline ({steps_target:,.0f}): "
            f"{'met' if new['steps'] <= steps_target else 'MISSED'}; staircase n_HALC = "
            f"1..18, 20, 20: {'holds' if stairs['new'] else 'DIFFERS'} (baseline: "
            f"{'holds' if stairs['old'] else 'differs'}). `run.py --only 8`"),
        Row("8. Fig. 4 scene, wall after compilation", fmt_time(old["warm_s"]),
            fmt_time(new["warm_s"]), fmt_ratio(old["warm_s"] / new["warm_s"]),
            f"{horizon}, queue engine, own processes"),
        Row("8. Fig. 3(b) sweep 21 v_d x 20 ics, ESTIMATE", fmt_time(sweep["old"]),
            fmt_time(sweep["new"]), fmt_ratio(sweep["old"] / sweep["new"]),
            f"from v_d = {', '.join(f'{v:g}' for v in settings.sweep_vds)} x 20 ics at "
            f"{horizon}, x{scale:g}; target <= 180 s: "
            f"{'met' if sweep['new'] <= 180 else 'MISSED'}"),
    ]
    progress("  8. import times", start)
    bare = _import_time("import jax, diffrax", base_env)
    ours = _import_time("import jaxchain", base_env)
    rows.append(Row("8. import jaxchain, whole process", f"{fmt_time(bare)} (import jax, "
                    "diffrax)", fmt_time(ours), f"{ours / bare:.2f} (jaxchain / bare)",
                    f"best of 3 fresh processes; target <= 1.5 s: "
                    f"{'met' if ours <= 1.5 else 'MISSED'}"))
    return rows, dict(runs={k: {str(v): r for v, r in d.items()} for k, d in runs.items()},
                      sweep_estimate_s=sweep, import_s=dict(bare=bare, jaxchain=ours))
