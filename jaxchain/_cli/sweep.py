"""`jaxchain sweep`: the bifurcation diagram over belt speeds (Fig. 3(b) of the
paper), stored batch by batch and resumable."""

import argparse
import time


from .._physics.initial import FAMILIES, localized_family
from .common import simulation_options
from .._plots.sweep import plot_bifurcation_diagram
from .._bifurcation.hopf import hopf_speed
from .._engine.status import Status, status_names
from .._analysis.fronts import front_fractions, front_ranges
from .._sweeps.sweep import sweep
from .._physics.record import chain_record
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     add_run_options, add_scheduler_option, add_vd_option, belt_speeds,
                     cluster_client, engine_of, engine_record, engine_text, note,
                     positive_int, print_json, show_progress)

HELP = "bifurcation diagram over belt speeds, stored as it runs (Fig. 3(b))"
DESCRIPTION = """\
Reproduce the bifurcation diagram of Fig. 3(b) of the paper: every belt speed of
--vd x every initial condition of --ics (k = 1..N oscillators excited by eq. (8)
and/or eq. (10)) is integrated to --t-end, and the energy E of eq. (9) and the
number of oscillators on the high-amplitude limit cycle (n_HALC) are taken after
--transient. With no options: v_d = 1.0, 1.05, ..., 2.0, eq. (8), N = 20,
t_end = 15000, transient = 10000 (420 trajectories).

The trajectories run in batches of --batch-size over all cores. Each finished
batch is written to <out>/sweep.zarr (a zarr store, read with
xarray.open_zarr or jaxchain.open_sweep) before the next starts, so a crash or a
kill loses at most the batches running; --resume skips the stored ones. The store
records a hash of every setting: it is never resumed with other settings.
--scheduler runs each batch as a task on a Dask cluster (local:N starts N worker
processes here): a lost worker's batches are run again, the result is the
in-process one to the last bit on the same kind of device, and if the scheduler
goes away the command exits with status 1 and --resume (with or without a
cluster) finishes the store.

Prints, per belt speed, the distinct states found (n_HALC values) and the
fraction of initial conditions that make a propagating front: stick-slip invades
the sliding oscillators or recedes from them (n_HALC differs between the two
halves of the observed window, or from the number excited). Writes
<out>/sweep.png: E against v_d coloured by n_HALC, with the ranges of fronts
shaded (the paper's red dashed lines). A failed trajectory is marked in the store
and the exit status is 1."""


def _families(text: str) -> list[str]:
    """An argparse type: a comma-separated list of initial-condition families."""
    names = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [v for v in names if v not in FAMILIES]
    if not names or unknown:
        raise argparse.ArgumentTypeError(
            f"expected a list of {', '.join(sorted(FAMILIES))}, got {text!r}")
    return list(dict.fromkeys(names))


def add_parser(sub):
    p = sub.add_parser("sweep", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("grid (eq. (5) of the paper; other parameters eq. (7))")
    add_vd_option(g, belt_speeds("1.0:2.0:21"), "belt speeds")
    g.add_argument("--ics", type=_families, default=["eq8"], metavar="eq8,eq10",
                   help="initial-condition families, each with k = 1..N excited "
                        "oscillators around oscillator N//2+1 (default eq8)")
    add_ring_options(g)
    add_chain_options(g)
    add_run_options(p)
    s = p.add_argument_group("storage")
    s.add_argument("--batch-size", type=positive_int, default=64, metavar="B",
                   help="trajectories per stored batch (default 64); memory is set by "
                        "it, never by the grid")
    add_scheduler_option(s)
    add_output_options(p, resume="the sweep stored in DIR/sweep.zarr, or an --overwrite "
                                 "of it cut short, skipping its finished batches (refused "
                                 "if it was made with other settings); --overwrite builds "
                                 "the new store beside the old one and swaps it in once "
                                 "complete")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    params = chain_params(args, args.n_osc)
    engine = engine_of(args, simulation_options(args), params)
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    outputs = Outputs(args, data=["sweep.zarr"], figures=["sweep"])
    ics = {name: localized_family(params.n_osc, name, params.graph) for name in args.ics}
    store = outputs.path("sweep.zarr")

    start = time.perf_counter()
    with cluster_client(args) as client:
        ds = sweep(params, args.vd, ics, engine=engine,
                   batch_size=args.batch_size, store=store, resume=args.resume or outputs.again,
                   overwrite=args.overwrite, client=client,
                   progress=show_progress(args)).load()
    wall = time.perf_counter() - start
    outputs.figure(plot_bifurcation_diagram(ds, hopf_vd=hopf_speed(params, engine)),
                   "sweep")

    v_d = ds["v_d"].values
    status = status_names(ds["status"].values)
    ok = ds["status"].values == Status.ok
    n_halc = ds["n_halc"].values
    states = [sorted(set(n_halc[i][ok[i]].tolist())) for i in range(v_d.size)]
    fractions = front_fractions(ds)
    share = {kind: fractions.sel(direction=sign).values
             for kind, sign in (("invading", 1), ("receding", -1))}
    ranges = {kind: front_ranges(v_d, f > 0) for kind, f in share.items()}
    summary = (f"sweep: {ds.attrs['batches_done']}/{ds.attrs['batches_total']} batches "
               f"of {args.batch_size} ({ds.attrs['batches_run']} run now), "
               f"{n_halc.size} trajectories, {wall:.1f} s; {int((~ok).sum())} failed; "
               f"fronts invading at v_d in {_ranges_text(ranges['invading'])}, receding "
               f"at {_ranges_text(ranges['receding'])}; {outputs.summary()}")
    if args.json:
        print_json({
            "v_d": v_d.tolist(),
            "chain": chain_record(params),
            "family": ds["family"].values.tolist(),
            "n_excited": ds["n_excited"].values.tolist(),
            "n_halc": n_halc.tolist(),
            "energy": ds["energy"].values.tolist(),
            "status": status.tolist(),
            "fronts": ds["front"].values.tolist(),
            "front_ranges": ranges,
            "front_fraction": {k: f.tolist() for k, f in share.items()},
            "n_states": [len(s) for s in states],
            "batches_done": ds.attrs["batches_done"],
            "batches_total": ds.attrs["batches_total"],
            "batches_run": ds.attrs["batches_run"],
            "wall_time_s": wall,
            **engine_record(engine),
        }, outputs)
        note(summary)
    else:
        print(f"N = {args.n_osc}, {engine_text(engine)}, ics = "
              f"{','.join(args.ics)}, t_end = {args.t_end:g}, transient = {args.transient:g}")
        print(f"{'v_d':>6} {'states':>6} {'invading':>8} {'receding':>8}  n_HALC found")
        for i, v in enumerate(v_d):
            print(f"{v:6.3g} {len(states[i]):6d} {share['invading'][i]:8.0%} "
                  f"{share['receding'][i]:8.0%}  {' '.join(map(str, states[i]))}")
        note(summary)
    failed = int((~ok).sum())
    if failed:
        kinds = sorted(set(status[~ok].tolist()))
        raise RunsFailed(f"{failed} of {n_halc.size} trajectories failed "
                         f"({', '.join(kinds)}); they are marked in the store")


def _ranges_text(ranges) -> str:
    if not ranges:
        return "none"
    return ", ".join(f"[{lo:g}, {hi:g}]" for lo, hi in ranges)
