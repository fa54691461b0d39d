"""`jaxchain basin`: basin stability of the chain's states over belt speeds."""

import argparse
import time

import numpy as np

from .._studies.basin.basin import BASIN_OPTIONS, basin_stability
from .._studies.basin.sampling import Box
from .._engine.status import Status
from .._plots.basin import plot_basin_stability, plot_halc_histogram
from .._physics.record import chain_record
from .._physics.forces import DEFAULT_EPS
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_scheduler_option,
                     add_solver_options, add_vd_option, cluster_client, engine_of,
                     engine_record, note, positive_float, positive_int, print_json,
                     show_progress, simulation_options)

HELP = "basin stability: how likely each state is from random initial states"
DESCRIPTION = """\
Draw --samples initial states uniformly from the box x_n(0) in --x-range, x_n'(0) in
--v-range (independently for each oscillator, with the JAX PRNG key of
--sample-seed), run
each at every belt speed of --vd to --t-end, and classify the state after
--transient by n_HALC (for one oscillator: steady sliding or stick-slip) and by the
number of separate groups of HALC oscillators. Prints, per belt speed, the fraction
of samples in each class with its 95 % Wilson interval (Menck et al., Nature
Physics 9, 89 (2013)). A subset of --check samples (up to 50 by default) runs again
to 2 t_end: the share whose class changed says whether t_end was long enough, and
its stick-slip states are classified periodic or irregular by their time delays.

The runs are stored batch by batch in <out>/basin.zarr (--resume continues a killed
run with the same settings); --scheduler runs the batches on a Dask cluster (local:N:
N worker processes here), with the in-process result to the last bit on the same kind
of device (the convergence subset runs in this process). Writes <out>/basin.nc (the
result, with the sampled initial states and the key), <out>/basin.png (the
probabilities against v_d as stacked areas) and <out>/basin_halc.png (the
distribution of n_HALC at the belt speed nearest 1.5). --quick: one oscillator,
v_d = 0.8:2.2:8, 200 samples, t_end 500."""


