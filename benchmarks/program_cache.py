"""What reading a kept program's output tree costs, against re-deriving it from the
code, and what checking the cache folder costs (docs/performance.md, "What the
cache holds and who may write it").

The kept program is `_run_block` of the small `jaxchain localized` case (3
oscillators, t_end 400, transient 200): kept once in a temporary folder, then, in
fresh processes (nothing traced in memory), read back with `kept_program` (the
JSON tree and the `jax.export` program) or its output's tree rebuilt by
`eqx.filter_eval_shape` (which traces diffrax's loop). Then `check_cache_folder`
on a folder of 4 and of 2000 files. Run: `python benchmarks/program_cache.py`.
"""

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = """
import sys, time
import jaxchain as jc
jc.configure()
import equinox as eqx
import numpy as np
from jaxchain._engine import lanes, programs
from jaxchain._engine.engines import as_engine
engine = as_engine("smoothed", None, jc.SimulationOptions(t_end=400.0, transient=200.0))
example = (lanes.lane_params(jc.ChainParams(n_osc=3), 1), np.zeros((1, 2, 3)), engine, None)
mode, folder = sys.argv[1], sys.argv[2]
start = time.perf_counter()
if mode == "eval_shape":
    eqx.filter_eval_shape(lanes._run_block, *example)
else:
    programs.keep_programs(folder)
    assert programs.kept_program(lanes._run_block, *example) is not None
print(time.perf_counter() - start)
"""


def _child(mode: str, folder: Path) -> float:
    out = subprocess.run([sys.executable, "-c", _CHILD, mode, str(folder)],
                         capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def main() -> None:
    from jaxchain._engine.cache_folder import check_cache_folder

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "traced"
        _child("keep", folder)  # traced and written once
        for mode in ("read", "eval_shape"):
            times = [_child(mode, folder) for _ in range(3)]
            print(f"{mode:>10}: median {statistics.median(times):.3f} s "
                  f"({', '.join(f'{t:.3f}' for t in times)})")
        for n in (4, 2000):
            many = Path(tmp) / f"files{n}"
            many.mkdir(mode=0o700)
            for i in range(n):
                (many / f"f{i}").touch()
            start = time.perf_counter()
            for _ in range(20):
                check_cache_folder(many)
            print(f"check of {n} files: {(time.perf_counter() - start) / 20 * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
