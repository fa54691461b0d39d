"""Comparisons of benchmarks/run.py that need fresh processes: time and peak memory
against the ring size (4), the XLA flag check (7), and the cold and warm start of
the command line."""

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jaxchain as jc
from jaxchain._engine.solver.registry import DEFAULT_SOLVER

from _common import BENCH_DIR, Row, Settings, fmt_ratio, fmt_time, progress

#: A valid XLA flag that changes nothing here: set, it keeps jaxchain from setting
#: its own XLA_FLAGS (the raised while-loop threshold), which is what comparison 7
#: switches off.
NEUTRAL_XLA_FLAGS = "--xla_cpu_enable_fast_math=false"


#: The flag takes effect when it speeds the step loop up by at least this much. Run
#: op by op, the loop pays the runtime's dispatch per operation: measured 1.4-2.0x
#: for ROS34PW2 (more work per operation) and 3-5.7x for Bosh3; without effect the
#: ratio is 1 within the noise (about 10 %).
FLAG_MIN_RATIO = 1.3


def _child(env: dict, *args: str, timeout: float = 900) -> dict:
    """Run `_child.py` with `args` in `env`; its JSON line as a dict."""
    out = subprocess.run([sys.executable, str(BENCH_DIR / "_child.py"), *args], env=env,
                         capture_output=True, text=True, timeout=timeout)
    if out.returncode != 0:
        tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"_child.py {' '.join(args)} failed: {tail}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _without_xla_flags(env: dict) -> dict:
    return {k: v for k, v in env.items() if k != "XLA_FLAGS"}


def compare_n_osc(settings: Settings, env: dict, start: float) -> tuple[list[Row], dict]:
    """4. One trajectory (eq. (8) with n_osc // 4 excited) for n_osc = 20, 100, 1000,
    each in its own process: time per step (after compilation, best of 3; on a short
    horizon it includes the per-chunk start and the dense sampling) and peak
    resident memory (compilation included; most of it is JAX and XLA themselves,
    hence the memory after import beside it). The baseline is n_osc = 20; the ratio
    is cost(n_osc) / cost(20), to read against n_osc / 20."""
    t_end, transient = settings.n_osc_horizon
    results = []
    for n in settings.n_oscs:
        r = _child(env, "--n-osc", str(n), "--t-end", str(t_end), "--transient",
                   str(transient), "--repeats", "3")
        results.append(r)
        progress(f"  4. n_osc = {n}: {r['us_per_step']:.2f} µs per step, peak RSS "
                 f"{r['peak_rss_mb']:.0f} MiB", start)
    base = results[0]
    rows = []
    for r in results:
        fails = "" if r["status"] == jc.Status.ok else f"; {jc.Status(r['status'])}"
        rows.append(Row(
            f"4. n_osc = {r['n_osc']}: µs per step",
            f"{base['us_per_step']:.2f} µs (n_osc = {base['n_osc']})",
            f"{r['us_per_step']:.2f} µs ({r['steps']:,} steps)",
            f"{r['us_per_step'] / base['us_per_step']:.2f} (cost ratio; n ratio "
            f"{r['n_osc'] / base['n_osc']:g})",
            f"{r['excited']} excited, t_end {t_end:g}, transient {transient:g}; "
            f"compile {fmt_time(r['compile_s'])}; own process. `run.py --only 4`{fails}"))
        rows.append(Row(
            f"4. n_osc = {r['n_osc']}: peak RSS",
            f"{base['peak_rss_mb']:.0f} MiB (n_osc = {base['n_osc']})",
            f"{r['peak_rss_mb']:.0f} MiB",
            f"{r['peak_rss_mb'] / base['peak_rss_mb']:.2f} (memory ratio)",
            f"{r['rss_after_import_mb']:.0f} MiB resident right after `import jaxchain`; "
            f"peak includes compilation"))
    return rows, dict(t_end=t_end, transient=transient, results=results)


