"""The warm process of the command line (`jaxchain._cli.warm`): the first command
runs in its own process and starts it; a later command is handed to it, without
importing JAX, and gets the same results, output and exit statuses as in its own
process. The other tests run every command in its own process (JAXCHAIN_SERVER=0,
`conftest.py`)."""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from test_cli import SCRIPT, SMALL

pytestmark = pytest.mark.skipif(SCRIPT is None or not hasattr(os, "getuid"),
                                reason="the console script on a POSIX system")


@pytest.fixture
def warm_env():
    """The environment of commands with a warm process, whose socket lives in a
    temporary folder of its own (short: a socket's path is limited to about 100
    characters). The warm process is stopped at the end."""
    tmp = tempfile.mkdtemp(prefix="jc")
    env = dict(os.environ, JAXCHAIN_SERVER="1", TMPDIR=tmp, JAXCHAIN_SERVER_IDLE="120")
    yield env
    for pid in Path(tmp).glob("jaxchain-*/*.pid"):
        try:
            os.kill(int(pid.read_text()), signal.SIGTERM)
        except (ProcessLookupError, ValueError):
            pass
    # it removes its files as it stops: within a few seconds
    end = time.monotonic() + 30
    while list(Path(tmp).glob("jaxchain-*/*.pid")) and time.monotonic() < end:
        time.sleep(0.2)
    shutil.rmtree(tmp, ignore_errors=True)


def _wait_for_socket(env, timeout=120.0) -> Path:
    folder = Path(env["TMPDIR"]) / f"jaxchain-{os.getuid()}"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        sockets = list(folder.glob("*.sock"))
        if sockets:
            return sockets[0]
        time.sleep(0.2)
    raise AssertionError(f"no warm process listened in {folder} within {timeout} s")


def _forward(argv, env, cwd) -> tuple[int, bool, str, str]:
    """`warm.forward(argv)` in a fresh process: (status, whether that process
    imported JAX, its standard output, its standard error)."""
    code = ("import json, os, sys; from jaxchain._cli import warm; "
            f"status = warm.forward({argv!r}, dict(os.environ)); "
            "print(json.dumps([status, 'jax' in sys.modules]))")
    run = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    *out, last = run.stdout.splitlines()
    status, jax_imported = json.loads(last)
    return status, jax_imported, "\n".join(out), run.stderr


def test_a_later_command_runs_in_the_warm_process_with_the_same_results(warm_env, tmp_path):
    args = ["localized", *SMALL, "--json", "--overwrite"]
    first = subprocess.run([SCRIPT, *args, "--out", "first"], env=warm_env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert "warm process" in first.stderr  # it says that it started one
    _wait_for_socket(warm_env)

    # handed over: the command's process never imports JAX, and gets the same
    # numbers (the same compiled programs), with its files in its own folder
    status, jax_imported, out, err = _forward([*args, "--out", "second"], warm_env, tmp_path)
    assert status == 0 and not jax_imported, err
    runs = [json.loads(text)["runs"] for text in (first.stdout, out)]
    assert runs[0] == runs[1]
    assert all((tmp_path / "second" / f"localized_vd1.5.{ext}").exists() for ext in ("nc", "png"))

    # a usage error: status 2 and one line, as in the command's own process
    status, jax_imported, out, err = _forward(["localized", "--eps", "x"], warm_env, tmp_path)
    assert (status, jax_imported, out) == (2, False, "")
    assert err.strip().splitlines() == ["jaxchain localized: error: argument --eps: expected "
                                        "a number, got 'x'"]

    # the console script itself, handed over: the same, and no second warm process
    again = subprocess.run([SCRIPT, *args, "--out", "third"], env=warm_env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "warm process" not in again.stderr, again.stderr
    assert json.loads(again.stdout)["runs"] == runs[0]
    assert len(list((Path(warm_env["TMPDIR"]) / f"jaxchain-{os.getuid()}").glob("*.sock"))) == 1


def test_no_warm_process_when_turned_off(tmp_path):
    """JAXCHAIN_SERVER=0: `forward` declines at once, and nothing is started."""
    env = dict(os.environ, JAXCHAIN_SERVER="0", TMPDIR=str(tmp_path))
    status, jax_imported, out, err = _forward(["localized", "--eps", "x"], env, tmp_path)
    assert (status, jax_imported) == (None, False)
    assert not (tmp_path / f"jaxchain-{os.getuid()}").exists()
