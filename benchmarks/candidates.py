"""The candidates for fewer steps on the Fig. 4 scene, each on the work-precision
diagram and on the scene itself.

    python benchmarks/candidates.py [--out DIR] [--rtols 1e-3,3e-4,1e-4,3e-5,1e-5,1e-6]
                                    [--scene-rtol 3e-5] [--only NAME,...]

A candidate is a solver and a step-size controller (a method "SOLVER/CONTROLLER" of
the work-precision study). Besides the package's ROS34PW2 (diagonal W) with its PI
controller (`pi`, the default) and with diffrax's integral controller (`diffrax`,
the previous), the candidates tried for issue 24 are defined here and registered
in `SOLVERS` and `CONTROLLERS` for this process only:

- controllers: diffrax's PID controller with PI coefficients (`diffrax-pi`, pcoeff
  0.3, icoeff 0.4), and the package's controller with pure integral control
  (`pi-i`), with PI 0.3/0.4 (`pi-34`) and 0.4/0.3 (`pi-43`);
- the error norm: the embedded error estimate filtered by W^-1 = (I - h gamma D)^-1
  (`ros34pw2-filtered`; Shampine's filter, Hairer & Wanner "Solving ODEs II",
  Section IV.8), which discounts the error of the stuck oscillators' stiff velocity;
- the W matrix: -|d| in place of min(d, 0), so that velocity weakening is damped
  too (`ros34pw2-absw`); the secant slope of the friction force over the last step
  where it is stiffer than the tangent (`ros34pw2-secant`); and the 2 x 2 block of
  each oscillator, (x, x') with its own spring (`ros34pw2-block`, `Ros34PW2(block=
  True)`). A W-method keeps its order for any W, so each is still of order 3.

Writes DIR/work_precision.csv and DIR/work_precision_chain.png (the chain scene of
`jaxchain work-precision`, eps = 1e-3, against the non-smooth reference) and
DIR/candidates.md and DIR/candidates.json: for every candidate the steps and wall
time of the Fig. 4 scene (N = 20, v_d = 1.5, k = 1..20, t_end 15000, transient
10000) at `--scene-rtol`, with the previous default (ros34pw2/diffrax at rtol
1e-5) as baseline in the same run, and whether the staircase n_HALC = 1..18, 20, 20
holds. About 15 minutes on 2 cores (each scene runs twice: the first call compiles).
"""

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

import jaxchain as jc
from jaxchain._engine.solver.controller import CONTROLLERS, PIController
from jaxchain._engine.solver.rosenbrock import _GAMMA, Ros34PW2
from jaxchain._engine.solver.registry import SOLVERS
from jaxchain._studies.work_precision import work_precision

jc.configure()  # float64, one CPU device per core, the XLA flags

REPO = Path(__file__).resolve().parent.parent
EXPECTED = list(range(1, 19)) + [20, 20]


class Filtered(Ros34PW2):
    """ROS34PW2 (diagonal W) with its error estimate filtered by (I - h gamma D)^-1."""

    block: bool = eqx.field(static=True, default=False)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        y1, err, dense, state, result = super().step(terms, t0, t1, y0, args,
                                                     solver_state, made_jump)
        d0 = jnp.minimum(solver_state[1], 0.0)
        return y1, err / (1.0 - (t1 - t0) * _GAMMA * d0), dense, state, result


class AbsW(Ros34PW2):
    """ROS34PW2 (diagonal W) with W from -|d|."""

    block: bool = eqx.field(static=True, default=False)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        f0, d0, spring = solver_state
        return super().step(terms, t0, t1, y0, args, (f0, -jnp.abs(d0), spring), made_jump)


