"""`jaxchain identify`: friction and damping fitted to measured stick-slip records,
with their standard errors, and the choice between friction laws."""

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np

from .._physics.params import parameter_names
from .._physics.record import chain_record
from .._studies.identification.fit import FIT_ATOL, FIT_EPS, FIT_RTOL, IdentifyOptions, fit_engine
from .._studies.identification.unknowns import CHAIN_FITTABLE
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_solver_options,
                     comma_list, note, one_belt_speed, positive_float, positive_int,
                     print_json)

HELP = "fit friction and damping to measured stick-slip records"
DESCRIPTION = f"""\
Fit the named parameters of the chain and its friction law (--fit) to measured
records of the rig, one CSV file per belt speed, by least squares through the
integration of eq. (5) (smoothed friction, eps = {FIT_EPS:g} unless --eps says
otherwise; or with --engine exact the stick/slip switch model itself, differentiated
through every switch, without the smoothing's bias), and print them with their
standard errors.

A record has a column t, one column x<n> per measured oscillator (n from 1, as in
the paper; any subset), optionally v<n> velocity columns, and a constant column v_d
or the belt speed given by --vd. It is dimensionless (eqs. (4)-(6)), or in SI units
(s, m, m/s) when the chain file has units = "SI".

Each record is cut into windows of --window time units (multiple shooting), each
with its own fitted initial state; Levenberg-Marquardt (optimistix) fits, with
Jacobians by forward-mode differentiation through diffrax, first letting windows
jump, then closing the jumps. The standard errors come from the Gauss-Newton
covariance with the residual variance; an ill-conditioned fit is named with its
poorly determined direction. Starting values: the breakaway positions give mu(0)
and xi; --start NAME=V,... or the chain's values give the others.

--laws L1,L2,... fits each friction law (all its parameters, and xi) and judges it
on the held-out records (--held-out; by default the last FILE), with the residual
and the information criteria AIC and BIC; the law with the lowest held-out residual
is written as the fitted chain.

Writes <out>/identified_chain.toml (a chain file every command reads with
--chain), <out>/fit_<record>.csv (measured, fitted, residual; records of the same
name in different folders as fit_<folder>_<record>.csv), and the figures
<out>/identification_fits.png and <out>/identified_friction.png (mu(v) with its
95 % band)."""


