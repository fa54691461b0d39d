"""Where the fixed cost of a command goes: a breakdown of `jaxchain localized` into its
phases, for a small run and for the main job, before and after (issue 43).

    python benchmarks/fixed_cost.py [--before REV] [--repeats 3] [--out DIR]

Each case runs as a whole process from a clean shell, first with an empty
compilation cache (cold), then `--repeats` times warm, for the code of `--before`
(checked out into a temporary git worktree, imported ahead of the installed
package through PYTHONPATH) and for this tree, in the same run. A run goes through
`fixed_cost.py --child`, which imports jaxchain and calls the console script's
entry (`jaxchain._cli.main.command`, or `main` before it existed) as `jaxchain`
does, with timestamps around its phases:

- interpreter start (the parent's clock before the process, to the child's first);
- `import jax`, `import jaxchain`, the JAX backend (`jax.devices()`, with the CPU
  devices of `jaxchain.configure()`);
- the options: the command's module, the arguments and the chain file;
- the initial conditions (the ensemble up to its run: steady sliding, eq. (8));
- the traced program (`kept_program`: read back, or traced and written);
- the executables: compiled, or read from the persistent cache, on each device
  thread (JAX's compile events; the slowest device's sum);
- the integration (the device threads' time less the executables);
- the dataset (`to_dataset`), the netCDF file, the figure (drawn and saved: the
  rest of the command after the run), the JSON document, and the interpreter's
  exit;
- and, across them, the programs that the main thread compiled op by op or for
  small functions (JAX's compile events outside the run), with their count.

The table gives the median of the warm runs of each phase, before and now, and
their ratio (before / now, > 1: faster now), the whole process cold, and the
whole process of the console script when the warm process of the command line
(`jaxchain._cli.warm`, which the phases above leave off) runs the command. It is
written to `<out>/fixed_cost.md` with the JSON numbers of both trees, which must
agree (the results are unchanged).
"""

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent

#: The commit before issue 43's changes: the "before" of the table.
BEFORE = "d302ca8"

#: The small case of issue 43: 6 oscillators, free ends, a Stribeck law.
SMALL_CHAIN = """\
n_osc = 6
boundary = "free"
friction = "stribeck"
mu_s = 1.0
mu_c = 0.5
v_s = 0.5
delta = 2.0
"""

CASES = {
    "small": ["localized", "--chain", "mychain.toml", "--vd", "1.1", "--t-end", "1000",
              "--transient", "600", "--json"],
    "main job": ["localized", "--json"],
}

#: The phases, in the order of a run, with the label of the table.
PHASES = [
    ("interpreter", "interpreter start"),
    ("import jax", "import jax"),
    ("import jaxchain", "import jaxchain"),
    ("backend", "JAX backend start (CPU devices)"),
    ("options", "command module, arguments, chain file"),
    ("initial", "initial conditions (steady sliding, eq. (8))"),
    ("traced", "traced program (read or trace)"),
    ("executables", "executables (read or compile, slowest device)"),
    ("integration", "integration"),
    ("dataset", "xarray dataset"),
    ("netcdf", "netCDF file"),
    ("figure", "figure (draw and save)"),
    ("json", "JSON document"),
    ("other", "other (between the phases above)"),
    ("exit", "interpreter exit"),
]

#: JAX's compile events (`jax.monitoring` time spans), by the part they time.
COMPILE_EVENTS = {"/jax/core/compile/jaxpr_trace_duration": "trace",
                  "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
                  "/jax/core/compile/backend_compile_duration": "compile"}


# -- the child: one instrumented run of the command ---------------------------------

