"""`jaxchain localized-ranges`: the one-site localized state's stable range in v_d
over stiffness mistuning draws, by harmonic balance vmapped over the draws."""

import argparse
import time

import numpy as np

from .._bifurcation.harmonic_balance import HarmonicBalance
from .._physics.params import ChainParams
from .._setup import usable_cores
from .._studies.localized_ranges import localized_ranges, shooting_ranges
from .common import (Outputs, RunsFailed, UsageError, add_output_options, comma_list,
                     non_negative_float, positive_float, positive_int, report, show_progress)

HELP = "one-site localized state: its stable range in v_d over mistuning draws"
DESCRIPTION = """\
The paper's ring (eq. (5), N oscillators, coupling eta_c) with random ground
stiffness mistuning: for each strength of --sigmas (multiples of eta_c) --draws
draws (draw d: seed d, the same normal numbers at every strength), the range of
belt speeds over which the one-site localized state (oscillator --site on the HALC)
is stable, and what ends it at each side (a Neimark-Sacker point, a fold of limit
cycles, a period doubling).

All orbits by harmonic balance (--harmonics H, --time-samples M, the friction law
smoothed at --eps). The tuned ring's branch is followed once with the
branch-following driver from the state found by simulation at --v-start; every
draw then starts at --v-start from the tuned orbit and marches along its own
branch both ways (pseudo-arclength steps, the draws vmapped, --lanes at a time)
until the largest non-trivial Floquet multiplier leaves the unit circle (located
by regula falsi) or the branch turns at a fold's corner (located by bisection).

--check K follows the first K draws of the strongest mistuning by shooting with the
same driver, and reports both methods' ends side by side; the run exits with status
1 where an end differs by more than 5e-3 in v_d or in kind.

Each sigma goes to <out>/localized_ranges_parts/ as it finishes: --resume
continues a killed run (a part is reused only with equal settings). Writes
<out>/localized_ranges.nc (both ends, their kinds, the tuned ring's range),
<out>/localized_ranges.json (the statistics per sigma, the check) and
<out>/localized_ranges.png."""


