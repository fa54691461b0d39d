"""`jaxchain crosscheck`: the smoothed model against the event-driven non-smooth
reference on a grid of belt speeds and initial conditions."""

import argparse
import time

from .._studies.crosscheck import CROSSCHECK_ICS, CROSSCHECK_VD, crosscheck
from .._engine.exact.options import NonsmoothOptions, REFERENCE_TOLERANCES
from .._engine.status import Status
from .._physics.params import with_parameter
from .._plots.crosscheck import plot_crosscheck
from .._physics.record import chain_record
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     add_run_options, add_scheduler_option, add_vd_option, cluster_client,
                     comma_list, engine_of, engine_record, engine_text, note, positive_float,
                     print_json, show_progress, simulation_options)

HELP = "smoothed model against the non-smooth stick/slip reference"
DESCRIPTION = f"""\
Run the smoothed (tanh) model and the event-driven non-smooth reference on the same
grid of belt speeds x initial conditions (by default v_d in {list(CROSSCHECK_VD)}
and eq. (8)/eq. (10) excitations {[f"{f} k={k}" for f, k in CROSSCHECK_ICS]}, N =
20, t_end = 15000, transient = 10000) and compare, for each case: the amplitude
error (max over oscillators, relative to max(1, largest reference amplitude)), the
energy error, whether n_HALC agrees and whether the state class agrees.

Irregular states diverge between any two models, so every case is compared by its
statistics over the observed window (amplitudes, E, n_HALC), never as a time
series. A state is periodic when its extrema over the two halves of the window
agree (to 1e-6 for the reference, 1e-3 for the sampled smoothed model).

Writes <out>/crosscheck.nc and <out>/crosscheck.png; each reference run is stored
in <out>/crosscheck_cases/ as it finishes, under a hash of everything that
determines it (parameters, initial state, reference options); a later run reads
back only runs of equal settings (--resume) and recomputes the others. --scheduler
runs each reference run as a task on a Dask cluster (local:N starts N worker
processes here), which stores it in <out>/crosscheck_cases/; the smoothed runs stay
in this process."""