def _pair(text: str) -> tuple[float, float]:
    """An argparse type: LO,HI with LO < HI, both finite."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO,HI, got {text!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise argparse.ArgumentTypeError(f"expected finite LO < HI, got {text!r}")
    return lo, hi


def add_parser(sub):
    p = sub.add_parser("basin", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    box = Box()
    add_vd_option(p, None, "belt speeds (the command's choice: 1.5; --quick 0.8:2.2:8)")
    p.add_argument("--n-osc", type=positive_int, default=None, metavar="N",
                   help="oscillators on the ring (default 20; --quick 1)")
    p.add_argument("--samples", type=positive_int, default=None, metavar="S",
                   help="initial states per belt speed (default 1000; --quick 200)")
    p.add_argument("--x-range", type=_pair, default=box.x, metavar="LO,HI",
                   help=f"box of x_n(0) (default {box.x[0]:g},{box.x[1]:g}; write "
                        "--x-range=-3,3 when LO is negative)")
    p.add_argument("--v-range", type=_pair, default=box.v, metavar="LO,HI",
                   help=f"box of x_n'(0) (default {box.v[0]:g},{box.v[1]:g})")
    p.add_argument("--check", type=int, default=None, metavar="C",
                   help="samples of the convergence check, run again to 2 t_end "
                        "(default min(S, 50); 0 for none)")
    p.add_argument("--sample-seed", type=int, default=0, metavar="K",
                   help="seed of the JAX PRNG key of the initial states (default 0)")
    p.add_argument("--eps", type=positive_float, default=DEFAULT_EPS,
                   help=f"tanh smoothing velocity (default {DEFAULT_EPS:g})")
    add_chain_options(p.add_argument_group("chain"))
    g = p.add_argument_group("integration")
    g.add_argument("--t-end", type=positive_float, default=None, metavar="T",
                   help=f"final time (default {BASIN_OPTIONS.t_end:g}; --quick 500)")
    g.add_argument("--transient", type=float, default=None, metavar="T",
                   help=f"classify after this time (default {BASIN_OPTIONS.transient:g}; "
                        "--quick 400)")
    add_solver_options(g)
    add_scheduler_option(p)
    p.add_argument("--quick", action="store_true", help="the small single-oscillator run")
    add_output_options(p, resume="the runs stored in DIR/basin.zarr (a killed run with "
                                 "the same settings)")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    quick = args.quick
    v_d = args.vd or (list(np.linspace(0.8, 2.2, 8).round(12)) if quick else [1.5])
    n_osc = args.n_osc or (1 if quick else 20)
    samples = args.samples or (200 if quick else 1000)
    t_end = args.t_end or (500.0 if quick else BASIN_OPTIONS.t_end)
    transient = args.transient if args.transient is not None else (
        400.0 if quick else t_end - (BASIN_OPTIONS.t_end - BASIN_OPTIONS.transient))
    if not 0 <= transient < t_end:
        raise UsageError(f"--transient must lie in [0, t_end = {t_end:g}), got {transient:g}")
    box = Box(x=tuple(args.x_range), v=tuple(args.v_range))
    options = simulation_options(args, t_end=t_end, transient=transient)
    params = chain_params(args, n_osc)
    n_osc = params.n_osc
    engine = engine_of(args, options, params)
    outputs = Outputs(args, data=["basin.zarr", "basin.nc"], figures=["basin", "basin_halc"])
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    start = time.perf_counter()
    with cluster_client(args) as client:
        ds = basin_stability(params, v_d, samples, box, args.sample_seed,
                             engine=engine, n_check=args.check,
                             store=outputs.path("basin.zarr"),
                             resume=args.resume or outputs.again,
                             overwrite=args.overwrite, client=client,
                             progress=show_progress(args))
    wall = time.perf_counter() - start
    outputs.dataset(ds, "basin.nc")
    outputs.figure(plot_basin_stability(ds), "basin")
    outputs.figure(plot_halc_histogram(ds, 1.5), "basin_halc")
    classes = ds["class"].values.tolist()
    shown = [c for c in range(len(classes)) if ds["counts"].values[:, c].any()]
    if args.json:
        print_json({
            "v_d": ds["v_d"].values.tolist(), "classes": classes,
            **engine_record(engine),
            "chain": chain_record(params),
            "counts": ds["counts"].values.tolist(),
            "fractions": ds["fraction"].values.tolist(),
            "ci_low": ds["ci_low"].values.tolist(), "ci_high": ds["ci_high"].values.tolist(),
            "n_samples": samples, "wall_time_s": wall,
            "changed_fraction": ds["changed_fraction"].values.tolist(),
            "periodic_fraction": ds["periodic_fraction"].values.tolist(),
            "periodic_ci_low": ds["periodic_ci_low"].values.tolist(),
            "periodic_ci_high": ds["periodic_ci_high"].values.tolist(),
            "n_check": int(ds.attrs["n_check"]), "scheduler": args.scheduler,
            "n_osc": n_osc, "box": {"x": list(box.x), "v": list(box.v)},
            "sample_seed": args.sample_seed, "t_end": t_end, "transient": transient},
            outputs)
    else:
        print(f"N = {n_osc}, {samples} samples, x in {list(box.x)}, x' in {list(box.v)}, "
              f"sample seed {args.sample_seed}, t_end = {t_end:g}, classified after {transient:g}")
        for i, v in enumerate(ds["v_d"].values):
            parts = [f"{classes[c]} {ds['fraction'].values[i, c]:.3f} "
                     f"[{ds['ci_low'].values[i, c]:.3f}, {ds['ci_high'].values[i, c]:.3f}]"
                     for c in shown if ds["counts"].values[i, c]]
            print(f"v_d = {v:g}: " + "; ".join(parts)
                  + f" (class changed at 2 t_end: {ds['changed_fraction'].values[i]:.0%})")
        note(f"{wall:.1f} s; {outputs.summary()}")
    failed = int((ds["status"].values != Status.ok).sum())
    if failed:
        raise RunsFailed(f"{failed} of {ds['status'].size} runs failed; they are counted "
                         "in the class 'failed'")
