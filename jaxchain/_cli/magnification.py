"""`jaxchain magnification`: the forced mistuned ring with friction dampers, the
amplitude magnification of stiffness mistuning over draws (Whitehead's bound)."""

import argparse
import time

import numpy as np

from .._bifurcation.harmonic_balance import HarmonicBalance
from .._physics.forcing import Forcing
from .._physics.friction import Coulomb
from .._physics.params import ChainParams
from .._studies.magnification import magnification_gradient, magnification_study
from .common import (Outputs, RunsFailed, UsageError, add_output_options, comma_list,
                     non_negative_float, positive_float, positive_int, report, show_progress)

HELP = "forced mistuned ring with friction dampers: amplitude magnification (Whitehead)"
DESCRIPTION = """\
A bladed disk in miniature: the ring of eq. (5) (N oscillators, coupling eta_c,
damping ratio xi) under an engine-order force A cos(OMEGA t + 2 pi R n / N), its
belt at rest (v_d = 0), so that the friction contacts are dampers (Coulomb's law,
friction coefficient mu, smoothed by tanh(v/eps)). For each mistuning strength of
--sigmas (multiples of eta_c) --draws random stiffness mistunings (draw d: seed d,
the same normal numbers at every strength); for each, the forced response over the
frequencies of --frequencies by harmonic balance (--harmonics H, --time-samples M;
each orbit started from the one before, the draws vmapped), and its peak (the root
of the amplitude's slope in OMEGA beside each of the grid's three largest local
maxima; space the grid by xi / 2 or less, or a resonance can hide between points). The amplitude
magnification factor of a draw is its largest first-harmonic amplitude over the
tuned ring's. Each friction coefficient of --mu is a study of its own; mu = 0 is
the linear ring, whose magnification Whitehead's bound (1 + sqrt(N)) / 2 caps.

--gradient also differentiates the mean magnification at --gradient-sigma in the
first nonzero mu over the first --gradient-draws draws, by jax.grad and jax.jvp
(the implicit function theorem through each peak's orbit) and by central
differences of the whole study, and reports them.

Each (mu, sigma) goes to <out>/magnification_parts/ as it finishes: --resume
continues a killed run (a part is reused only with equal settings). Writes
<out>/magnification.nc (magnification, peak frequency and oscillator of every
draw, the tuned ring's peak, the chain and the method as attributes),
<out>/magnification.json (the statistics per mu and sigma, the gradient) and
<out>/magnification.png."""


def _frequency_grid(text: str) -> np.ndarray:
    parts = comma_list(float)(text)
    if len(parts) != 3 or not (0 < parts[0] < parts[1]) or parts[2] != int(parts[2]) \
            or parts[2] < 3:
        raise argparse.ArgumentTypeError(f"give LOW,HIGH,COUNT with 0 < LOW < HIGH and COUNT "
                                         f">= 3, got {text!r}")
    return np.linspace(parts[0], parts[1], int(parts[2]))