def compare_before_after(settings: Settings, env: dict, start: float
                         ) -> tuple[list[Row], dict]:
    """0. The Fig. 4 ensemble (N = 20, v_d = 1.5, eq. (8) k = 1..20, the horizon of
    comparison 3) as jaxchain ran it before the fast engine (Bosh3 at rtol 1e-6,
    atol 1e-8, vmapped lanes in lockstep, XLA's while loops run op by op) against
    its defaults now (the work queue, the default solver and tolerances, jaxchain's
    XLA flag), each in its own process, two calls each (the first compiles). Both
    must find the same staircase n_HALC."""
    t_end, transient = settings.ensemble
    common = ("--fig4", "--n-osc", "20", "--t-end", str(t_end), "--transient",
              str(transient))
    default_env = _without_xla_flags(env)
    before = _child(dict(default_env, XLA_FLAGS=NEUTRAL_XLA_FLAGS), *common, "--engine",
                    "vmap", "--solver", "bosh3", "--rtol", "1e-6", "--atol", "1e-8",
                    "--controller", "diffrax", timeout=3600)
    progress(f"  0. before: {fmt_time(before['warm_s'])} after compilation", start)
    after = _child(default_env, *common)
    progress(f"  0. now: {fmt_time(after['warm_s'])} after compilation", start)
    same = before["n_halc"] == after["n_halc"]
    horizon = f"t_end {t_end:g}, transient {transient:g}"
    rows = [
        Row("0. Fig. 4 ensemble (20 traj.), before and now, after compilation",
            f"{fmt_time(before['warm_s'])} (Bosh3 rtol 1e-6, vmap, no flag; "
            f"{before['steps']:,} steps)",
            f"{fmt_time(after['warm_s'])} ({after['solver']} rtol {after['rtol']:g}, "
            f"queue; {after['steps']:,} steps)",
            fmt_ratio(before["warm_s"] / after["warm_s"]),
            f"{horizon}; own processes; n_HALC {'equal' if same else 'DIFFER'}: "
            f"{after['n_halc']}. `run.py --only 0`"),
        Row("0. Fig. 4 ensemble, before and now, first call (compile + run)",
            fmt_time(before["first_s"]), fmt_time(after["first_s"]),
            fmt_ratio(before["first_s"] / after["first_s"]), "in-process, after import"),
    ]
    return rows, dict(before=before, after=after, same_n_halc=same)


def flag_check(settings: Settings, env: dict, start: float) -> tuple[list[Row], dict, bool]:
    """7. Does jaxchain's XLA flag (the raised small-while-loop threshold, set on
    import) take effect on the engine's loop? The single trajectory of comparison 1,
    time per step after compilation, in one process with jaxchain's own XLA_FLAGS
    and one with a neutral flag set instead (so jaxchain leaves XLA_FLAGS alone),
    alternately (twice each in the full run, once in --quick). Fails (run.py exits
    with 1) if the flag does not speed the loop up by at least `FLAG_MIN_RATIO`."""
    t_end, transient = settings.single
    args = ("--n-osc", "20", "--excited", "5", "--t-end", str(t_end), "--transient",
            str(transient), "--repeats", str(settings.repeats))
    default_env = _without_xla_flags(env)
    neutral_env = dict(default_env, XLA_FLAGS=NEUTRAL_XLA_FLAGS)
    runs = {"default": [], "neutral": []}
    for _ in range(1 if settings.name == "quick" else 2):
        for name, e in (("default", default_env), ("neutral", neutral_env)):
            runs[name].append(_child(e, *args))
            progress(f"  7. XLA_FLAGS {name}: {runs[name][-1]['us_per_step']:.2f} µs per step",
                     start)
    # For information (not part of the pass/fail): the same for the other solver of
    # comparison 2, once each.
    other = "bosh3" if DEFAULT_SOLVER != "bosh3" else "ros34pw2"
    others = {}
    for name, e in (("default", default_env), ("neutral", neutral_env)):
        others[name] = _child(e, *args, "--solver", other)
        progress(f"  7. {other}, XLA_FLAGS {name}: {others[name]['us_per_step']:.2f} µs per "
                 f"step", start)
    best = {k: min(v, key=lambda r: r["us_per_step"]) for k, v in runs.items()}
    ratio = best["neutral"]["us_per_step"] / best["default"]["us_per_step"]
    ok = ratio >= FLAG_MIN_RATIO
    row = Row("7. XLA flag check: µs per step",
              f"{best['neutral']['us_per_step']:.2f} µs (XLA_FLAGS={NEUTRAL_XLA_FLAGS})",
              f"{best['default']['us_per_step']:.2f} µs (jaxchain's flag)",
              fmt_ratio(ratio),
              f"{'OK' if ok else 'FAIL'}: needs >= {FLAG_MIN_RATIO:g}x; in effect: "
              f"`{best['default']['xla_flags']}`; one trajectory as in 1 "
              f"({DEFAULT_SOLVER}), own processes. `run.py --only 7`")
    other_ratio = others["neutral"]["us_per_step"] / others["default"]["us_per_step"]
    info = Row(f"7. XLA flag, for information: {other}",
               f"{others['neutral']['us_per_step']:.2f} µs (neutral flag)",
               f"{others['default']['us_per_step']:.2f} µs (jaxchain's flag)",
               fmt_ratio(other_ratio),
               f"not the default solver, not part of the check; "
               f"{others['default']['steps']:,} / {others['neutral']['steps']:,} steps "
               f"(jaxchain's / neutral flag)")
    row.notes += (f"; {best['default']['steps']:,} / {best['neutral']['steps']:,} steps "
                  f"(jaxchain's / neutral flag)")
    return [row, info], dict(runs=runs, ratio=ratio, ok=ok, other=others), ok


