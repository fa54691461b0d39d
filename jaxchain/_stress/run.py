"""Running the stress matrix: every case on every solver path, each ending verified
(finite results whose physics checks hold) or failed with a specific status and a
hint."""

import time
from collections.abc import Sequence

import numpy as np

from .._checks import as_solver
from .._hints import failure_hint
from .._progress import progress_bar
from .._simulate import STATUS, simulate
from .cases import StressCase, stress_cases
from .checks import physics_checks

#: The solver paths of the matrix: the default linearly implicit Rosenbrock-W
#: method, an explicit Runge-Kutta method and an IMEX method (`SOLVERS`).
PATHS = ("ros34pw2", "tsit5", "kencarp4")


def _finite(observed) -> bool:
    fields = (observed.amplitudes, observed.energy, observed.y_final)
    return all(bool(np.all(np.isfinite(np.asarray(f)))) for f in fields)


def run_case(case: StressCase, solver: str) -> dict:
    """Run one case on one solver path (`simulate`, never raising) and check it.

    **Returns:**

    dict with `what`, `value`, `solver`, `outcome` ("verified" or "failed"),
    `status` (the `STATUS` of the run, "non-finite result" or "check failed"),
    `check` (what was checked, and the numbers), `hint` (what to do about a
    failure, "" otherwise), `num_steps` and `wall_s`.
    """
    start = time.perf_counter()
    solve = as_solver(solver)
    observed = simulate(case.params, case.y0, solve, case.options, throw=False)
    code = int(observed.status)
    row = {"what": case.what, "value": case.value, "solver": solver,
           "num_steps": int(observed.num_steps)}
    if code != 0:
        row |= {"outcome": "failed", "status": STATUS[code].split(":")[0], "check": "",
                "hint": failure_hint(code, case.params, solve, case.options)}
    elif not _finite(observed):
        row |= {"outcome": "failed", "status": "non-finite result", "check": "",
                "hint": failure_hint(3, case.params, solve, case.options)}
    else:
        exactly = case.what == "ics" and case.value == "steady sliding"
        checks = physics_checks(case.params, case.y0, solve, case.options, observed, exactly)
        held = all(ok for ok, _ in checks)
        row |= {"outcome": "verified" if held else "failed",
                "status": "ok" if held else "check failed",
                "check": "; ".join(("" if ok else "FAILED: ") + text for ok, text in checks),
                "hint": "" if held else "a physics check failed: tighten rtol, or report "
                                        "this case as a bug"}
    return row | {"wall_s": time.perf_counter() - start}


def stress(cases: Sequence[StressCase] | None = None, solvers: Sequence[str] = PATHS,
           *, quick: bool = False, progress: bool = False, on_row=None) -> list[dict]:
    """Run the stress matrix: every case (`stress_cases(quick)` by default) on every
    solver path, one after the other.

    **Arguments:**

    - `cases`: the cases; by default the whole `MATRIX` (or `QUICK_MATRIX`).
    - `solvers`: solver names (`SOLVERS`), `PATHS` by default.
    - `progress`: a tqdm bar, one tick per case and solver.
    - `on_row`: called with each row as it is done (to write as it goes).

    **Returns:**

    The rows of `run_case`, case by case, solver by solver.

    **Raises:**

    `ValueError` for an unknown solver name.
    """
    for name in solvers:
        as_solver(name, "solvers")
    cases = stress_cases(quick) if cases is None else list(cases)
    rows = []
    with progress_bar(len(cases) * len(solvers), "stress", progress) as bar:
        for case in cases:
            for name in solvers:
                rows.append(run_case(case, name))
                if on_row is not None:
                    on_row(rows[-1])
                bar.update(1)
    return rows
