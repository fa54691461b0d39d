"""Running the stress matrix: every case on every solver path, each ending verified
(finite results whose physics checks hold) or failed with a specific status and a
hint."""

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..._engine.checks import as_solver
from ..._engine.engines import Smoothed
from ..._engine.progress import progress_bar
from ..._engine.solver.rosenbrock import Ros34PW2
from ..._engine.simulate import simulate
from ..._engine.smoothed import SPLIT_SOLVERS
from ..._engine.status import Status
from ..._sweeps.result_store import CsvStore, settings_key
from .cases import StressCase, stress_cases
from .physics_checks import physics_checks

#: The solver paths of the matrix: the default linearly implicit Rosenbrock-W
#: method, an explicit Runge-Kutta method and an IMEX method (`SOLVERS`).
PATHS = ("ros34pw2", "tsit5", "kencarp4")

#: The columns of a row of `stress` (and of its CSV file).
COLUMNS = ("what", "value", "solver", "outcome", "status", "check", "hint", "num_steps",
           "wall_s", "key")


#: Where the IMEX path is not run: KenCarp's implicit stages solve dense (2N)x(2N)
#: Newton systems, so its cost per step grows as N^3 from 1.7 ms at N = 20 (eps =
#: 1e-5: 88582 steps in 149 s, against ROS34PW2's 69123 in 0.4 s), and one case at
#: N = 200 did not finish in 7 minutes (docs/stress.md).
IMEX_LIMITS = {"n_osc": 20, "eps": 1e-5}


def _too_costly(case: StressCase, solver) -> str:
    """Why `solver` is not run on `case` (its cost is out of proportion: see
    `IMEX_LIMITS`), or ""."""
    if not isinstance(solver, SPLIT_SOLVERS) or isinstance(solver, Ros34PW2):
        return ""
    n, eps = case.params.n_osc, float(case.eps)
    if n <= IMEX_LIMITS["n_osc"] and eps >= IMEX_LIMITS["eps"]:
        return ""
    return (f"not run: {type(solver).__name__}'s dense Newton solves cost O(N^3) per "
            f"stage, beyond the budget at N = {n}, eps = {eps:g}; use solver='ros34pw2', "
            f"linearly implicit in the diagonal friction Jacobian")


def _finite(observed) -> bool:
    fields = (observed.amplitudes, observed.energy, observed.y_final)
    return all(bool(np.all(np.isfinite(np.asarray(f)))) for f in fields)


def run_case(case: StressCase, solver: str) -> dict:
    """Run one case on one solver path (`simulate`, never raising) and check it.

    **Returns:**

    dict with `what`, `value`, `solver`, `outcome` ("verified" or "failed"),
    `status` (the `Status` name of the run, or "check failed"),
    `check` (what was checked, and the numbers), `hint` (what to do about a
    failure, "" otherwise), `num_steps` and `wall_s`.
    """
    start = time.perf_counter()
    solve = as_solver(solver)
    reason = _too_costly(case, solve)
    if reason:
        return {"what": case.what, "value": case.value, "solver": solver, "num_steps": 0,
                "outcome": "failed", "status": f"{Status.not_run}: too costly", "check": "",
                "hint": reason, "wall_s": 0.0}
    engine = Smoothed(solve, case.options, case.eps)
    observed = simulate(case.params, case.y0, engine=engine, throw=False)
    code = Status(int(observed.status))
    row = {"what": case.what, "value": case.value, "solver": solver,
           "num_steps": int(observed.num_steps)}
    if code is not Status.ok:
        row |= {"outcome": "failed", "status": code.name, "check": "",
                "hint": engine.failure_hint(code, case.params)}
    elif not _finite(observed):
        row |= {"outcome": "failed", "status": Status.non_finite_state.name, "check": "",
                "hint": engine.failure_hint(Status.non_finite_state, case.params)}
    else:
        exactly = case.what == "ics" and case.value == "steady sliding"
        checks = physics_checks(case.params, case.y0, engine, observed, exactly)
        held = all(ok for ok, _ in checks)
        row |= {"outcome": "verified" if held else "failed",
                "status": Status.ok.name if held else "check failed",
                "check": "; ".join(("" if ok else "FAILED: ") + text for ok, text in checks),
                "hint": "" if held else "a physics check failed: tighten rtol, or report "
                                        "this case as a bug"}
    return row | {"wall_s": time.perf_counter() - start}


#: Part of every row's key: raise it when the checks change, so that rows stored by
#: an older version are run again.
CHECKS_VERSION = 2


def _row_key(case: StressCase, solver: str) -> str:
    """The key of a stored row: everything that determines it (`settings_key`)."""
    return settings_key("stress row", what=case.what, value=case.value,
                        params=case.params, eps=case.eps, y0=case.y0,
                        options=case.options, solver=solver, checks=CHECKS_VERSION)


def stress(cases: Sequence[StressCase] | None = None, solvers: Sequence[str] = PATHS,
           *, quick: bool = False, path: Path | None = None, progress: bool = False,
           on_row=None) -> list[dict]:
    """Run the stress matrix: every case (`stress_cases(quick)` by default) on every
    solver path, one after the other.

    **Arguments:**

    - `cases`: the cases; by default the whole `MATRIX` (or `QUICK_MATRIX`).
    - `solvers`: solver names (`SOLVERS`), `PATHS` by default.
    - `path`: a CSV file that rows are written to as they are done; a row stored
        there under the same key (the same case, options and solver) is
        read back instead of run again.
    - `progress`: a tqdm bar, one tick per case and solver.
    - `on_row`: called with each row as it is done or read back.

    **Returns:**

    The rows of `run_case` (with their `key`), case by case, solver by solver.

    **Raises:**

    `ValidationError` for an unknown solver name.
    """
    for name in solvers:
        as_solver(name, "solvers")
    cases = stress_cases(quick) if cases is None else list(cases)
    rows = []
    with (CsvStore(path, COLUMNS) if path is not None else _NoStore()) as store, \
            progress_bar(len(cases) * len(solvers), "stress", progress) as bar:
        for case in cases:
            for name in solvers:
                row = {"key": _row_key(case, name)}
                rows.append(_typed(store.fetch(row, lambda c=case, n=name: run_case(c, n))))
                if on_row is not None:
                    on_row(rows[-1])
                bar.update(1)
    return rows


class _NoStore:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def fetch(self, row, compute):
        return row | compute()


def _typed(row: dict) -> dict:
    """A row as read back from CSV (all strings) or as computed, with its numbers."""
    out = dict(row)
    out["num_steps"], out["wall_s"] = int(row["num_steps"]), float(row["wall_s"])
    try:
        out["value"] = float(row["value"])
    except ValueError:  # the initial conditions, named
        pass
    return out
