"""The warm process of the command line (`jaxchain._cli.warm`, `warm_process`): the
first command runs in its own process and starts it; later commands are handed to
it, without importing JAX, and behave as in a process of their own (results and
their history, output, exit status, standard input, working directory,
environment); a command of other settings (environment, limits, nice value,
affinity) runs in its own process. It is visible and stoppable (`jaxchain
server`) whatever $TMPDIR is, lets a command finish when stopped, is bounded in
memory and in number, never stale, stops its work on Ctrl-C and answers a
malformed request with an error. The other tests run every command in its own
process (JAXCHAIN_SERVER=0, `conftest.py`)."""

import contextlib
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

RUN = ["localized", *SMALL, "--json", "--overwrite"]

#: A chain file of three oscillators on a line.
CHAIN = 'n_osc = 3\nboundary = "free"\n'


def _new_env(**extra) -> dict:
    """The environment of commands with warm processes of their own, whose sockets
    live in a runtime folder of their own (XDG_RUNTIME_DIR, mode 0700; short: a
    socket's path is limited to about 100 characters), with a temporary folder
    of their own."""
    return dict(os.environ, JAXCHAIN_SERVER="1", XDG_RUNTIME_DIR=tempfile.mkdtemp(prefix="jc"),
                TMPDIR=tempfile.mkdtemp(prefix="jt"), JAXCHAIN_SERVER_IDLE="120", **extra)


def _place(env) -> Path:
    """The folder of the warm processes of `env` (docs/cli.md)."""
    return Path(env["XDG_RUNTIME_DIR"], "jaxchain")


def _stop_all(env) -> None:
    """Stop every warm process of `env` (`jaxchain server stop --all --kill`) and
    remove its folders."""
    subprocess.run([SCRIPT, "server", "stop", "--all", "--kill"], env=env, capture_output=True,
                   timeout=60)
    for name in ("XDG_RUNTIME_DIR", "TMPDIR"):
        shutil.rmtree(env[name], ignore_errors=True)