class SecantW(Ros34PW2):
    """ROS34PW2 (diagonal W) with W from the stiffer of the tangent slope at y0 and
    the secant slope of the stiff term over the last step."""

    block: bool = eqx.field(static=True, default=False)

    def init(self, terms, t0, t1, y0, args):
        f, d, spring = super().init(terms, t0, t1, y0, args)
        return f, d, spring, jnp.zeros_like(d)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        f0, d0, spring, secant = solver_state
        y1, err, dense, (f1, d1, _), result = super().step(
            terms, t0, t1, y0, args, (f0, jnp.minimum(d0, secant), spring), made_jump)
        stiff = terms.terms[1]
        dy = y1 - y0
        moved = jnp.abs(dy) > 1e-14
        slope = (stiff.vf(t1, y1, args) - stiff.vf(t0, y0, args)) / jnp.where(moved, dy, 1.0)
        return (y1, err, dense, (f1, d1, spring, jnp.minimum(jnp.where(moved, slope, 0.0), 0.0)),
                result)


CANDIDATE_SOLVERS = {"ros34pw2-filtered": Filtered, "ros34pw2-absw": AbsW,
                     "ros34pw2-secant": SecantW,
                     "ros34pw2-block": functools.partial(Ros34PW2, block=True)}
CANDIDATE_CONTROLLERS = {
    "diffrax-pi": functools.partial(diffrax.PIDController, pcoeff=0.3, icoeff=0.4),
    "pi-i": functools.partial(PIController, pcoeff=0.0, icoeff=1.0),
    "pi-34": functools.partial(PIController, pcoeff=0.3, icoeff=0.4),
    "pi-43": functools.partial(PIController, pcoeff=0.4, icoeff=0.3),
}
#: Every candidate, the baseline (the previous solver and controller) first.
METHODS = ("ros34pw2/diffrax", "ros34pw2/diffrax-pi",
           "ros34pw2/pi-i", "ros34pw2/pi-34", "ros34pw2/pi-43",
           "ros34pw2", "ros34pw2-filtered", "ros34pw2-absw", "ros34pw2-secant",
           "ros34pw2-block/diffrax", "ros34pw2-block")
BASELINE = ("ros34pw2/diffrax", 1e-5)


