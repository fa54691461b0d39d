"""Comparison 9 of benchmarks/run.py: the cost per step of a chain on a coupling
graph (the 4 x 5 pad, free edges, links by the incidence matrix) against the ring of
20 (shifts), the same scene otherwise, best of `repeats` runs each, interleaved; and a
graph given by its links (the incidence-matrix route) of the same lattice."""

import numpy as np

import jaxchain as jc
from jaxchain._physics.params import with_fields
from jaxchain._engine.solver.registry import DEFAULT_SOLVER

from _common import Row, Settings, fmt_ratio, scene, simulate_once


def compare_graphs(settings: Settings):
    """µs per step of the 4 x 5 free lattice, a 4 x 5 lattice with masses and a
    Tabulated law (eq. (1) sampled at 101 speeds), against the ring of 20."""
    # the horizon of the ensembles (3000 in the quick run): on the single runs' 300
    # the fixed cost of a call is a fifth of the wall time and hides the step's
    ring, _, options = scene(*settings.ensemble)
    lattice = with_fields(ring, graph=jc.Graph.lattice(4, 5, "free"))
    v = np.linspace(0.0, 5.0, 101)
    law = ring.friction
    table = jc.Tabulated(v=v, mu=np.asarray(law(v)))
    loaded = with_fields(lattice, mass=np.linspace(0.8, 1.2, 20), friction=table)
    links = with_fields(ring, graph=jc.Graph.from_links(20, lattice.graph.links))
    chains = {"ring of 20": ring, "4 x 5 lattice": lattice,
              "4 x 5 as links (incidence matrix)": links,
              "4 x 5, masses, table": loaded}
    solver = jc.SOLVERS[DEFAULT_SOLVER]()
    per_step = {name: [] for name in chains}
    for name, params in chains.items():  # compile
        ic = jc.OutOfPhaseExcitation.eq8(jc.excited_block(20, 5, params.graph))
        simulate_once(params, ic, solver, options)
    for _ in range(settings.repeats):
        for name, params in chains.items():
            ic = jc.OutOfPhaseExcitation.eq8(jc.excited_block(20, 5, params.graph))
            obs, wall = simulate_once(params, ic, solver, options)
            per_step[name].append(wall / float(obs.num_steps))
    best = {name: min(t) for name, t in per_step.items()}
    base = best["ring of 20"]
    rows = [Row(f"9. µs per step, {name}", f"{base * 1e6:.2f} µs (ring of 20)",
                f"{best[name] * 1e6:.2f} µs", fmt_ratio(best[name] / base),
                f"ratio = this / ring (< 1.3 wanted for the lattice); best of {settings.repeats}")
            for name in chains if name != "ring of 20"]
    return rows, {"us_per_step": {k: v * 1e6 for k, v in best.items()}}