@pytest.fixture(scope="module")
def warm_env():
    """A warm process started by a first command (in its own process), shared by
    the tests of this module, stopped at the end."""
    env = _new_env()
    folder = Path(tempfile.mkdtemp(prefix="jcw"))
    first = subprocess.run([SCRIPT, *RUN, "--out", "first"], env=env, cwd=folder,
                           capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert "warm process" in first.stderr  # it says that it started one
    _server(env)
    yield env, folder, json.loads(first.stdout)
    _stop_all(env)
    shutil.rmtree(folder, ignore_errors=True)


def _states(env) -> list[dict]:
    run = subprocess.run([SCRIPT, "server", "status", "--json"], env=env, capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def _server(env, timeout=120.0, not_pid=None) -> dict:
    """The state of the one warm process of `env` once it listens (and is not
    `not_pid`)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = [s for s in _states(env) if s["state"] == "idle" and s["pid"] != not_pid]
        if found:
            return found[0]
        time.sleep(0.2)
    raise AssertionError(f"no warm process listened within {timeout} s")


def _command(args, env, cwd, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([SCRIPT, *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=600, **kwargs)


def _forward(argv, env, cwd, before="pass") -> tuple[int, bool, str, str]:
    """`warm.forward(argv)` in a fresh process, after the statements `before`:
    (status, whether that process imported JAX, its standard output, its
    standard error)."""
    code = (f"import json, os, sys; {before}; from jaxchain._cli import warm; "
            f"status = warm.forward({argv!r}, dict(os.environ)); "
            "print(json.dumps([status, 'jax' in sys.modules]))")
    run = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    *out, last = run.stdout.splitlines()
    status, jax_imported = json.loads(last)
    return status, jax_imported, "\n".join(out), run.stderr


@pytest.mark.study
def test_commands_back_to_back_are_served_warm_with_the_same_results(warm_env):
    env, folder, first = warm_env
    before = _server(env)
    # handed over: the command's process never imports JAX, and gets the same
    # numbers (the same compiled programs), with its files in its own folder
    status, jax_imported, out, err = _forward([*RUN, "--out", "second"], env, folder)
    assert status == 0 and not jax_imported, err
    assert json.loads(out)["runs"] == first["runs"]
    assert all((folder / "second" / f"localized_vd1.5.{ext}").exists() for ext in ("nc", "png"))
    # three commands back to back, as a user's loop runs them: each served by the
    # same warm process (its own count), none starting another
    for i in range(3):
        again = _command([*RUN, "--out", f"loop{i}"], env, folder)
        assert again.returncode == 0 and "warm process" not in again.stderr, again.stderr
        assert json.loads(again.stdout)["runs"] == first["runs"]
    after = _server(env)
    assert after["pid"] == before["pid"] and after["served"] == before["served"] + 4
    log = (_place(env) / f"{after['key']}.log").read_text()
    assert sum(f'"loop{i}"' in line for line in log.splitlines() for i in range(3)) == 3


@pytest.mark.study
def test_exit_status_stdin_cwd_and_environment_as_in_a_process_of_its_own(warm_env, tmp_path):
    env, _, _ = warm_env
    pid = _server(env)["pid"]
    # exit statuses: 2 and one line for a usage error, 1 for a failed run
    usage = _command(["localized", "--eps", "x"], env, tmp_path)
    assert (usage.returncode, usage.stdout) == (2, "")
    assert usage.stderr.strip().splitlines() == ["jaxchain localized: error: argument --eps: "
                                                 "expected a number, got 'x'"]
    failed = _command([*RUN, "--max-steps", "1", "--out", "failed"], env, tmp_path)
    assert failed.returncode == 1 and "trajectories failed" in failed.stderr
    # standard input: a chain file read from it gives the results of the same file
    # named, and --out lands in the command's working directory
    (tmp_path / "chain.toml").write_text(CHAIN)
    named = _command([*RUN, "--chain", "chain.toml", "--out", "named"], env, tmp_path)
    piped = _command([*RUN, "--chain", "/dev/stdin", "--out", "piped"], env, tmp_path,
                     input=CHAIN)
    assert named.returncode == piped.returncode == 0, piped.stderr
    runs = json.loads(piped.stdout)["runs"]
    assert runs == json.loads(named.stdout)["runs"] and len(runs[0]["n_halc"]) == 3
    assert (tmp_path / "piped" / "localized_vd1.5.nc").exists()
    # the command's environment, not the warm process's: argparse wraps --help at
    # the command's COLUMNS, as in a process of its own, and the next command's
    # COLUMNS is its own again
    narrow = _command(["localized", "--help"], dict(env, COLUMNS="50"), tmp_path)
    wide = _command(["localized", "--help"], dict(env, COLUMNS="200"), tmp_path)
    own = _command(["localized", "--help"], dict(env, COLUMNS="50", JAXCHAIN_SERVER="0"),
                   tmp_path)
    assert narrow.stdout == own.stdout != wide.stdout
    assert _server(env)["pid"] == pid  # all of it served by the one warm process


def test_ctrl_c_stops_the_work_in_the_warm_process(warm_env, tmp_path):
    """SIGINT to the command (as Ctrl-C at a terminal) ends it with status 130, and
    the warm process stops the trajectory it was integrating (a run of minutes)."""
    env, _, _ = warm_env
    pid = _server(env)["pid"]
    long_run = ["localized", "--n-osc", "20", "--t-end", "1e7", "--transient", "10",
                "--json", "--out", "long"]
    # SIGINT as at a terminal: default in the command (a pytest worker's own
    # disposition, which its children inherit, may be to ignore it); set before the
    # command's exec, which keeps a default disposition (no preexec_fn: a fork of a
    # process with JAX's threads may deadlock)
    at_terminal = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                   "os.execv(sys.argv[1], sys.argv[1:])")
    proc = subprocess.Popen([sys.executable, "-c", at_terminal, str(SCRIPT), *long_run],
                            env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 60
    while not any(s["state"] == "busy" for s in _states(env)) and time.monotonic() < end:
        time.sleep(0.1)
    time.sleep(1.0)  # into the integration
    assert proc.poll() is None
    proc.send_signal(signal.SIGINT)
    interrupted = time.monotonic()
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and err.strip().endswith("interrupted"), err
    # no longer busy: idle again, or replaced by a fresh process
    while any(s["state"] == "busy" for s in _states(env)) and time.monotonic() - interrupted < 30:
        time.sleep(0.1)
    stopped = time.monotonic() - interrupted
    assert stopped < 10, f"the warm process still worked {stopped:.1f} s after Ctrl-C"
    state = _server(env)
    assert state["pid"] != pid or state["state"] == "idle"


def test_an_edited_source_file_is_used_by_the_next_command(tmp_path):
    """A copy of jaxchain (PYTHONPATH) whose warm process runs; a source file of the
    copy is changed: the next command runs the changed code, and the warm process
    of the old code stops by itself."""
    copy = tmp_path / "copy"
    shutil.copytree(Path(__import__("jaxchain").__file__).parent, copy / "jaxchain",
                    ignore=shutil.ignore_patterns("__pycache__"))
    env = _new_env(PYTHONPATH=str(copy))
    try:
        start = subprocess.run([sys.executable, "-c", "import os; from jaxchain._cli.warm "
                                "import start; start(dict(os.environ))"],
                               env=env, capture_output=True, text=True, timeout=60)
        assert start.returncode == 0, start.stderr
        old = _server(env)["pid"]
        before = _command(["localized", "--help"], env, tmp_path)
        assert before.returncode == 0 and "EDITED" not in before.stdout
        assert _server(env)["served"] == 1  # served by the warm process of the copy

        module = copy / "jaxchain" / "_cli" / "localized.py"
        module.write_text(module.read_text().replace("Reproduce the staircase",
                                                     "EDITED Reproduce the staircase"))
        after = _command(["localized", "--help"], env, tmp_path)
        assert after.returncode == 0 and "EDITED Reproduce" in after.stdout
        end = time.monotonic() + 30
        while any(s["pid"] == old for s in _states(env)) and time.monotonic() < end:
            time.sleep(0.2)
        assert all(s["pid"] != old for s in _states(env))  # the stale one stopped itself
    finally:
        _stop_all(env)


def test_over_its_memory_bound_it_replaces_itself_and_stop_ends_it(tmp_path):
    env = _new_env(JAXCHAIN_SERVER_MAX_MB="1")  # every process is over 1 MiB
    try:
        subprocess.run([sys.executable, "-c", "import os; from jaxchain._cli.warm import "
                        "start; start(dict(os.environ))"], env=env, check=True, timeout=60)
        old = _server(env)
        assert old["max_mb"] == 1 and old["served"] == 0
        assert _command(["localized", "--help"], env, tmp_path).returncode == 0
        new = _server(env, not_pid=old["pid"])  # a fresh process in its place
        assert new["served"] == 0 and len(_states(env)) == 1
        assert _command(["localized", "--help"], env, tmp_path).returncode == 0
        assert _server(env, not_pid=new["pid"])["served"] == 0  # replaced again

        stop = _command(["server", "stop", "--json"], env, tmp_path)
        assert stop.returncode == 0 and len(json.loads(stop.stdout)["stopped"]) == 1
        assert _states(env) == []
        bad = _command(["server", "stop", "--pid", "999999999"], env, tmp_path)
        assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
        shown = _command(["server", "status"], env, tmp_path)
        assert shown.returncode == 0 and "no warm process" in shown.stdout
    finally:
        _stop_all(env)


def test_stop_never_signals_a_process_that_has_a_dead_warm_process_s_id(tmp_path):
    """A warm process killed without clean-up leaves its state file; the system may
    give its id to another process of the user (ids are reused). That process is
    not the warm process: `status` does not list it, `stop` leaves it running and
    removes the stale files."""
    env = _new_env()
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"])
    try:
        place = _place(env)
        place.mkdir(mode=0o700)
        now = time.time()
        stale = {"pid": other.pid, "start": "0", "version": "0", "prefix": sys.prefix,
                 "python": sys.executable, "state": "idle", "since": now, "started": now,
                 "served": 0, "rss_mb": 1.0, "max_mb": 1024.0, "idle_limit_s": 120.0}
        (place / "stale.json").write_text(json.dumps(stale))
        assert _states(env) == []
        (place / "stale.json").write_text(json.dumps(stale))
        stop = _command(["server", "stop", "--json"], env, tmp_path)
        assert stop.returncode == 0 and json.loads(stop.stdout)["stopped"] == []
        assert other.poll() is None, "stop signalled the process that has the old id"
        assert not (place / "stale.json").exists()
    finally:
        other.kill()
        other.wait()
        _stop_all(env)


def test_no_warm_process_under_ci_or_a_batch_scheduler_unless_asked(tmp_path):
    from jaxchain._cli.warm import enabled

    assert enabled({}) and not enabled({"JAXCHAIN_SERVER": "0"})
    for name in ("CI", "SLURM_JOB_ID", "PBS_JOBID", "LSB_JOBID"):
        assert not enabled({name: "1"}) and enabled({name: "1", "JAXCHAIN_SERVER": "1"})
    env = {k: v for k, v in os.environ.items() if k != "JAXCHAIN_SERVER"}
    tmp_path.chmod(0o700)
    env.update(CI="true", XDG_RUNTIME_DIR=str(tmp_path))
    status, jax_imported, _, _ = _forward(["localized", "--eps", "x"], env, tmp_path)
    assert (status, jax_imported) == (None, False)
    assert not (tmp_path / "jaxchain").exists()


def test_the_key_follows_the_installed_packages(tmp_path):
    """An upgrade of a dependency in the venv (its dist-info renamed) or its
    reinstall (made anew) gives another key: the next command does not run in a
    warm process that imported the old one."""
    from jaxchain._cli.warm import key

    site = tmp_path / "site-packages"
    (site / "jax-0.10.2.dist-info").mkdir(parents=True)
    first = key({}, [str(site)])
    assert key({}, [str(site)]) == first
    (site / "jax-0.10.2.dist-info").rename(site / "jax-0.10.3.dist-info")
    upgraded = key({}, [str(site)])
    shutil.rmtree(site / "jax-0.10.3.dist-info")
    time.sleep(0.01)
    (site / "jax-0.10.3.dist-info").mkdir()
    os.utime(site / "jax-0.10.3.dist-info", ns=(1, 1))
    assert len({first, upgraded, key({}, [str(site)])}) == 3


def _history_command(path: Path) -> str:
    """The command line that the `history` attribute of the netCDF file `path`
    names (after its time stamp)."""
    import h5py

    with h5py.File(path, "r") as f:
        history = f.attrs["history"]
    history = history.decode() if isinstance(history, bytes) else str(history)
    return history.split(": ", 1)[1]


def test_results_written_warm_name_the_user_s_command_in_their_history(warm_env):
    env, folder, _ = warm_env
    before = _server(env)
    run = _command([*RUN, "--out", "history"], env, folder)
    assert run.returncode == 0, run.stderr
    after = _server(env)
    assert (after["pid"], after["served"]) == (before["pid"], before["served"] + 1)  # warm
    expected = " ".join(["jaxchain", *RUN, "--out", "history"])
    assert _history_command(folder / "history" / "localized_vd1.5.nc") == expected
    # the first command, in its own process, the same way
    own = _history_command(folder / "first" / "localized_vd1.5.nc")
    assert own == " ".join(["jaxchain", *RUN, "--out", "first"])


def test_status_finds_the_warm_process_whatever_tmpdir_is(warm_env, tmp_path):
    env, _, _ = warm_env
    pid = _server(env)["pid"]
    assert [s["pid"] for s in _states(dict(env, TMPDIR=str(tmp_path)))] == [pid]
    assert [s["pid"] for s in _states({k: v for k, v in env.items() if k != "TMPDIR"})] == [pid]


def test_a_malformed_request_is_answered_with_an_error_and_the_process_goes_on(warm_env):
    """A request that is not JSON, lacks a field, comes without the standard
    streams, is of another kind or is too long: the warm process answers "e"
    with a message and serves the next command."""
    import socket

    from jaxchain._cli.warm import receive, send

    env, folder, _ = warm_env
    state = _server(env)
    sock = str(_place(env) / f"{state['key']}.sock")
    read, write = os.pipe()
    good = {"argv": ["localized", "--help"], "cwd": str(folder), "env": env, "umask": 0o022}
    cases = [(b"r", b"not json", (read, write, write)),
             (b"r", json.dumps({k: v for k, v in good.items() if k != "argv"}).encode(),
              (read, write, write)),
             (b"r", json.dumps(dict(good, argv="localized")).encode(), (read, write, write)),
             (b"r", json.dumps(good).encode(), ()),  # no standard streams
             (b"x", b"{}", (read, write, write)),
             (b"r", None, ())]  # a frame that says it is 2 GiB long
    try:
        for kind, payload, fds in cases:
            conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            conn.settimeout(30)
            conn.connect(sock)
            assert receive(conn) == (b"a", b"")
            if payload is None:
                conn.sendall(kind + (2**31).to_bytes(4, "big"))
            else:
                send(conn, kind, payload, fds=fds)
            answer = receive(conn)
            conn.close()
            assert answer is not None and answer[0] == b"e", (kind, payload, answer)
            assert b"malformed request" in answer[1]
    finally:
        os.close(read)
        os.close(write)
    assert _server(env)["pid"] == state["pid"]  # still there, and idle
    ran = _command(["localized", "--help"], env, folder)
    assert ran.returncode == 0 and _server(env)["served"] == state["served"] + 1


def test_settings_that_limit_a_command_or_that_libraries_read_keep_it_out(warm_env, tmp_path):
    """A command whose nice value, CPU-time limit, CPU affinity or environment (a
    variable that a library reads at import: ZARR_DEFAULT_ZARR_FORMAT) differ
    from the warm process's is not served there (it runs in its own process)."""
    env, _, _ = warm_env
    assert _forward(["localized", "--help"], env, tmp_path)[0] == 0  # served, the same
    limited = ["os.nice(1)",
               "import resource; resource.setrlimit(resource.RLIMIT_CPU, "
               "(10**6, resource.getrlimit(resource.RLIMIT_CPU)[1]))",
               "os.environ['ZARR_DEFAULT_ZARR_FORMAT'] = '2'"]
    if hasattr(os, "sched_getaffinity") and len(os.sched_getaffinity(0)) > 1:
        limited.append(f"os.sched_setaffinity(0, {{{min(os.sched_getaffinity(0))}}})")
    for before in limited:
        assert _forward(["localized", "--help"], env, tmp_path, before=before)[0] is None, before
    assert _forward(["localized", "--help"], dict(env, COLUMNS="33"), tmp_path)[0] == 0


@pytest.mark.study
@pytest.mark.slow
def test_an_environment_variable_that_zarr_reads_at_import_is_honoured(warm_env, tmp_path):
    """ZARR_DEFAULT_ZARR_FORMAT=2 gives a sweep store of zarr's format 2, as in a
    process of its own, after a sweep served warm (zarr imported there, its
    default format 3 read once)."""
    from helpers import sweep_cli

    env, _, _ = warm_env
    pid = _server(env)["pid"]

    def formats(out: str) -> set:
        stores = list((tmp_path / out).glob("*.zarr"))
        assert stores
        return {3 if (s / "zarr.json").exists() else 2 if (s / ".zgroup").exists() else None
                for s in stores}

    served = _server(env)["served"]
    run = _command([*sweep_cli("1.5"), "--out", "z3"], env, tmp_path)
    assert run.returncode == 0, run.stderr
    assert formats("z3") == {3} and _server(env)["served"] == served + 1
    run = _command([*sweep_cli("1.5"), "--out", "z2"], dict(env, ZARR_DEFAULT_ZARR_FORMAT="2"),
                   tmp_path)
    assert run.returncode == 0, run.stderr
    assert formats("z2") == {2}
    # in its own process, it started a warm process of its settings: killed, not
    # left to load JAX beside the tests
    started = {int(m.read_text()) for m in _place(env).glob("*.starting") if m.read_text()}
    for other in (started | {s["pid"] for s in _states(env)}) - {pid}:
        with contextlib.suppress(ProcessLookupError):
            os.kill(other, signal.SIGKILL)
    assert [s["pid"] for s in _states(env)] == [pid]


def _start(env) -> dict:
    """Start the warm process of `env` (as a first command does) and wait until it
    listens: its state."""
    subprocess.run([sys.executable, "-c", "import os; from jaxchain._cli.warm import start; "
                    "start(dict(os.environ))"], env=env, check=True, timeout=60)
    return _server(env)


@pytest.mark.study
def test_server_stop_lets_the_running_command_finish(tmp_path):
    """`jaxchain server stop` (from a shell of another $TMPDIR) while a command runs
    (held, reading its chain file from standard input): past the seconds after
    which stop used to kill it, the command still runs, and a new command is not
    taken; once its input comes, it finishes with its results and figure, and
    then the warm process ends."""
    from jaxchain._cli.server import STOP_S

    env = _new_env()
    try:
        pid = _start(env)["pid"]
        held = subprocess.Popen([SCRIPT, *RUN, "--chain", "/dev/stdin", "--out", "held"],
                                env=env, cwd=tmp_path, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        end = time.monotonic() + 60
        while not any(s["state"] == "busy" for s in _states(env)) and time.monotonic() < end:
            time.sleep(0.1)
        other = dict(env, TMPDIR=str(tmp_path))
        stop = subprocess.Popen([SCRIPT, "server", "stop", "--json"], env=other, cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(STOP_S + 1)
        assert held.poll() is None and stop.poll() is None
        assert _forward(["localized", "--help"], env, tmp_path)[0] is None  # not taken
        out, err = held.communicate(CHAIN, timeout=300)
        assert held.returncode == 0, err
        assert len(json.loads(out)["runs"][0]["n_halc"]) == 3
        assert all((tmp_path / "held" / f"localized_vd1.5.{ext}").exists()
                   for ext in ("nc", "png"))
        out, err = stop.communicate(timeout=60)
        assert stop.returncode == 0 and json.loads(out) == {"stopped": [pid]}, err
        assert f"waiting for warm process {pid}" in err and len(err.strip().splitlines()) == 1
        assert _states(env) == []
    finally:
        _stop_all(env)


def _sleeper() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"])


def _fake_state(env, name: str, process: subprocess.Popen, **fields) -> None:
    """A state file `<name>.json` in the folder of `env` for `process`, as a warm
    process of this installation writes it (its start time read from /proc)."""
    import jaxchain

    place = _place(env)
    place.mkdir(mode=0o700, exist_ok=True)
    with open(f"/proc/{process.pid}/stat") as f:
        start = f.read().rsplit(")", 1)[1].split()[19]
    now = time.time()
    state = {"pid": process.pid, "start": start, "version": "0", "prefix": sys.prefix,
             "package": str(Path(jaxchain.__file__).parent), "python": sys.executable,
             "state": "idle", "since": now, "started": now, "served": 0, "rss_mb": 1.0,
             "max_mb": 1024.0, "idle_limit_s": 120.0} | fields
    (place / f"{name}.json").write_text(json.dumps(state))


needs_proc = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")


@needs_proc
def test_a_dead_warm_process_is_not_shown(tmp_path):
    """A warm process killed during a command whose parent has not reaped it (a
    zombie: a container's first process may never reap one) is not shown as
    busy, and its files are removed."""
    env = _new_env()
    dead = _sleeper()
    try:
        _fake_state(env, "dead", dead, state="busy", command=["localized"])
        dead.kill()
        end = time.monotonic() + 10
        while Path(f"/proc/{dead.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
            assert time.monotonic() < end
            time.sleep(0.05)
        assert _states(env) == []
        shown = _command(["server", "status"], env, tmp_path)
        assert shown.returncode == 0 and "busy" not in shown.stdout
        assert not (_place(env) / "dead.json").exists()
    finally:
        dead.kill()
        dead.wait()
        _stop_all(env)


@needs_proc
def test_stop_stops_only_this_installation_s_processes_unless_all(tmp_path):
    env = _new_env()
    mine, theirs = _sleeper(), _sleeper()
    try:
        _fake_state(env, "mine", mine)
        _fake_state(env, "theirs", theirs, prefix="/elsewhere/venv", package="/elsewhere/jaxchain")
        stop = _command(["server", "stop", "--json"], env, tmp_path)
        assert stop.returncode == 0 and json.loads(stop.stdout) == {"stopped": [mine.pid]}
        assert mine.wait(timeout=30) == -signal.SIGTERM
        assert theirs.poll() is None  # another installation's: left running
        assert [s["pid"] for s in _states(env)] == [theirs.pid]
        stop = _command(["server", "stop", "--all", "--json"], env, tmp_path)
        assert stop.returncode == 0 and json.loads(stop.stdout) == {"stopped": [theirs.pid]}
        assert theirs.wait(timeout=30) == -signal.SIGTERM
    finally:
        for process in (mine, theirs):
            process.kill()
            process.wait()
        _stop_all(env)


@needs_proc
def test_the_number_of_warm_processes_is_capped(tmp_path):
    """At JAXCHAIN_SERVER_MAX_PROCESSES warm processes, a command that would start
    another starts none while each runs a command, and stops the one idle
    longest to make room otherwise."""
    env = _new_env()
    busy, recent, old = _sleeper(), _sleeper(), _sleeper()
    start = [sys.executable, "-c", "import os; from jaxchain._cli.warm import start; "
             "start(dict(os.environ))"]
    try:
        _fake_state(env, "busy", busy, state="busy", command=["sweep"])
        _fake_state(env, "recent", recent, state="busy", command=["sweep"])
        at_two = dict(env, JAXCHAIN_SERVER_MAX_PROCESSES="2")
        assert subprocess.run(start, env=at_two, timeout=60).returncode == 0
        assert not list(_place(env).glob("*.starting"))  # none started
        assert busy.poll() is None and recent.poll() is None

        _fake_state(env, "recent", recent, since=time.time() - 10)
        _fake_state(env, "old", old, since=time.time() - 100)
        at_three = dict(env, JAXCHAIN_SERVER_MAX_PROCESSES="3")
        assert subprocess.run(start, env=at_three, timeout=60).returncode == 0
        started = list(_place(env).glob("*.starting"))
        assert len(started) == 1  # one started
        with contextlib.suppress(ProcessLookupError, ValueError):
            os.kill(int(started[0].read_text()), signal.SIGKILL)  # no need to let it load JAX
        assert old.wait(timeout=30) == -signal.SIGTERM  # the one idle longest made room
        assert busy.poll() is None and recent.poll() is None
    finally:
        for process in (busy, recent, old):
            process.kill()
            process.wait()
        _stop_all(env)
