"""Where the steps of the Fig. 4 scene go: every attempted step of a window of the
scene's trajectories, accepted or rejected, classified by what the chain was doing.

    python benchmarks/steps.py [--k 1,5,10,20] [--window 2000,2100] [--rtol 1e-5]
                               [--atol 1e-7] [--pcoeff 0] [--icoeff 1] [--out DIR]

The scene is the paper's ring (N = 20, v_d = 1.5, eq. (8) with k oscillators
excited), integrated by the default solver at the default eps (`DEFAULT_EPS`) to
the window's start without recording, then over the window with a step-size
controller that reports every attempted step (a host callback: slow, for
measurement only). A step is

- `switch`: an oscillator enters or leaves the stick band (`STICK_BAND` eps) between
  its start and its end;
- `near switch`: within `NEAR` time units of a switch step (the approach, with
  its rejections, and the growth of the step size after it);
- `stick`: otherwise, with at least one oscillator in the stick band;
- `slip`: otherwise (every oscillator slipping).

Prints a table per k (accepted and rejected steps per class, switches, steps per
switch) and writes DIR/steps.md and DIR/steps.json.
"""

import argparse
import json
import sys
from pathlib import Path

import diffrax
import jax
import numpy as np

import jaxchain as jc
from jaxchain._physics.forces import DEFAULT_EPS
from jaxchain._engine.solver.registry import DEFAULT_SOLVER
from jaxchain._physics.model import Model
from jaxchain._physics.stick import STICK_BAND
from jaxchain._engine.smoothed import terms

jc.configure()  # float64, one CPU device per core, the XLA flags

#: Half-width (time units) of the neighbourhood of a switch step.
NEAR = 0.05
CLASSES = ("switch", "near switch", "stick", "slip")

_steps = []


def _record(t0, t1, keep, v0, v1):
    _steps.append((float(t0), float(t1), bool(keep), np.asarray(v0), np.asarray(v1)))


class ReportingPID(diffrax.PIDController):
    """diffrax's PID controller, reporting each attempted step to the host."""

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order,
                        controller_state):
        out = super().adapt_step_size(t0, t1, y0, y1_candidate, args, y_error,
                                      error_order, controller_state)
        jax.debug.callback(_record, t0, t1, out[0], y0[1], y1_candidate[1], ordered=True)
        return out


def classify(steps, v_d: float, eps: float) -> dict:
    """Counts of accepted and rejected steps per class (see the module's doc)."""
    t0 = np.array([s[0] for s in steps])
    keep = np.array([s[2] for s in steps])
    band = STICK_BAND * eps
    stuck0 = np.array([np.abs(s[3] - v_d) <= band for s in steps])
    stuck1 = np.array([np.abs(s[4] - v_d) <= band for s in steps])
    switch = np.any(stuck0 != stuck1, axis=1)
    switch_times = t0[switch & keep]
    near = np.zeros(len(t0), bool)
    for t in switch_times:
        near |= np.abs(t0 - t) < NEAR
    kind = np.where(switch, 0, np.where(near, 1, np.where(stuck0.any(axis=1), 2, 3)))
    counts = {c: {"accepted": int(np.sum((kind == i) & keep)),
                  "rejected": int(np.sum((kind == i) & ~keep))}
              for i, c in enumerate(CLASSES)}
    total = len(steps)
    return {"classes": counts, "switches": int(len(switch_times)), "steps": total,
            "rejected": int(np.sum(~keep)),
            "steps_per_switch": (int(np.sum(switch | near)) / max(len(switch_times), 1))}


def census(k: int, window: tuple[float, float], controller: dict) -> dict:
    params = jc.ChainParams(v_d=1.5)
    model = Model(params, DEFAULT_EPS)  # the diffrax args of a smoothed run
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(params.n_osc, k))(params)
    solver = jc.SOLVERS[DEFAULT_SOLVER]()
    field = terms(solver)
    start = diffrax.diffeqsolve(field, solver, 0.0, window[0], None, y0, model,
                                stepsize_controller=diffrax.PIDController(**controller),
                                max_steps=10**7)
    _steps.clear()
    diffrax.diffeqsolve(field, solver, window[0], window[1], None, start.ys[-1], model,
                        stepsize_controller=ReportingPID(**controller), max_steps=10**7)
    jax.effects_barrier()
    return classify(_steps, params.v_d, model.eps)


def markdown(results: dict, args) -> str:
    lines = [f"Steps of the Fig. 4 scene (N = 20, v_d = 1.5, eq. (8)) over t in "
             f"[{args.window[0]:g}, {args.window[1]:g}], {DEFAULT_SOLVER}, rtol "
             f"{args.rtol:g}, atol {args.atol:g}, pcoeff {args.pcoeff:g}, icoeff "
             f"{args.icoeff:g}. Accepted / rejected per class; `near switch` is within "
             f"{NEAR} time units of a switch step.", "",
             "| k | " + " | ".join(CLASSES) + " | all | switches | steps per switch |",
             "|" + "---|" * (len(CLASSES) + 4)]
    for k, r in results.items():
        cells = [f"{r['classes'][c]['accepted']} / {r['classes'][c]['rejected']}"
                 for c in CLASSES]
        lines.append(f"| {k} | " + " | ".join(cells)
                     + f" | {r['steps'] - r['rejected']} / {r['rejected']} | "
                       f"{r['switches']} | {r['steps_per_switch']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--k", default="1,5,10,20",
                        help="numbers of excited oscillators (default 1,5,10,20)")
    parser.add_argument("--window", default="2000,2100",
                        help="the recorded window T0,T1 (default 2000,2100)")
    parser.add_argument("--rtol", type=float, default=1e-5)
    parser.add_argument("--atol", type=float, default=1e-7)
    parser.add_argument("--pcoeff", type=float, default=0.0)
    parser.add_argument("--icoeff", type=float, default=1.0)
    parser.add_argument("--out", type=Path, default=Path("docs/benchmarks"))
    args = parser.parse_args(argv)
    args.window = tuple(float(v) for v in args.window.split(","))
    controller = dict(rtol=args.rtol, atol=args.atol, pcoeff=args.pcoeff,
                      icoeff=args.icoeff)
    results = {}
    for k in (int(v) for v in args.k.split(",")):
        results[k] = census(k, args.window, controller)
        print(f"k = {k}: {results[k]['steps']} steps, {results[k]['rejected']} rejected, "
              f"{results[k]['switches']} switches", file=sys.stderr, flush=True)
    table = markdown(results, args)
    print(table)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "steps.md").write_text(table)
    (args.out / "steps.json").write_text(json.dumps(
        {"settings": vars(args) | {"out": str(args.out)}, "results": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
