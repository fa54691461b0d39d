"""One command at a time per output folder: a second command into a folder that a
running command writes is refused in one line naming the first (its process id
and command line), or waits for it with --wait; the lock of a command killed by
SIGKILL blocks nothing."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import xarray as xr

import jaxchain as jc

#: The quickest localized run (N = 2).
TINY = ["localized", "--n-osc", "2", "--t-end", "20", "--transient", "10"]
#: The installed console script, as a user runs it.
SCRIPT = next((p for p in (Path(sys.executable).parent / "jaxchain", shutil.which("jaxchain"))
               if p and Path(p).exists()), None)
#: The file beside the lock that names its holder.
HOLDER = ".jaxchain-lock.json"

#: A command that holds its folder while it runs (a localized run at v_d = 1.2, its
#: results beside those of `TINY`), as a user starts it.
_HOLD = ["import sys, jaxchain; sys.exit(jaxchain.main(sys.argv[1:]))", "localized",
         "--n-osc", "2", "--vd", "1.2", "--transient", "10", "--no-progress"]


def _holder(folder: Path, t_end: float = 1e5) -> subprocess.Popen:
    """A command into `folder` of horizon `t_end`, once it holds the folder's lock."""
    proc = subprocess.Popen([sys.executable, "-c", *_HOLD, "--t-end", f"{t_end:g}",
                             "--out", str(folder)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _wait_for(folder / HOLDER, proc)
    return proc


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 300.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, "the first command ended before it held its folder"
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.02)


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.skipif(SCRIPT is None, reason="the jaxchain console script is not installed")
@pytest.mark.study
def test_a_second_command_into_a_busy_folder_is_refused_and_the_first_keeps_its_results(
        tmp_path, capsys):
    out = tmp_path / "out"
    first = [str(SCRIPT), "localized", "--n-osc", "2", "--t-end", "300", "--transient", "10",
             "--out", str(out)]
    proc = subprocess.Popen(first, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(out / HOLDER, proc)
        assert jc.main([*TINY, "--out", str(out)]) == 2
        err = _one_line_error(capsys)
        assert f"pid {proc.pid}" in err and "--t-end 300" in err and "--wait" in err, err
        assert proc.wait(timeout=600) == 0, proc.stderr.read()
    finally:
        proc.kill()
    ds = xr.load_dataset(out / "localized_vd1.5.nc")
    assert ds.attrs["t_end"] == 300.0  # the first command's results, whole
    made = json.loads((out / ".jaxchain-results.json").read_text())
    assert set(made) == {"localized_vd1.5.nc", "localized_vd1.5.png"}
    assert not (out / HOLDER).exists()  # released at its end


def test_the_lock_of_a_killed_command_blocks_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    holder = _holder(out)
    try:
        assert jc.main([*TINY, "--out", str(out)]) == 2
        err = _one_line_error(capsys)
        assert f"pid {holder.pid} (jaxchain localized --out {out}" in err, err
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert (out / HOLDER).exists()  # what the killed holder left
    assert jc.main([*TINY, "--out", str(out)]) == 0
    assert (out / "localized_vd1.5.nc").exists() and not (out / HOLDER).exists()


@pytest.mark.study
def test_wait_waits_for_the_holder_to_end(tmp_path, capsys):
    out = tmp_path / "out"
    holder = _holder(out, t_end=300.0)
    try:
        assert jc.main([*TINY, "--out", str(out), "--wait"]) == 0
        # the holder writes its results before it lets the folder go
        assert (out / "localized_vd1.2.nc").exists(), "ran while the folder was held"
    finally:
        holder.kill()
    err = capsys.readouterr().err
    assert f"waiting for pid {holder.pid}" in err, err
    assert xr.load_dataset(out / "localized_vd1.5.nc").attrs["t_end"] == 20.0


def test_a_refused_command_leaves_the_folder_to_the_next(tmp_path, capsys):
    """A command refused after it took the lock (its results would replace others)
    releases it: the next command runs."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "localized_vd1.5.nc").write_text("another command's result")
    assert jc.main([*TINY, "--out", str(out)]) == 2
    assert "exists" in _one_line_error(capsys)
    assert jc.main([*TINY, "--out", str(out), "--overwrite"]) == 0