def child(argv: list[str]) -> None:
    """Run `jaxchain argv` in this process with timestamps, and write them as JSON to
    the file named by FIXED_COST_SPANS."""
    t0 = time.time()
    spans: list[tuple] = []  # (label, start, end, thread id)
    main_thread = threading.get_ident()

    def span(label, start):
        spans.append((label, start, time.time(), threading.get_ident()))

    import jax
    span("import jax", t0)

    def on_event(event, start, end, **kwargs):
        if event in COMPILE_EVENTS:
            spans.append((COMPILE_EVENTS[event], start, end, threading.get_ident()))

    jax.monitoring.register_event_time_span_listener(on_event)
    start = time.time()
    import jaxchain
    import jaxchain._cli.main as cli
    span("import jaxchain", start)
    start = time.time()
    jaxchain.configure()
    jax.devices()
    span("backend", start)

    def wrap(owner, name, label):
        fn = getattr(owner, name, None)
        if fn is None:
            return

        def timed(*args, **kwargs):
            begin = time.time()
            try:
                return fn(*args, **kwargs)
            finally:
                span(label, begin)

        setattr(owner, name, timed)

    import jaxchain._cli.common as common
    import jaxchain._cli.localized as localized
    import jaxchain._engine.lanes as lanes
    import jaxchain._sweeps.ensemble as ensemble
    wrap(localized, "ensemble", "ensemble")
    wrap(ensemble, "run_lanes", "run_lanes")
    wrap(lanes, "kept_program", "traced")
    wrap(lanes, "on_devices", "devices")
    wrap(common.Outputs, "dataset", "netcdf")
    wrap(localized, "print_json", "json")
    run_main = cli.main

    def timed_main(*args):
        start = time.time()
        status = run_main(*args)
        span("main", start)
        Path(os.environ["FIXED_COST_SPANS"]).write_text(json.dumps(
            {"t0": t0, "spans": spans, "main_thread": main_thread, "status": status}))
        return status

    cli.main = timed_main
    sys.argv = ["jaxchain", *argv]
    try:  # the console script's entry, as it ends the process (JAXCHAIN_SERVER=0: here)
        from jaxchain._cli.warm import command
    except ImportError:  # before the warm process
        command = getattr(cli, "command", lambda: sys.exit(cli.main()))
    command()


# -- the parent: phases from the spans ------------------------------------------------

def _total(spans, label, thread=None):
    return sum(e - s for lab, s, e, th in spans
               if lab == label and (thread is None or th == thread))


def _union(intervals) -> float:
    """The length of the union of the (label, start, end) intervals (a trace
    holds the traces of the functions it calls)."""
    total, reach = 0.0, float("-inf")
    for _, s, e in sorted(intervals, key=lambda x: x[1]):
        if e > reach:
            total += e - max(s, reach)
            reach = e
    return total


def phases(record: dict, wall: float, started: float) -> dict:
    """The phases' durations (s) of one run from its spans, `wall` the whole
    process and `started` the parent's clock when it was started."""
    spans, main = record["spans"], record["main_thread"]
    one = {lab: (s, e) for lab, s, e, th in spans if th == main}
    out = {"interpreter": record["t0"] - started}
    for label in ("import jax", "import jaxchain", "backend", "json", "netcdf"):
        out[label] = _total(spans, label, main)
    devices = one.get("devices")
    threads = {th for lab, s, e, th in spans if th != main}
    if devices:
        slowest = max((sum(e - s for lab, s, e, t in spans if t == th and lab == "compile")
                       for th in threads), default=0.0)
        out["executables"] = slowest
        out["integration"] = devices[1] - devices[0] - slowest
    out["traced"] = _total(spans, "traced", main)
    ens, runs = one.get("ensemble"), one.get("run_lanes")
    if ens and runs:
        out["initial"] = runs[0] - ens[0]
        out["dataset"] = ens[1] - runs[1]
    main_span = one["main"]
    out["options"] = (ens[0] if ens else main_span[1]) - main_span[0]
    # The figure, drawn and saved (`Outputs.figure`) after the run: the main
    # thread's time after the ensemble that the netCDF file and the JSON do not hold.
    if ens:
        out["figure"] = main_span[1] - ens[1] - out["netcdf"] - out["json"]
    end_of_main = main_span[1]
    out["exit"] = started + wall - end_of_main
    out["other"] = wall - sum(v for k, v in out.items() if k != "other")
    small = [(lab, s, e) for lab, s, e, th in spans if th == main
             and lab in ("trace", "lower", "compile")
             and not (devices and devices[0] <= s <= devices[1])]
    out["small programs"] = (_union(small), sum(1 for lab, *_ in small if lab == "compile"))
    return out


