"""Bad input to the command line gets one line and exit status 2, before anything is
computed: records of the same name, a record with a header and no rows, files and
folder names that are not UTF-8, and runs larger than this machine's memory."""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import jaxchain as jc
from helpers import EXAMPLE_RECORD, assert_usage_error

#: The quickest localized run (N = 2).
TINY = ["localized", "--n-osc", "2", "--t-end", "20", "--transient", "10"]


def _record(path: Path, rows: int, source: str = EXAMPLE_RECORD) -> Path:
    """The first `rows` samples of the example rig's record, at `path`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = Path(source).read_text().splitlines()
    path.write_text("\n".join(lines[:rows + 1]) + "\n")
    return path


@pytest.mark.study
@pytest.mark.slow
@pytest.mark.long
def test_records_of_the_same_name_in_two_folders_each_get_their_fit(tmp_path):
    examples = Path(EXAMPLE_RECORD).parent
    records = [_record(tmp_path / "a" / "rig.csv", 60, examples / "rig_vd0.4.csv"),
               _record(tmp_path / "b" / "rig.csv", 60, examples / "rig_vd0.7.csv")]
    out = tmp_path / "out"
    assert jc.main(["identify", *map(str, records), "--fit", "xi", "--window", "6",
                    "--out", str(out)]) == 0
    for name, record in zip(("fit_a_rig.csv", "fit_b_rig.csv"), records):
        fit = np.genfromtxt(out / name, delimiter=",", names=True)
        measured = np.genfromtxt(record, delimiter=",", names=True)
        # its own record, written to 10 significant digits
        np.testing.assert_allclose(fit["x1"], measured["x1"], rtol=1e-9, atol=0)
    assert not (out / "fit_rig.csv").exists()


@pytest.mark.parametrize("names, says", [
    (("a/rig.csv", "a/rig.csv"), "given twice"),
    (("a/rig.csv", "a/./rig.csv"), "given twice"),
    (("a/rig.csv", "a/rig.txt"), "rename one"),
])
def test_records_that_no_folder_tells_apart_are_refused(tmp_path, capsys, names, says):
    files = [str(_record(tmp_path / n, 60)) for n in names]
    assert_usage_error(["identify", *files, "--out", str(tmp_path / "out")], says, capsys)
    assert not (tmp_path / "out").exists()


def test_a_record_with_a_header_and_no_rows_is_refused(tmp_path, capsys):
    empty = _record(tmp_path / "empty.csv", 0)
    assert_usage_error(["identify", str(empty), "--out", str(tmp_path / "out")],
                       f"{empty}: no samples", capsys)


def test_a_record_that_is_not_utf8_is_named(tmp_path, capsys):
    latin = tmp_path / "latin.csv"
    latin.write_bytes(b"t,x1,v_d\n0,0.1,0.4\n0.1,0.2\xe9,0.4\n")
    assert_usage_error(["identify", str(latin), "--out", str(tmp_path / "out")],
                       f"{latin}: not UTF-8", capsys)


def test_a_chain_file_that_is_not_utf8_is_named(tmp_path, capsys):
    chain = tmp_path / "chaîne.toml"
    chain.write_bytes("n_osc = 2\nxi = 0.05  # amorti\n".encode("latin-1") + b"# \xe9\n")
    assert_usage_error([*TINY, "--chain", str(chain), "--out", str(tmp_path / "out")],
                       f"--chain {chain}: not UTF-8", capsys)


def test_a_friction_table_that_is_not_utf8_is_named(tmp_path, capsys):
    table = tmp_path / "mu.csv"
    table.write_bytes(b"v,mu\n0,1\n1,0.5 # \xe9\n")
    assert_usage_error([*TINY, "--friction", f"table:{table}", "--out", str(tmp_path / "out")],
                       f"{table}: not UTF-8", capsys)


def test_an_out_folder_whose_name_is_not_utf8_is_refused_before_computing(tmp_path, capsys):
    out = os.fsdecode(os.fsencode(tmp_path) + b"/r\xe9sultats")
    assert_usage_error([*TINY, "--out", out], "not UTF-8", capsys)
    assert not os.path.exists(os.fsencode(out))  # refused before the folder was made


@pytest.mark.parametrize("argv, says", [
    (["--n-osc", "1000000000"], "--n-osc 1000000000: the run would hold at least"),
    (["--lattice", "40000x40000"], "--lattice 40000x40000 (1600000000 oscillators)"),
    (["--n-osc", "2", "--t-end", "1e15"], "--t-end 1e+15: the run would hold at least"),
])
def test_a_run_larger_than_the_memory_is_refused_with_its_estimate(argv, says, tmp_path):
    """In a process of its own, timed: without the estimate such runs build their
    chain for minutes, then fail for memory."""
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", "import sys, jaxchain; "
                           "sys.exit(jaxchain.main(sys.argv[1:]))", "localized", *argv,
                           "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=240)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and len(err.splitlines()) == 1 and says in err, err
    assert " TB " in err or " PB " in err, err  # the estimate, in words
    assert time.monotonic() - start < 120