def add_parser(sub):
    p = sub.add_parser("localized-ranges", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5), the paper's ring)")
    g.add_argument("--n-osc", type=positive_int, default=20, metavar="N",
                   help="oscillators on the ring (default 20)")
    g.add_argument("--eta-c", type=positive_float, default=0.01,
                   help="coupling eta_c (default 0.01, the paper's)")
    g.add_argument("--xi", type=positive_float, default=0.05,
                   help="damping ratio (default 0.05, the paper's)")
    g.add_argument("--v-start", type=positive_float, default=1.5, metavar="V",
                   help="belt speed inside the tuned ring's range where every draw starts "
                        "(default 1.5)")
    g.add_argument("--site", type=int, default=0,
                   help="the oscillator on the HALC, 0-based (default 0)")
    g.add_argument("--eps", type=positive_float, default=1e-2,
                   help="tanh smoothing velocity of the friction law (default 1e-2: "
                        "H = 16 then resolves the stick-slip orbit)")
    g = p.add_argument_group("study")
    g.add_argument("--sigmas", type=comma_list(non_negative_float), default=[0.5, 1.0, 2.0],
                   metavar="S,...", help="mistuning strengths sigma / eta_c "
                   "(default 0.5,1,2)")
    g.add_argument("--draws", type=positive_int, default=256,
                   help="mistuned rings per strength (default 256)")
    g.add_argument("--harmonics", type=positive_int, default=16, metavar="H",
                   help="harmonic balance: highest harmonic (default 16)")
    g.add_argument("--time-samples", type=positive_int, default=None, metavar="M",
                   help="harmonic balance: time samples of a period (default: the "
                        "smallest power of two >= 4H + 1)")
    g.add_argument("--lanes", type=positive_int, default=64,
                   help="rings solved together, vmapped: a group (default 64)")
    g.add_argument("--workers", type=positive_int, default=None, metavar="W",
                   help="processes that compute the groups side by side, one core each "
                        "(default: one per usable core; 1: one group after another, on "
                        "every core)")
    g.add_argument("--check", type=int, default=0, metavar="K",
                   help="follow the first K draws of the strongest mistuning by shooting "
                        "too, and compare (default 0; each takes one to three minutes)")
    add_output_options(p, resume="a killed run from its finished sigma parts")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    if args.check < 0:
        raise UsageError(f"--check: must be >= 0, got {args.check}")
    if args.check > args.draws:
        raise UsageError(f"--check: at most --draws ({args.draws}), got {args.check}")
    # the library's checks name a bad value (ValidationError: exit status 2)
    params = ChainParams(n_osc=args.n_osc, xi=args.xi, eta_c=args.eta_c, v_d=args.v_start)
    method = HarmonicBalance(eps=args.eps, harmonics=args.harmonics,
                             time_samples=args.time_samples, linear_solver="lu")
    outputs = Outputs(args, data=["localized_ranges.nc", "localized_ranges.json"],
                      figures=["localized_ranges"])
    sigmas = [s * args.eta_c for s in args.sigmas]
    start = time.perf_counter()
    ds = localized_ranges(params, sigmas, args.draws, method, site=args.site,
                          lanes=args.lanes, workers=args.workers or usable_cores(),
                          progress=show_progress(args),
                          store=outputs.path("localized_ranges_parts"))
    summary = {"tuned": {k: ds.attrs[k] for k in (
        "tuned_low", "tuned_low_kind", "tuned_high", "tuned_high_kind",
        "tuned_low_lanes", "tuned_high_lanes")}, "studies": []}
    for s in ds["sigma"].values:
        part = ds.sel(sigma=s)
        ok = part["found"].values
        row = {"sigma_over_eta_c": float(s / args.eta_c), "found": int(ok.sum()),
               "failed": int((~ok).sum())}
        for end in ("low", "high"):
            v = part[end].values[ok]
            row[end] = ({"mean": float(v.mean()), "std": float(v.std()),
                         "p5": float(np.percentile(v, 5)), "p95": float(np.percentile(v, 95))}
                        if v.size else None)
            kinds, counts = np.unique(part[f"{end}_kind"].values[ok], return_counts=True)
            row[f"{end}_kinds"] = {str(k): int(c) for k, c in zip(kinds, counts)}
        width = (part["high"] - part["low"]).values[ok]
        row["width_mean"] = float(width.mean()) if width.size else None
        summary["studies"].append(row)
    summary["harmonic_balance_s"] = time.perf_counter() - start
    if args.check:
        sigma = max(sigmas)
        checks = shooting_ranges(params, sigma, range(args.check), eps=args.eps,
                                 site=args.site, workers=args.workers or usable_cores())
        part = ds.sel(sigma=sigma)
        for c in checks:
            c["low_hb"] = float(part["low"].values[c["draw"]])
            c["high_hb"] = float(part["high"].values[c["draw"]])
            c["low_kind_hb"] = str(part["low_kind"].values[c["draw"]])
            c["high_kind_hb"] = str(part["high_kind"].values[c["draw"]])
            c["difference"] = (None if c["low"] is None else
                               max(abs(c["low"] - c["low_hb"]), abs(c["high"] - c["high_hb"])))
        summary["check"] = {"sigma_over_eta_c": sigma / args.eta_c, "draws": checks}
    wall = time.perf_counter() - start
    summary["wall_time_s"] = wall
    outputs.dataset(ds, "localized_ranges.nc")
    from .._plots.localized_ranges import plot_localized_ranges

    outputs.figure(plot_localized_ranges(ds), "localized_ranges")
    failed = sum(s["failed"] for s in summary["studies"])

    def table(s):
        t = s["tuned"]
        print(f"tuned ring: stable for v_d in [{t['tuned_low']:.5f}, {t['tuned_high']:.5f}] "
              f"({t['tuned_low_kind']}, {t['tuned_high_kind']}; the draws' procedure: "
              f"[{t['tuned_low_lanes']:.5f}, {t['tuned_high_lanes']:.5f}])")
        print(f"{'sigma/eta_c':>11} {'low mean':>9} {'low std':>8} {'high mean':>9} "
              f"{'high std':>8} {'width':>7} {'failed':>6}  lower ends")
        for row in s["studies"]:
            lo, hi = row["low"] or {}, row["high"] or {}

            def f(d, k, w):
                return f"{d[k]:{w}.5f}" if k in d else " " * (w - 3) + "n/a"

            print(f"{row['sigma_over_eta_c']:11.3g} {f(lo, 'mean', 9)} {f(lo, 'std', 8)} "
                  f"{f(hi, 'mean', 9)} {f(hi, 'std', 8)} "
                  f"{row['width_mean'] or float('nan'):7.4f} {row['failed']:6d}  "
                  + ", ".join(f"{k} {v}" for k, v in row["low_kinds"].items()))
        if "check" in s:
            print(f"check by shooting at sigma = {s['check']['sigma_over_eta_c']:g} eta_c:")
            for c in s["check"]["draws"]:
                if c["low"] is None:
                    print(f"  draw {c['draw']}: shooting gave no range ({c['error']})")
                    continue
                print(f"  draw {c['draw']}: low {c['low']:.5f} (HB {c['low_hb']:.5f}), "
                      f"high {c['high']:.5f} (HB {c['high_hb']:.5f}), largest difference "
                      f"{c['difference']:.1e}")

    report(summary, outputs, "localized_ranges.json", args.json, table, wall)
    if failed:
        raise RunsFailed(f"{failed} draws have no range found: they are flagged in "
                         "localized_ranges.nc (found = false)")
    wrong = check_disagreements(summary.get("check", {}).get("draws", []))
    if wrong:
        raise RunsFailed(f"the check by shooting disagrees with harmonic balance on draws "
                         f"{wrong} (an end off by more than {CHECK_TOLERANCE:g} in v_d, of "
                         "another kind, or not found): see localized_ranges.json")


#: The largest difference in v_d between an end by harmonic balance and by shooting
#: that the check accepts: what H = 16 resolves at eps = 1e-2 (docs/localized-ranges.md).
CHECK_TOLERANCE = 5e-3


def check_disagreements(checks: list[dict]) -> list[int]:
    """The draws of the check (`shooting_ranges`' dicts with `low_hb`, `high_hb`
    and the harmonic-balance kinds `low_kind_hb`, `high_kind_hb` added) whose
    ends by harmonic balance and by shooting differ by more than `CHECK_TOLERANCE`
    or in kind, or where shooting found no range."""
    return [c["draw"] for c in checks
            if c["low"] is None or c["difference"] > CHECK_TOLERANCE
            or c["low_kind"] != c["low_kind_hb"] or c["high_kind"] != c["high_kind_hb"]]
