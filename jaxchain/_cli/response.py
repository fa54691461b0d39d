"""`jaxchain response`: the frequency-response curve of a forced chain, by harmonic
balance or shooting and continuation in the forcing frequency."""

import argparse
import time

import numpy as np

from .._bifurcation.harmonic_balance import HarmonicBalance
from .._bifurcation.shooting import Shooting
from .._engine.engines import Smoothed
from .._studies.response import frequency_response
from .chain import CHAIN_HELP, add_chain_options, chain_params
from .common import (Outputs, RunsFailed, UsageError, add_output_options, add_ring_options,
                     belt_speed_or_rest, param_default, positive_float, positive_int, report,
                     show_progress)

HELP = "frequency-response curve of a forced chain (harmonic balance, shooting)"
DESCRIPTION = """\
Follow the periodic orbits of a chain under a harmonic force (--force A,OMEGA[,R]:
amplitude A on each oscillator, frequency OMEGA, engine order R) from OMEGA to --to
by pseudo-arclength continuation in the forcing frequency, which passes the
curve's folds; each orbit's Floquet multipliers give its stability. The belt may
stand still (--vd 0, the default here): a friction damper. --method hb (default)
solves each orbit by harmonic balance (--harmonics H, --time-samples M: the
alternating frequency-time scheme), --method shooting by shooting on the smoothed
engine; both smooth the friction law with --eps. A friction force that jumps
(Coulomb's law, --friction coulomb:mu=...) makes harmonic balance converge only as
1/H: give H of 64 or more, and M of 16 H or more, for amplitudes to 1e-3.

Writes <out>/response.nc (the amplitude of each oscillator, the largest, and the
stability at each point, with the chain and the method as attributes),
<out>/response.png and <out>/response.json (the folds' frequencies, the peak)."""


def add_parser(sub):
    p = sub.add_parser("response", help=HELP, description=DESCRIPTION + "\n\n" + CHAIN_HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5) of the paper with a harmonic force)")
    g.add_argument("--vd", type=belt_speed_or_rest, default=None, metavar="V",
                   help="belt speed v_d (default 0 with --force: a friction damper; a "
                        "chain file's own otherwise)")
    g.add_argument("--xi", type=positive_float, default=param_default("xi"),
                   help=f"damping ratio (default {param_default('xi'):g})")
    add_ring_options(g, n_osc=1)
    add_chain_options(g, forcing=True)
    g = p.add_argument_group("analysis")
    g.add_argument("--to", type=positive_float, required=False, default=None, metavar="OMEGA",
                   help="the other end of the frequency range (required)")
    g.add_argument("--method", choices=("hb", "shooting"), default="hb",
                   help="harmonic balance (default) or shooting")
    g.add_argument("--harmonics", type=positive_int, default=32, metavar="H",
                   help="harmonic balance: the highest harmonic (default 32)")
    g.add_argument("--time-samples", type=positive_int, default=None, metavar="M",
                   help="harmonic balance: time samples of a period (default the "
                        "smallest power of two >= 4H + 1)")
    g.add_argument("--max-points", type=positive_int, default=300,
                   help="the continuation's budget of points (default 300)")
    add_output_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    if args.force is None and args.chain is None:
        raise UsageError("--force: give the force (A,OMEGA[,R]) or a chain file with "
                         "force_amplitude and force_frequency")
    fields = {"xi": args.xi}
    if args.vd is not None or args.force is not None:
        fields["v_d"] = 0.0 if args.vd is None else args.vd
    params = chain_params(args, args.n_osc, **fields)
    if params.forcing is None:
        raise UsageError("--force: give the force (A,OMEGA[,R]) or a chain file with "
                         "force_amplitude and force_frequency")
    if args.to is None:
        raise UsageError("--to: give the other end of the frequency range")
    if args.to == float(params.forcing.frequency):
        raise UsageError(f"--to: must differ from the force's frequency {args.to:g}")
    if args.method == "hb":
        method = HarmonicBalance(eps=args.eps, harmonics=args.harmonics,
                                 time_samples=args.time_samples)
    else:
        method = Shooting(Smoothed(eps=args.eps).for_orbits())
    outputs = Outputs(args, data=["response.nc", "response.json"], figures=["response"])
    from .._bifurcation.continuation import ContinuationOptions

    start = time.perf_counter()
    try:
        ds = frequency_response(params, method, args.to,
                                ContinuationOptions(ds=0.05, ds_max=0.5,
                                                    max_points=args.max_points),
                                progress=show_progress(args))
    except RuntimeError as err:
        raise RunsFailed(f"the forced orbit at OMEGA = {float(params.forcing.frequency):g}: "
                         f"{err}") from None
    wall = time.perf_counter() - start
    outputs.dataset(ds, "response.nc")
    from .._plots.response import plot_frequency_response

    outputs.figure(plot_frequency_response(ds), "response")
    peak = int(np.argmax(ds["max_amplitude"].values))
    summary = {"points": ds.sizes["point"], "stop": ds.attrs["stop"],
               "fold_frequencies": ds.attrs["fold_frequencies"],
               "peak_frequency": float(ds["frequency"][peak]),
               "peak_amplitude": float(ds["max_amplitude"][peak]),
               "unstable_points": int((~ds["stable"]).sum()), "wall_time_s": wall}

    def table(s):
        print(f"{s['points']} orbits from OMEGA = {float(ds['frequency'][0]):g} to "
              f"{float(ds['frequency'][-1]):g} ({s['stop']}); peak {s['peak_amplitude']:.6g} "
              f"at OMEGA = {s['peak_frequency']:.6g}; folds at "
              f"{', '.join(f'{f:.6g}' for f in s['fold_frequencies']) or 'none'}; "
              f"{s['unstable_points']} unstable")

    report(summary, outputs, "response.json", args.json, table, wall)