def _plot(rows: list[dict]):
    """The work-precision diagram of the candidates on the chain scene: amplitude
    error against steps (left) and against wall time (right), one line per method
    over its rtols, the smoothing's error at eps = 1e-3 dotted."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5), sharey=True, layout="constrained")
    lines = {}
    for row in rows:
        if row["status"] == "ok":
            lines.setdefault(row["method"], []).append(
                (float(row["rtol"]), int(row["num_steps"]), float(row["wall_s"]),
                 float(row["amplitude_error"])))
    for i, (method, pts) in enumerate(lines.items()):
        pts.sort()
        style = dict(marker="o", ms=3, color=plt.cm.tab20(i % 20),
                     ls="-" if "/" in method or method == "ros34pw2" else "--")
        for ax, col in zip(axes, (1, 2)):
            ax.plot([p[col] for p in pts], [p[3] for p in pts], label=method, **style)
    for ax, name in zip(axes, ("steps", "wall time (s), after compilation")):
        ax.set(xscale="log", yscale="log", xlabel=name)
        ax.axhline(2.35e-3, color="k", ls=":", lw=1)
        ax.axhline(1e-2, color="grey", ls="--", lw=1)
    axes[0].set_ylabel("amplitude error against the non-smooth reference")
    axes[1].legend(loc="upper left", bbox_to_anchor=(1.02, 1), fontsize=8)
    fig.suptitle("Candidates on the work-precision chain scene (eps = 1e-3, rtol 1e-3 to "
                 "1e-6; dotted: the smoothing error, dashed: 1 %)")
    return fig


def scene_run(method: str, rtol: float) -> dict:
    """The Fig. 4 scene with `method` at `rtol` (atol = rtol / 100): steps, wall time
    of a second call (the first compiles), n_HALC and E."""
    solver_name, _, controller = method.partition("/")
    options = jc.SimulationOptions(rtol=jnp.asarray(rtol), atol=jnp.asarray(rtol / 100),
                                   controller=controller or "pi")
    solver = SOLVERS[solver_name]()
    family = jc.localized_family(20)
    run = functools.partial(jc.ensemble, jc.ChainParams(), [1.5], family, solver,
                            progress=False)
    start = time.perf_counter()
    run(options=options)  # compiles
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    ds = run(options=options)
    wall = time.perf_counter() - start
    compile_s -= wall
    n_halc = ds["n_halc"].values[0].tolist()
    return {"method": method, "rtol": rtol, "steps": int(ds["num_steps"].values.sum()),
            "wall_s": wall, "compile_s": compile_s, "n_halc": n_halc,
            "staircase": n_halc == EXPECTED and int(ds["status"].values.max()) == 0,
            "energy": ds["energy"].values[0].tolist()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=REPO / "docs" / "benchmarks" / "candidates")
    p.add_argument("--rtols", default="1e-3,3e-4,1e-4,3e-5,1e-5,1e-6")
    p.add_argument("--scene-rtol", type=float, default=3e-5)
    p.add_argument("--only", default=",".join(METHODS), help="methods to run")
    args = p.parse_args(argv)
    SOLVERS.update(CANDIDATE_SOLVERS)
    CONTROLLERS.update(CANDIDATE_CONTROLLERS)
    methods = args.only.split(",")
    args.out.mkdir(parents=True, exist_ok=True)
    rtols = [float(r) for r in args.rtols.split(",")]

    rows = work_precision(args.out / "work_precision.csv", ["chain"], methods, rtols, [1e-3],
                          scipy=False, reference_points=False,
                          progress=lambda m: print(m, file=sys.stderr, flush=True))
    _plot(rows).savefig(args.out / "work_precision_chain.png", dpi=120)

    scene = [scene_run(*BASELINE)]
    for method in methods:
        scene.append(scene_run(method, args.scene_rtol))
        r = scene[-1]
        print(f"{method} rtol {args.scene_rtol:g}: {r['steps']:,} steps, {r['wall_s']:.1f} s, "
              f"staircase {'holds' if r['staircase'] else 'DIFFERS'}", file=sys.stderr,
              flush=True)
    base = scene[0]
    by_method = {}
    for row in rows:
        if row["eps"] and float(row["eps"]) == 1e-3 and row["status"] == "ok":
            by_method.setdefault(row["method"], {})[float(row["rtol"])] = row
    lines = [f"Candidates for fewer steps (issue 24). The Fig. 4 scene: N = 20, v_d = 1.5, "
             f"k = 1..20, t_end 15000, transient 10000, eps 1e-3, on {jax.device_count()} "
             f"cores; the baseline is {BASELINE[0]} at rtol {BASELINE[1]:g} (the previous "
             f"default) in the same run, every candidate at rtol {args.scene_rtol:g}; atol = "
             f"rtol / 100. The amplitude error is that of the work-precision chain scene "
             f"(k = 1, window [1000, 1500]) against the non-smooth reference at the same "
             f"rtol (the eps = 1e-3 smoothing alone gives about 0.24 %).", "",
             "| method | rtol | steps | steps / baseline | wall (s) | wall / baseline | "
             "staircase | chain scene amplitude error |", "|---|---|---|---|---|---|---|---|"]
    for r in scene:
        wp = by_method.get(r["method"], {}).get(r["rtol"])
        err = f"{100 * float(wp['amplitude_error']):.3f} %" if wp else "-"
        lines.append(f"| {r['method']} | {r['rtol']:g} | {r['steps']:,} | "
                     f"{r['steps'] / base['steps']:.3f} | {r['wall_s']:.1f} | "
                     f"{r['wall_s'] / base['wall_s']:.3f} | "
                     f"{'holds' if r['staircase'] else 'differs: ' + str(r['n_halc'])} | {err} |")
    table = "\n".join(lines) + "\n\n![work-precision](work_precision_chain.png)\n"
    (args.out / "candidates.md").write_text(table)
    (args.out / "candidates.json").write_text(json.dumps({"scene": scene}, indent=1))
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
