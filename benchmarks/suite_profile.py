"""Where the test suite's time goes: a pytest plugin that records, per test, the
seconds JAX spends tracing, lowering and compiling, and every XLA compilation by
the name of its program, then prints the test files and programs that cost most.

    PYTHONPATH=benchmarks python -m pytest -p suite_profile

Each pytest-xdist worker writes its records to SUITE_PROFILE_DIR (a temporary
folder by default, printed at the end) and the controller sums them. Processes that
the tests start (commands, notebooks) are not seen. The session's persistent
compilation cache must be set in the environment (JAX_COMPILATION_CACHE_DIR) when
this plugin is given, since it imports JAX before tests/conftest.py can set it.
"""

import collections
import json
import logging
import os
import re
import tempfile
import time
from pathlib import Path

import jax
import jax.monitoring
import pytest

_FOLDER = Path(os.environ.setdefault("SUITE_PROFILE_DIR",
                                     tempfile.mkdtemp(prefix="suite-profile-")))
_COMPILED = re.compile(r"Finished XLA compilation of (.*?) in ([0-9.e+-]+) sec")
_PHASES = {"/jax/core/compile/jaxpr_trace_duration": "trace",
           "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
           "/jax/core/compile/backend_compile_duration": "compile"}
_test = ["(outside a test)"]
_records: list[tuple[str, str, str, float]] = []  # (test, phase, program, seconds)


class _Compilations(logging.Handler):
    def emit(self, record):
        found = _COMPILED.search(record.getMessage())
        if found:
            _records.append((_test[0], "program", found.group(1), float(found.group(2))))


def _on_duration(event, duration, **_):
    if event in _PHASES:
        _records.append((_test[0], _PHASES[event], "", duration))


jax.config.update("jax_log_compiles", True)
logging.getLogger("jax").addHandler(_Compilations())
jax.monitoring.register_event_duration_secs_listener(_on_duration)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _test[0], start = item.nodeid, time.perf_counter()
    yield
    _records.append((item.nodeid, "wall", "", time.perf_counter() - start))


def pytest_unconfigure(config):
    (_FOLDER / f"{os.getpid()}.json").write_text(json.dumps(_records))
    if not hasattr(config, "workerinput"):
        _report(_FOLDER)


def _report(folder: Path, files: int = 25, programs: int = 30):
    rows = [r for f in folder.glob("*.json") for r in json.loads(f.read_text())]
    per_file = collections.defaultdict(collections.Counter)
    per_program = collections.defaultdict(lambda: [0.0, 0])
    for test, phase, program, seconds in rows:
        per_file[test.split("::")[0]][phase] += seconds
        if phase == "program":
            per_program[program][0] += seconds
            per_program[program][1] += 1
    total = collections.Counter()
    for counts in per_file.values():
        total.update(counts)
    print(f"\nsuite profile ({folder}): in tests {total['wall']:.0f} s, of which "
          f"tracing {total['trace']:.0f} s, lowering {total['lower']:.0f} s, "
          f"compiling {total['compile']:.0f} s")
    print(f"{'test file':44s} {'wall':>6s} {'trace':>6s} {'lower':>6s} {'compile':>7s}")
    for name, c in sorted(per_file.items(), key=lambda kv: -kv[1]["wall"])[:files]:
        print(f"{name:44s} {c['wall']:6.0f} {c['trace']:6.0f} {c['lower']:6.0f} "
              f"{c['compile']:7.0f}")
    print(f"\n{'seconds':>8s} {'count':>6s}  program")
    for name, (seconds, count) in sorted(per_program.items(),
                                         key=lambda kv: -kv[1][0])[:programs]:
        print(f"{seconds:8.1f} {count:6d}  {name[:90]}")