def add_parser(sub):
    p = sub.add_parser("crosscheck", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("grid (eq. (5) of the paper; other parameters eq. (7))")
    add_vd_option(g, list(CROSSCHECK_VD), "belt speeds")
    default8 = [k for f, k in CROSSCHECK_ICS if f == "eq8"]
    default10 = [k for f, k in CROSSCHECK_ICS if f == "eq10"]
    g.add_argument("--eq8", type=comma_list(int), default=None, metavar="K,K,...",
                   help="numbers of excited oscillators of eq. (8) initial conditions "
                        f"(default {','.join(map(str, default8))}, each at most N: on a "
                        "shorter chain the larger ones become k = N; '' for none)")
    g.add_argument("--eq10", type=comma_list(int), default=None, metavar="K,K,...",
                   help="the same for eq. (10) (default "
                        f"{','.join(map(str, default10))}, each at most N; '' for none)")
    add_ring_options(g)
    add_chain_options(g)
    add_run_options(p)
    g = p.add_argument_group("reference")
    g.add_argument("--ref-rtol", type=positive_float, default=REFERENCE_TOLERANCES["rtol"],
                   help="tolerance (rtol = atol) of the reference's smooth phases "
                        f"(default {REFERENCE_TOLERANCES['rtol']:g})")
    add_scheduler_option(g)
    add_output_options(p, resume="from the reference runs stored in DIR/crosscheck_cases")
    p.set_defaults(run=run)
    return p


def _excited(family: str, given: list[int] | None, n_osc: int) -> list[int]:
    """The numbers of excited oscillators of `family` ("eq8" or "eq10"): those
    given, each checked against the chain's `n_osc`, or the defaults of
    `CROSSCHECK_ICS` with each k at most `n_osc` (k = 20, the whole default ring,
    is the whole chain on a shorter one).

    **Raises:** `UsageError` naming the option for a k outside [1, n_osc]."""
    if given is None:
        return sorted({min(k, n_osc) for f, k in CROSSCHECK_ICS if f == family})
    for k in given:
        if not 1 <= k <= n_osc:
            raise UsageError(f"--{family}: k must lie in [1, {n_osc}], got {k}")
    return given


def run(args) -> None:
    ics = [(family, k) for family in ("eq8", "eq10")
           for k in _excited(family, getattr(args, family), args.n_osc)]
    if not ics:
        raise UsageError("--eq8 and --eq10 are both empty: no initial conditions")
    params = chain_params(args, args.n_osc)
    for vd in args.vd:
        with_parameter(params, "v_d", vd)  # validates every belt speed now
    options = simulation_options(args)
    ref_options = NonsmoothOptions.reference(t_end=args.t_end, transient=args.transient,
                                             rtol=args.ref_rtol, atol=args.ref_rtol)
    engine = engine_of(args, options, params)
    outputs = Outputs(args, data=["crosscheck.nc"], figures=["crosscheck"])

    start = time.perf_counter()
    with cluster_client(args) as client:
        ds = crosscheck(params, args.vd, ics, reference_options=ref_options,
                        engine=engine,
                        checkpoint=outputs.path("crosscheck_cases"), client=client,
                        progress=show_progress(args))
    wall = time.perf_counter() - start
    ds.attrs["wall_time_s"] = wall
    outputs.dataset(ds, "crosscheck.nc")
    outputs.figure(plot_crosscheck(ds), "crosscheck")

    s = args.engine  # the suffix of the engine's variables
    failed = int(((ds[f"status_{s}"] != Status.ok)
                  | (ds["status_reference"] != Status.ok)).sum())
    rows = []
    for i in range(ds.sizes["case"]):
        c = ds.isel(case=i)
        rows.append({
            "v_d": float(c["v_d"]), "ic": f"{str(c['family'].values)} k={int(c['n_excited'])}",
            f"n_halc_{s}": int(c[f"n_halc_{s}"]),
            "n_halc_reference": int(c["n_halc_reference"]),
            f"class_{s}": str(c[f"state_class_{s}"].values),
            "class_reference": str(c["state_class_reference"].values),
            "amplitude_error": float(c["amplitude_error"]),
            "energy_error": float(c["energy_error"]),
            "n_halc_agrees": bool(c["n_halc_agrees"]), "class_agrees": bool(c["class_agrees"]),
            "reference_wall_time_s": float(c["wall_time_s_reference"]),
        })
    periodic = [r for r in rows if "periodic" in r["class_reference"]]
    summary = {
        "max_amplitude_error_periodic": max((r["amplitude_error"] for r in periodic),
                                            default=None),
        "n_halc_agrees_periodic": all(r["n_halc_agrees"] for r in periodic),
        "n_halc_agrees_all": all(r["n_halc_agrees"] for r in rows),
    }
    if args.json:
        print_json({
            "cases": rows, **summary, "chain": chain_record(params), **engine_record(engine),
            "scheduler": args.scheduler,
            "rtol": engine.options.rtol, "reference_rtol": args.ref_rtol, "wall_time_s": wall,
            f"{s}_wall_time_s": ds.attrs[f"wall_time_s_{s}"],
            "note": "irregular states are compared by statistics (amplitudes, E, "
                    "n_HALC), not as time series",
        }, outputs)
    else:
        print(f"{s} ({engine_text(engine)}, rtol {engine.options.rtol:g}) against "
              f"the non-smooth reference, N = {args.n_osc}, window "
              f"[{args.transient:g}, {args.t_end:g}]")
        print(f"{'v_d':>5} {'ic':>10} {'n_HALC s/r':>10} {'A err %':>8} {'E err %':>8}"
              f"  class ({s} / reference)")
        for r in rows:
            same = "" if r["class_agrees"] else "  <- differs"
            print(f"{r['v_d']:5.2f} {r['ic']:>10} {r[f'n_halc_{s}']:4d}/"
                  f"{r['n_halc_reference']:<5d} {100 * r['amplitude_error']:8.3f} "
                  f"{100 * r['energy_error']:8.3f}  {r[f'class_{s}']} / "
                  f"{r['class_reference']}{same}")
        err = summary["max_amplitude_error_periodic"]
        print(f"periodic states: max amplitude error "
              f"{'-' if err is None else f'{100 * err:.3f} %'}, n_HALC agrees: "
              f"{summary['n_halc_agrees_periodic']}. Irregular states are compared by "
              f"statistics, not time series.")
        note(f"wall time {wall:.1f} s; {outputs.summary()}")
    if failed:
        raise RunsFailed(f"{failed} of {ds.sizes['case']} cases failed ({s} or "
                         "reference); their rows are kept in the Dataset")