def add_parser(sub):
    p = sub.add_parser("identify", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("records", nargs="+", type=Path, metavar="FILE",
                   help="the records, CSV files (one belt speed each)")
    g = p.add_argument_group("fit")
    g.add_argument("--fit", type=comma_list(str), default=["mu_st", "mu_d", "v0", "xi"],
                   metavar="NAME,...",
                   help="the fitted parameters: of the friction law and of xi, eta_c, "
                        "stiffness, load, mass (default mu_st,mu_d,v0,xi)")
    g.add_argument("--vd", type=one_belt_speed, default=None, metavar="V",
                   help="the belt speed of records without a v_d column")
    g.add_argument("--start", type=_assignments, default={}, metavar="NAME=V,...",
                   help="starting values of fitted parameters")
    g.add_argument("--offsets", action="store_true",
                   help="also fit a sensor offset per record (on its displacements)")
    g.add_argument("--window", type=positive_float, default=IdentifyOptions().window,
                   metavar="T", help="length of a multiple-shooting window (default "
                                     f"{IdentifyOptions().window:g})")
    g.add_argument("--laws", type=comma_list(str), default=None, metavar="L1,L2,...",
                   help="compare friction laws on held-out records")
    g.add_argument("--held-out", nargs="+", type=Path, default=None, metavar="FILE",
                   help="records held out for --laws (default: the last FILE)")
    g = p.add_argument_group("chain (the values of the parameters that are not fitted)")
    g.add_argument("--n-osc", type=positive_int, default=None, metavar="N",
                   help="number of oscillators (default: the highest measured)")
    add_chain_options(g, mistuning=False)
    g = p.add_argument_group("integration of the windows (tighter than a simulation's: "
                             "the fit needs accurate sensitivities)")
    add_solver_options(g, rtol=FIT_RTOL, atol=FIT_ATOL)
    g.add_argument("--eps", type=positive_float, default=FIT_EPS,
                   help=f"the smoothed engine's tanh smoothing velocity of sign(v_rel) "
                        f"(default {FIT_EPS:g}: a bias of the fit, linear in eps; the "
                        "exact engine has none)")
    add_output_options(p)
    p.set_defaults(run=run)
    return p


def _assignments(text: str) -> dict:
    out = {}
    for item in filter(None, text.split(",")):
        key, sep, value = item.partition("=")
        try:
            out[key] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise argparse.ArgumentTypeError(f"expected NAME=V,..., got {item!r}")
    return out


def run(args) -> None:
    files, held_files = _check_identify(args)
    names = _fit_names(files)
    params, records, held_out = _read_records(args, files, held_files)
    # the engine value, built once from --engine, --eps and the solver options
    engine = fit_engine(args.engine, solver=args.solver, eps=args.eps, rtol=args.rtol,
                        atol=args.atol, controller=args.controller,
                        max_steps=args.max_steps, params=params)
    options = IdentifyOptions(window=args.window, engine=engine)
    outputs = Outputs(args, data=["identified_chain.toml", *names],
                      figures=["identification_fits", "identified_friction"])
    start = time.perf_counter()
    result, comparison = _fit(args, records, held_out, params, options)
    wall = time.perf_counter() - start
    for row in comparison:
        if not row["best"]:
            for text in row["fit"].warnings:
                note(f"{row['law']}: warning: {text}")
    _write(outputs, result, names, records)
    _print(args, result, comparison, files, held_files, wall, outputs)
    if not result.converged:
        raise RunsFailed("the fit did not converge; its last iterate is written")


def _check_identify(args) -> tuple[list, list]:
    """The records fitted and held out (for --laws: --held-out, by default the last
    FILE).

    **Raises:** `UsageError` when every record is held out, or for --held-out
    without --laws."""
    files = list(args.records)
    held_files = []
    if args.laws:
        held_files = list(args.held_out) if args.held_out else files[-1:]
        files = [f for f in files if f not in held_files]
        if not files:
            raise UsageError("--laws: every record is held out; give more records than "
                             "--held-out names")
    elif args.held_out:
        raise UsageError("--held-out is for --laws")
    return files, held_files


def _fit_names(files) -> list[str]:
    """The name of each record's fit: fit_<record>.csv, or where two records share a
    name (a/rig.csv, b/rig.csv), fit_<folder>_<record>.csv with as many of their
    folders as tell them apart.

    **Raises:** `UsageError` for a record given twice, or records that no folder
    tells apart (rig.csv and rig.txt)."""
    parts = [Path(os.path.abspath(f)).with_suffix("").parts[1:] for f in files]
    names = []
    for i, own in enumerate(parts):
        others = [p for j, p in enumerate(parts) if j != i]
        depth = 1
        while depth < len(own) and any(p[-depth:] == own[-depth:] for p in others):
            depth += 1
        names.append("fit_" + "_".join(own[-depth:]) + ".csv")
    for i, name in enumerate(names):
        if name in names[:i]:
            first = files[names.index(name)]
            same = os.path.abspath(first) == os.path.abspath(files[i])
            raise UsageError(f"{files[i]}: given twice" if same else
                             f"{first} and {files[i]}: records of the same name, told apart by no "
                             f"folder (their fits would both be {name}); rename one")
    return names


def _read_records(args, files, held_files) -> tuple:
    """(the chain, the fitted records, the held-out records): the chain of the
    options, as long as the highest measured oscillator unless --n-osc or --chain
    says otherwise.

    **Raises:** `UsageError` for a --fit name that is not a parameter of the chain."""
    from .._studies.identification.records import read_record

    params = chain_params(args, args.n_osc or 1)
    scales = params.scales

    def read(paths):
        return [read_record(f, args.vd, scales) for f in paths]

    records, held_out = read(files), read(held_files)
    highest = max(max(r.oscillators) for r in records + held_out)
    if args.n_osc is None and args.chain is None and highest > params.n_osc:
        params = chain_params(args, highest)
    for name in args.fit:
        if name not in parameter_names(params) and not args.laws:
            raise UsageError(f"--fit: unknown parameter {name!r} for this chain: choose "
                             f"from {', '.join(parameter_names(params))}")
    return params, records, held_out


def _fit(args, records, held_out, params, options) -> tuple:
    """(the fit, the comparison of the laws of --laws: one row each, empty without):
    with --laws the fit of the law of lowest held-out residual."""
    from .._studies.identification.choice import compare_laws
    from .._studies.identification.fit import identify

    comparison = []
    with warnings.catch_warnings():  # each fit keeps its warnings: printed below
        warnings.simplefilter("ignore")
        if args.laws:
            chain_fit = [n for n in args.fit if n in CHAIN_FITTABLE]
            comparison = compare_laws(records, held_out, params, args.laws,
                                      fit_chain=chain_fit, offsets=args.offsets,
                                      options=options)
            result = next(row["fit"] for row in comparison if row["best"])
        else:
            result = identify(records, params, args.fit, start=args.start,
                              offsets=args.offsets, options=options)
    return result, comparison


def _write(outputs, result, names, records) -> None:
    """The fitted chain file, each record's fit as CSV (`names`), and the two
    figures."""
    from .._plots.identification import plot_friction_band, plot_record_fits
    from .._sweeps.chain_files import write_chain_file

    write_chain_file(result.chain, outputs.path("identified_chain.toml"))
    for name, rec, fitted in zip(names, records, result.fits):
        outputs.text(_fit_csv(rec, fitted), name)
    outputs.figure(plot_record_fits(result, records), "identification_fits")
    outputs.figure(plot_friction_band(result), "identified_friction")


def _print(args, result, comparison, files, held_files, wall, outputs) -> None:
    """The fit (and the laws' table) as one JSON document with --json, otherwise as
    lines, with a note of the wall time and the files written."""
    rows = [{"law": r["law"], "sigma": r["sigma"], "aic": r["aic"], "bic": r["bic"],
             "held_out_rms": r["held_out_rms"], "best": r["best"],
             "parameters": r["fit"].to_dict()["parameters"],
             "warnings": list(r["fit"].warnings)} for r in comparison]
    if args.json:
        print_json(result.to_dict() | {"laws": rows, "chain": chain_record(result.chain),
                                       "records": [str(f) for f in files],
                                       "held_out": [str(f) for f in held_files],
                                       "window": args.window, "wall_time_s": wall},
                   outputs)
    else:
        if rows:
            print(f"{'law':<12}{'sigma':>11}{'AIC':>11}{'BIC':>11}{'held-out rms':>14}")
            for r in rows:
                print(f"{r['law']:<12}{r['sigma']:11.4g}{r['aic']:11.1f}{r['bic']:11.1f}"
                      f"{r['held_out_rms']:14.4g}{'  <- best' if r['best'] else ''}")
            print()
        print(result.summary())
        note(f"wall time {wall:.1f} s; {outputs.summary()}")


def _fit_csv(rec, fitted) -> str:
    columns = {"t": rec.t}
    for k, n in enumerate(rec.oscillators):
        columns[f"x{n}"] = rec.x[:, k]
        columns[f"x{n}_fit"] = fitted[:, k]
        columns[f"x{n}_residual"] = rec.x[:, k] - fitted[:, k]
    table = np.column_stack(list(columns.values()))
    lines = [",".join(columns)] + [",".join(f"{v:.10g}" for v in row) for row in table]
    return "\n".join(lines) + "\n"