def run_case(tree: Path | None, args: list[str], cache: Path, folder: Path) -> dict:
    """One whole process of `jaxchain args` through the child, in `folder`, with the
    compilation cache `cache`, importing jaxchain from `tree` (None: as installed)."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS",)}
    env["JAXCHAIN_CACHE_DIR"] = str(cache)
    spans_file = folder / "spans.json"
    env["FIXED_COST_SPANS"] = str(spans_file)
    env["JAXCHAIN_SERVER"] = "0"  # the phases of a command that runs in its own process
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    out = folder / "out"
    started = time.time()
    proc = subprocess.run([sys.executable, str(BENCH_DIR / "fixed_cost.py"), "--child", "--",
                           *args, "--out", str(out), "--overwrite"], cwd=folder, env=env,
                          capture_output=True, text=True)
    wall = time.time() - started
    if proc.returncode != 0:
        raise RuntimeError(f"jaxchain {' '.join(args)} failed ({proc.returncode}): "
                           f"{proc.stderr.strip().splitlines()[-1:]}")
    record = json.loads(spans_file.read_text())
    result = json.loads(proc.stdout)
    return {"wall": wall, "phases": phases(record, wall, started),
            "numbers": [{k: r[k] for k in ("n_halc", "energy", "amplitudes", "num_steps",
                                             "status")} for r in result["runs"]],
            "wall_time_s": result["wall_time_s"]}


def measure(tree: Path | None, name: str, args: list[str], repeats: int, work: Path,
            say) -> dict:
    """The cold run (empty cache) and `repeats` warm runs of one case for one tree;
    for this tree, also `repeats` runs handed to the warm process (`served`)."""
    folder = work / f"{name.replace(' ', '_')}-{'before' if tree else 'now'}"
    folder.mkdir()
    (folder / "mychain.toml").write_text(SMALL_CHAIN)
    cache = folder / "cache"
    cold = run_case(tree, args, cache, folder)
    say(f"  {name}, {'before' if tree else 'now'}: cold {cold['wall']:.2f} s")
    warm = []
    for _ in range(repeats):
        warm.append(run_case(tree, args, cache, folder))
        say(f"  {name}, {'before' if tree else 'now'}: warm {warm[-1]['wall']:.2f} s")
    served = [] if tree is not None else served_runs(args, cache, folder, repeats, say, name)
    return {"cold": cold, "warm": warm, "served": served}


def served_runs(args: list[str], cache: Path, folder: Path, repeats: int, say, name: str
                ) -> list[dict]:
    """`repeats` whole processes of the `jaxchain` console script handed to the warm
    process (`jaxchain._cli.warm`), which a first command starts: their wall times
    and JSON numbers. The warm process lives in a temporary folder of its own and
    is stopped at the end."""
    exe = Path(sys.executable).with_name("jaxchain")
    command = [str(exe)] if exe.exists() else [
        sys.executable, "-c", "from jaxchain._cli.warm import command; command()"]
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update(JAXCHAIN_CACHE_DIR=str(cache), JAXCHAIN_SERVER="1",
               XDG_RUNTIME_DIR=str(folder / "t"), JAXCHAIN_SERVER_IDLE="300")
    (folder / "t").mkdir(mode=0o700)
    sockets = folder / "t" / "jaxchain"

    def one() -> dict:
        started = time.time()
        proc = subprocess.run([*command, *args, "--out", str(folder / "served"), "--overwrite"],
                              cwd=folder, env=env, capture_output=True, text=True)
        wall = time.time() - started
        if proc.returncode != 0:
            raise RuntimeError(f"jaxchain {' '.join(args)} failed: {proc.stderr.strip()}")
        result = json.loads(proc.stdout)
        return {"wall": wall, "numbers": [{k: r[k] for k in ("n_halc", "energy", "amplitudes",
                                                            "num_steps", "status")}
                                           for r in result["runs"]]}

    one()  # in its own process: it starts the warm process
    end = time.time() + 120
    while not list(sockets.glob("*.sock")) and time.time() < end:
        time.sleep(0.2)
    runs = []
    try:
        for _ in range(repeats):
            runs.append(one())
            say(f"  {name}, now: served by the warm process {runs[-1]['wall']:.2f} s")
    finally:
        for pid in sockets.glob("*.pid"):
            try:
                os.kill(int(pid.read_text()), signal.SIGTERM)
            except (ProcessLookupError, ValueError):
                pass
    return runs


def _median_phase(runs, key):
    values = [r["phases"].get(key) for r in runs]
    if key == "small programs":
        return (statistics.median(v[0] for v in values), statistics.median(v[1] for v in values))
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def table(name: str, before: dict | None, now: dict) -> list[str]:
    """The Markdown table of one case."""
    def fmt(v):
        return "-" if v is None else f"{v:.2f}"

    def ratio(b, n):
        return "" if b is None or n is None or n <= 0.005 else f"{b / n:.2f}x"

    lines = [f"### {name}", "",
             "| phase (warm, median) | before (s) | now (s) | ratio |",
             "| --- | --- | --- | --- |"]
    for key, label in PHASES:
        b = _median_phase(before["warm"], key) if before else None
        n = _median_phase(now["warm"], key)
        lines.append(f"| {label} | {fmt(b)} | {fmt(n)} | {ratio(b, n)} |")
    bs = _median_phase(before["warm"], "small programs") if before else None
    ns = _median_phase(now["warm"], "small programs")
    lines.append(f"| of which small programs traced and compiled on the main thread "
                 f"(count) | {fmt(bs[0]) + f' ({bs[1]:g})' if bs else '-'} | "
                 f"{fmt(ns[0])} ({ns[1]:g}) | {ratio(bs[0] if bs else None, ns[0])} |")
    bw = statistics.median(r["wall"] for r in before["warm"]) if before else None
    nw = statistics.median(r["wall"] for r in now["warm"])
    lines.append(f"| **whole process, warm** | {fmt(bw)} | {fmt(nw)} | {ratio(bw, nw)} |")
    bc = before["cold"]["wall"] if before else None
    lines.append(f"| **whole process, cold (empty cache)** | {fmt(bc)} | "
                 f"{fmt(now['cold']['wall'])} | {ratio(bc, now['cold']['wall'])} |")
    if now.get("served"):
        sw = statistics.median(r["wall"] for r in now["served"])
        lines.append(f"| **whole process, warm, handed to the warm process** | | {fmt(sw)} | "
                     f"{ratio(bw, sw)} |")
    return lines + [""]


def same_numbers(before: dict, now: dict) -> bool:
    """Whether both trees' runs give the same JSON numbers (every run, warm and cold)."""
    runs = [before["cold"], *before["warm"], now["cold"], *now["warm"], *now["served"]]
    return all(r["numbers"] == runs[0]["numbers"] for r in runs)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[3:])
        return
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", default=BEFORE,
                   help=f"the git revision of the 'before' column (default {BEFORE}, the "
                        f"code before issue 43); 'none' for this tree alone")
    p.add_argument("--repeats", type=int, default=3, help="warm runs per case and tree")
    p.add_argument("--cases", default=",".join(CASES),
                   help=f"comma-separated cases among {', '.join(CASES)}")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "benchmarks" / "fixed_cost")
    args = p.parse_args()
    cases = [c.strip() for c in args.cases.split(",")]
    if unknown := [c for c in cases if c not in CASES]:
        p.error(f"--cases: unknown case {unknown[0]!r}")
    if args.repeats < 1:
        p.error("--repeats must be at least 1")

    def say(text):
        print(text, file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="jaxchain-fixed-cost-") as tmp:
        work = Path(tmp)
        tree = None
        if args.before != "none":
            tree = work / "before"
            subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q",
                            str(tree), args.before], check=True)
        try:
            results = {}
            for name in cases:
                results[name] = {
                    "before": measure(tree, name, CASES[name], args.repeats, work, say)
                    if tree else None,
                    "now": measure(None, name, CASES[name], args.repeats, work, say)}
        finally:
            if tree is not None:
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force",
                                str(tree)], check=False)
    lines = ["# Fixed cost of `jaxchain localized`", "",
             f"`python benchmarks/fixed_cost.py --repeats {args.repeats}`: before = "
             f"{args.before}, now = this tree, measured in one run on "
             f"{os.cpu_count()} cores; warm phases are medians of {args.repeats} runs.", ""]
    for name in cases:
        r = results[name]
        lines += [f"`jaxchain {' '.join(CASES[name])}`", ""]
        lines += table(name, r["before"], r["now"])
        if r["before"]:
            same = same_numbers(r["before"], r["now"])
            lines += [f"Same JSON numbers before and now, in its own process and in the "
                      f"warm process (n_halc, energy, amplitudes, num_steps, status): "
                      f"**{'yes' if same else 'NO'}**", ""]
    text = "\n".join(lines)
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / "fixed_cost.md.tmp"
    tmp.write_text(text + "\n")
    os.replace(tmp, args.out / "fixed_cost.md")
    tmp = args.out / "fixed_cost.json.tmp"
    tmp.write_text(json.dumps(results, indent=1))
    os.replace(tmp, args.out / "fixed_cost.json")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
