"""`jaxchain localized`: the staircase of localized states at each belt speed (Fig. 4
and the v_d column of Fig. 3(b) of the paper)."""

import argparse
import time

import numpy as np

from .._sweeps.ensemble import ensemble
from .._physics.initial import FAMILIES, localized_family
from .._engine.status import status_names
from .._physics.record import chain_record
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (RESULT_MODULES, Outputs, RunsFailed, add_model_options, add_output_options,
                     add_run_options, engine_of, engine_record, engine_text, note, prefetch,
                     print_json, show_progress, simulation_options, speeds_of_chain)

HELP = "localized states at each belt speed, N initial conditions (Fig. 4)"
DESCRIPTION = """\
Reproduce the staircase of localized states of Fig. 4 of the paper: N initial
conditions with 1, 2, ..., N oscillators excited (eq. (8) by default, or eq. (10)),
integrated to --t-end; amplitudes, the energy E of eq. (9) and the number of
oscillators on the high-amplitude limit cycle (n_HALC) are taken after --transient.
With no options this is the paper's scene: N = 20, v_d = 1.5, t_end = 15000,
transient = 10000.

Writes, for each belt speed V, <out>/localized_vd<V>.nc (xarray Dataset with all
parameters as attributes) and <out>/localized_vd<V>.png (circles of radius
proportional to amplitude, drawn on the grid for a lattice). With --chain and no
--vd, the chain file's v_d (or belt_speed) is run."""


def add_parser(sub):
    p = sub.add_parser("localized", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_options(p, vd=1.5, n_osc=20)
    add_chain_options(p.add_argument_group("chain"))
    p.add_argument("--ics", choices=sorted(FAMILIES), default="eq8",
                   help="initial-condition family: eq8 (at rest, the default) or eq10 "
                        "(x'(0) = 0.56); k = 1..N oscillators excited in a block "
                        "around oscillator N//2+1")
    add_run_options(p)
    add_output_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    prefetch(*RESULT_MODULES)
    params = chain_params(args, args.n_osc, v_d=args.vd[0])
    args.vd = speeds_of_chain(args, params)
    engine = engine_of(args, simulation_options(args), params)
    stems = [f"localized_vd{v:g}" for v in args.vd]
    outputs = Outputs(args, data=[f"{stem}.nc" for stem in stems], figures=stems)
    ics = localized_family(params.n_osc, args.ics, params.graph)
    n_excited = np.arange(1, params.n_osc + 1)

    start = time.perf_counter()
    ds = ensemble(params, args.vd, ics, engine=engine,
                  progress=show_progress(args))
    wall = time.perf_counter() - start

    from .._plots.localized import plot_localized_states

    ds.attrs["ics_family"] = args.ics
    ds.attrs["wall_time_s"] = wall
    rows, status = [], []
    for i, (v, stem) in enumerate(zip(args.vd, stems)):
        one = ds.isel(v_d=[i])
        outputs.dataset(one, f"{stem}.nc")
        outputs.figure(plot_localized_states(one), stem)
        row = one.isel(v_d=0)
        rows.append({"v_d": v, "n_excited": n_excited.tolist(),
                     "n_halc": row["n_halc"].values.tolist(),
                     "energy": row["energy"].values.tolist(),
                     "amplitudes": row["amplitudes"].values.tolist(),
                     "status": status_names(row["status"].values).tolist(),
                     "num_steps": row["num_steps"].values.tolist()})
        status += rows[-1]["status"]
    if args.json:
        print_json({"runs": rows, "wall_time_s": wall, **engine_record(engine),
                    "ics": args.ics, "chain": chain_record(params)}, outputs)
    else:
        for r in rows:
            print(f"v_d = {r['v_d']:g}, N = {params.n_osc}, {params.boundary}, "
                  f"{engine_text(engine)}, ics = {args.ics}")
            print(f"{'n_excited':>9} {'n_HALC':>6} {'E':>9} {'E/n_HALC':>8}  status")
            for k, nh, e, s in zip(n_excited, r["n_halc"], r["energy"], r["status"]):
                ratio = f"{e / nh:8.3f}" if nh > 0 else f"{'-':>8}"
                print(f"{k:9d} {int(nh):6d} {e:9.3f} {ratio}  {s}")
        note(f"wall time {wall:.1f} s (compilation included); {outputs.summary()}")
    failed = [s for s in status if s != "ok"]
    if failed:
        raise RunsFailed(f"{len(failed)} of {len(status)} trajectories failed "
                         f"({', '.join(sorted(set(failed)))}); their rows are marked")