def _jaxchain_command() -> list[str]:
    exe = Path(sys.executable).with_name("jaxchain")
    if exe.exists():
        return [str(exe)]
    return [sys.executable, "-c", "from jaxchain._cli.warm import command; command()"]


def _cli_twice(args: list[str], env: dict, start: float, label: str) -> dict:
    """Run `jaxchain *args` twice with a fresh, empty JAXCHAIN_CACHE_DIR: (cold, warm)
    wall times of the whole process, and whether the cache folder was written."""
    with tempfile.TemporaryDirectory(prefix="jaxchain-bench-") as tmp:
        cache = Path(tmp) / "cache"
        cache.mkdir()
        # In its own process each time: the warm process of the command line
        # (jaxchain._cli.warm) is measured by benchmarks/fixed_cost.py.
        e = dict(_without_xla_flags(env), JAXCHAIN_CACHE_DIR=str(cache), JAXCHAIN_SERVER="0")
        walls, errors = [], []
        for attempt in ("cold", "warm"):
            out_dir = Path(tmp) / f"out-{attempt}"
            cmd = _jaxchain_command() + args + ["--out", str(out_dir), "--no-progress"]
            t0 = time.perf_counter()
            out = subprocess.run(cmd, env=e, capture_output=True, text=True, timeout=1800)
            walls.append(time.perf_counter() - t0)
            if out.returncode != 0:
                errors.append((out.stderr.strip().splitlines() or ["?"])[-1])
            progress(f"  CLI {label}, {attempt}: {fmt_time(walls[-1])}", start)
        files = sum(1 for p in cache.rglob("*") if p.is_file())
    return dict(cold_s=walls[0], warm_s=walls[1], cache_files=files, errors=errors,
                command="jaxchain " + " ".join(args) + " --out TMP --no-progress")


def compare_cli(settings: Settings, env: dict, start: float) -> tuple[list[Row], dict]:
    """The command line's cold and warm start: `jaxchain localized` run twice in
    fresh processes, the first with an empty persistent compilation cache
    (JAXCHAIN_CACHE_DIR), the second after it. The ratio is cold / warm: what the
    cache saves (about 1 if the package does not honour JAXCHAIN_CACHE_DIR). Whole
    process wall time: imports, compilation, run, netCDF and PNG writing. In the full
    run also the paper's main job, `jaxchain localized` with its defaults (targets:
    <= 10 s warm, <= 20 s cold), and the main job
    at the previous defaults (--rtol 1e-5 --atol 1e-7 --controller diffrax) as the
    baseline of its second run."""
    jobs = [(["localized", "--n-osc", "20", "--t-end", "3000", "--transient", "2000"],
             "Fig. 4 at t_end 3000", None)]
    if settings.cli_main_job:
        jobs.append((["localized"], "main job (defaults)", (10.0, 20.0)))
        jobs.append((["localized", "--rtol", "1e-5", "--atol", "1e-7", "--controller",
                      "diffrax"], "main job at the previous defaults", None))
    rows, raw = [], {}
    for args, label, targets in jobs:
        r = _cli_twice(args, env, start, label)
        raw[label] = r
        cache = (f"cache folder written ({r['cache_files']} files)" if r["cache_files"]
                 else "JAXCHAIN_CACHE_DIR not used (cache folder empty)")
        verdict = ""
        if targets:
            warm_ok, cold_ok = r["warm_s"] <= targets[0], r["cold_s"] <= targets[1]
            verdict = (f"; targets <= {targets[0]:g} s warm: {'met' if warm_ok else 'MISSED'}"
                       f", <= {targets[1]:g} s cold: {'met' if cold_ok else 'MISSED'}")
        err = f"; FAILED: {'; '.join(r['errors'])}" if r["errors"] else ""
        rows.append(Row(f"CLI {label}: cold / warm start", f"{fmt_time(r['cold_s'])} (cold)",
                        f"{fmt_time(r['warm_s'])} (warm)",
                        f"{fmt_ratio(r['cold_s'] / r['warm_s'])} (cold / warm)",
                        f"`{r['command']}`, whole process; {cache}{verdict}{err}"))
    if settings.cli_main_job:
        now, before = raw["main job (defaults)"], raw["main job at the previous defaults"]
        rows.append(Row("CLI main job, second run (warm): the previous defaults / now",
                        fmt_time(before["warm_s"]), fmt_time(now["warm_s"]),
                        fmt_ratio(before["warm_s"] / now["warm_s"]),
                        "whole process, same cache folder state (warm); target <= 10 s: "
                        + ("met" if now["warm_s"] <= 10 else "MISSED")))
    return rows, raw