def add_parser(sub):
    p = sub.add_parser("magnification", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_argument_group("model (eq. (5) with an engine-order force, belt at rest)")
    g.add_argument("--n-osc", type=positive_int, default=20, metavar="N",
                   help="oscillators on the ring (default 20)")
    g.add_argument("--eta-c", type=positive_float, default=0.01,
                   help="coupling eta_c (default 0.01, the paper's)")
    g.add_argument("--xi", type=positive_float, default=2e-3,
                   help="damping ratio (default 2e-3: light, below the coupling)")
    g.add_argument("--amplitude", type=positive_float, default=4e-3, metavar="A",
                   help="force amplitude on each oscillator (default 4e-3: the tuned "
                        "linear ring's peak amplitude about 1)")
    g.add_argument("--engine-order", type=int, default=3, metavar="R",
                   help="engine order R: phase 2 pi R n / N (default 3)")
    g.add_argument("--mu", type=comma_list(non_negative_float), default=[0.0, 1e-3],
                   metavar="MU,...", help="friction coefficients of the dampers, each a "
                   "study (default 0,1e-3: the linear ring and one damped)")
    g.add_argument("--eps", type=positive_float, default=0.05,
                   help="tanh smoothing velocity of the dampers' friction (default 0.05, "
                        "against peak velocities of about 1)")
    g = p.add_argument_group("study")
    g.add_argument("--sigmas", type=comma_list(non_negative_float),
                   default=[0.1, 0.25, 0.5, 1.0, 2.0, 4.0], metavar="S,...",
                   help="mistuning strengths sigma / eta_c (default 0.1,0.25,0.5,1,2,4)")
    g.add_argument("--draws", type=positive_int, default=1000,
                   help="mistuned rings per strength (default 1000)")
    g.add_argument("--frequencies", type=_frequency_grid, default=_frequency_grid(
        "0.95,1.07,121"), metavar="LOW,HIGH,COUNT",
        help="forcing frequencies swept (default 0.95,1.07,121: every draw's resonances "
             "up to sigma = 4 eta_c, spaced by half the default xi)")
    g.add_argument("--harmonics", type=positive_int, default=1, metavar="H",
                   help="harmonic balance: highest harmonic (default 1, exact for the "
                        "linear ring)")
    g.add_argument("--time-samples", type=positive_int, default=64, metavar="M",
                   help="harmonic balance: time samples of a period (default 64)")
    g.add_argument("--lanes", type=positive_int, default=256,
                   help="rings solved together, vmapped (default 256)")
    g.add_argument("--gradient", action="store_true",
                   help="differentiate the mean magnification in mu (jax.grad and "
                        "central differences)")
    g.add_argument("--gradient-sigma", type=non_negative_float, default=1.0, metavar="S",
                   help="sigma / eta_c of --gradient (default 1)")
    g.add_argument("--gradient-draws", type=positive_int, default=200, metavar="D",
                   help="draws of --gradient, the first D of the study's (default 200: "
                        "the check runs the study three times)")
    add_output_options(p, resume="a killed run from its finished (mu, sigma) parts")
    p.set_defaults(run=run)
    return p


def run(args) -> None:
    if args.engine_order < 0:
        raise UsageError(f"--engine-order: must be >= 0, got {args.engine_order}")
    if args.gradient and not any(m > 0 for m in args.mu):
        raise UsageError("--gradient: give a nonzero friction coefficient in --mu")
    # the library's checks name a bad value (ValidationError: exit status 2)
    params = ChainParams(n_osc=args.n_osc, xi=args.xi, eta_c=args.eta_c, v_d=0.0,
                         friction=Coulomb(mu=max(args.mu)),
                         forcing=Forcing.engine_order(args.n_osc, args.engine_order,
                                                      args.amplitude, 1.0))
    method = HarmonicBalance(eps=args.eps, harmonics=args.harmonics,
                             time_samples=args.time_samples, linear_solver="lu",
                             newton_tol=1e-10, newton_steps=8)
    outputs = Outputs(args, data=["magnification.nc", "magnification.json"],
                      figures=["magnification"])
    sigmas = [s * args.eta_c for s in args.sigmas]
    start = time.perf_counter()
    ds = magnification_study(params, sigmas, args.draws, args.frequencies, method,
                             friction_coefficients=args.mu, lanes=args.lanes,
                             progress=show_progress(args),
                             store=outputs.path("magnification_parts"))
    summary = {"whitehead_bound": ds.attrs["whitehead_bound"], "studies": []}
    for mu in ds["mu"].values:
        for s in ds["sigma"].values:
            m = ds["magnification"].sel(mu=mu, sigma=s)
            ok = ds["converged"].sel(mu=mu, sigma=s).values
            summary["studies"].append({
                "mu": float(mu), "sigma_over_eta_c": float(s / args.eta_c),
                "mean": float(m.values[ok].mean()) if ok.any() else None,
                "p95": float(np.percentile(m.values[ok], 95)) if ok.any() else None,
                "max": float(m.values[ok].max()) if ok.any() else None,
                "failed": int((~ok).sum())})
    if args.gradient:
        mu = min(m for m in args.mu if m > 0)
        from .._physics.params import with_parameter

        summary["gradient"] = {"mu": mu, "sigma_over_eta_c": args.gradient_sigma} | \
            magnification_gradient(with_parameter(params, "mu", mu),
                                   args.gradient_sigma * args.eta_c,
                                   min(args.gradient_draws, args.draws),
                                   args.frequencies, method, lanes=args.lanes)
    wall = time.perf_counter() - start
    summary["wall_time_s"] = wall
    outputs.dataset(ds, "magnification.nc")
    from .._plots.magnification import plot_magnification

    outputs.figure(plot_magnification(ds), "magnification")
    failed = sum(s["failed"] for s in summary["studies"])

    def table(s):
        print(f"amplitude magnification over {args.draws} draws (Whitehead's bound "
              f"{s['whitehead_bound']:.4f})")
        print(f"{'mu':>8} {'sigma/eta_c':>11} {'mean':>8} {'p95':>8} {'max':>8} {'failed':>6}")
        for row in s["studies"]:
            values = " ".join("     n/a" if row[k] is None else f"{row[k]:8.4f}"
                              for k in ("mean", "p95", "max"))
            print(f"{row['mu']:8.3g} {row['sigma_over_eta_c']:11.3g} {values} "
                  f"{row['failed']:6d}")
        if "gradient" in s:
            g = s["gradient"]
            print(f"d(mean magnification)/d mu at mu = {g['mu']:g}, sigma = "
                  f"{g['sigma_over_eta_c']:g} eta_c: {g['gradient']:.8g} (jax.grad), "
                  f"{g['forward']:.8g} (jax.jvp), "
                  f"{g['finite_difference']:.8g} (central differences), relative "
                  f"difference {g['relative_error']:.2e}")

    report(summary, outputs, "magnification.json", args.json, table, wall)
    if failed:
        raise RunsFailed(f"{failed} draws did not converge at every frequency: they are "
                         f"flagged in magnification.nc (converged = false)")
