"""The warm process of the command line, as its commands see it: which warm process
may run a command (`key`), handing a command to it (`forward`), starting one
(`start`) and reading what each one says of itself (`states`). The warm process's
own side is `jaxchain._cli.warm_process`; `jaxchain server` shows and stops them.

- The first command runs in its own process, as always, and then starts the warm
  process in the background (one line on standard error says so). It stops after
  `IDLE_S` seconds without a command (JAXCHAIN_SERVER_IDLE, in seconds), when its
  code or its installed packages change, and on `jaxchain server stop`.
- A later command with the same Python, the same installed packages
  (`_installed_state`), the same jaxchain source files (`source_identity`) and the
  same environment variables that set JAX, XLA, jaxchain, matplotlib, threads and
  paths (`key`) runs there, with its own standard input, output and error (their
  file descriptors are passed over the socket), working directory, environment
  and umask; its exit status comes back to the command.
- One command at a time: a command that finds the warm process running another
  one runs in its own process; one that finds it finishing the previous command,
  or starting, waits for it.
- JAXCHAIN_SERVER=0 turns it off and JAXCHAIN_SERVER=1 on. Unset, it is on except
  under CI (CI set) or a batch scheduler (SLURM_JOB_ID, PBS_JOBID, LSB_JOBID set),
  where a process left behind does harm. It lives on POSIX systems only.

This module imports only the standard library and `jaxchain._setup` (no JAX), so
that a command handed over costs about 0.1 s of its own.

Protocol, over a Unix socket in a folder of the user's own (mode 0700): frames of
one byte of kind, four bytes of length and the payload. The warm process answers
a connection at once (a thread of its own listens): "a" when it will run the
command, "b" when it runs another one, "w" when it is replacing itself. After
"a" the command sends "r" with its request (JSON: argv, cwd, env, umask) and its
standard input, output and error; the warm process answers "s" with the exit
status (JSON) once the command's output is written and closed.
"""

import array
import contextlib
import hashlib
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time

from .._setup import source_identity

#: Seconds a warm process waits for a command before it stops (JAXCHAIN_SERVER_IDLE).
IDLE_S = 600.0

#: The memory a warm process may hold between commands, in MiB
#: (JAXCHAIN_SERVER_MAX_MB): above it after a command, it replaces itself.
MAX_MB = 1024

#: The environment variables that are part of the key: a command whose values of
#: these differ from the warm process's starts (or finds) a warm process of its own.
KEY_PREFIXES = ("JAX", "XLA", "TF_", "CUDA", "NVIDIA", "MPL", "PYTHON", "OMP_", "MKL_",
                "OPENBLAS_", "XDG_", "DASK_", "TQDM_", "LD_", "LC_", "LANG")
KEY_NAMES = ("HOME", "TMPDIR")

#: Switches of the warm process itself (JAXCHAIN_SERVER, JAXCHAIN_SERVER_IDLE,
#: JAXCHAIN_SERVER_MAX_MB), not part of the key.
SWITCH_PREFIX = "JAXCHAIN_SERVER"

#: Where a lingering process does harm: continuous integration and batch schedulers.
#: The warm process does not start there unless JAXCHAIN_SERVER=1.
NO_SERVER_WHERE = ("CI", "SLURM_JOB_ID", "PBS_JOBID", "LSB_JOBID")

#: Seconds a command waits for the warm process's answer. It answers at once from
#: a thread of its own; only a stopped or hung process makes a command wait this
#: long, and then run in its own process.
ANSWER_S = 5.0

#: Seconds a command waits for a warm process that is starting (or replacing
#: itself) before it runs in its own process.
START_S = 30.0

_HEADER = struct.Struct(">cI")


def enabled(env=os.environ) -> bool:
    """Whether commands use a warm process: JAXCHAIN_SERVER=1 turns it on, =0 off;
    unset, on unless one of `NO_SERVER_WHERE` is set. Only on systems with Unix
    sockets and user ids."""
    if not (hasattr(socket, "AF_UNIX") and hasattr(os, "getuid")):
        return False
    switch = env.get("JAXCHAIN_SERVER", "")
    if switch in ("0", "1"):
        return switch == "1"
    return not any(env.get(name) for name in NO_SERVER_WHERE)


def _installed_state(paths=None) -> list:
    """The installed distributions on `paths` (by default the site-packages folders
    of `sys.path`, not the working directory or the script's): each `*.dist-info`
    and `*.egg-info` entry's name (which holds the version) and its modification
    time (a reinstall of the same version makes it anew), and the `.pth` files
    (editable installs). An upgrade of JAX in the venv changes it."""
    if paths is None:
        paths = [p for p in sys.path if os.path.basename(p) in ("site-packages", "dist-packages")]
    found = []
    for path in paths:
        try:
            entries = os.scandir(path or ".")
        except OSError:
            continue
        with entries:
            for entry in entries:
                if entry.name.endswith((".dist-info", ".egg-info", ".pth")):
                    try:
                        found.append([path, entry.name, entry.stat().st_mtime_ns])
                    except OSError:
                        continue
    return sorted(found)


def key(env=os.environ, paths=None) -> str:
    """The key of the warm process that may run a command from `env`: Python and
    its environment (`sys.prefix`), the installed packages (`_installed_state` of
    `paths`), the source files of jaxchain (`source_identity`) and the environment
    variables of `KEY_PREFIXES` and `KEY_NAMES` (the switches aside)."""
    chosen = {k: v for k, v in env.items()
              if (k.startswith(KEY_PREFIXES) or k in KEY_NAMES)
              and not k.startswith(SWITCH_PREFIX)}
    data = {"prefix": sys.prefix, "python": os.path.realpath(sys.executable),
            "version": sys.version, "source": source_identity(),
            "installed": _installed_state(paths), "env": chosen}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:24]


def folder() -> str:
    """The folder of the warm processes' sockets, the user's own: made with mode
    0700 if missing.

    **Raises:** `OSError` when it is a link, belongs to another user or others may
    enter it."""
    import stat

    path = os.path.join(tempfile.gettempdir(), f"jaxchain-{os.getuid()}")
    os.makedirs(path, mode=0o700, exist_ok=True)
    info = os.lstat(path)  # a link planted by another user is refused, not followed
    if (not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid()
            or info.st_mode & 0o077):
        raise OSError(f"{path} is not private to this user")
    return path


def send(conn: socket.socket, kind: bytes, payload: bytes = b"", fds=()) -> None:
    """Send one frame, with the file descriptors `fds` (SCM_RIGHTS)."""
    data = _HEADER.pack(kind, len(payload)) + payload
    if fds:
        sent = conn.sendmsg([data], [(socket.SOL_SOCKET, socket.SCM_RIGHTS,
                                      array.array("i", fds))])
        data = data[sent:]
    if data:  # sendall of nothing fails on a socket the other end has closed
        conn.sendall(data)


def receive(conn: socket.socket, fds: list | None = None) -> tuple[bytes, bytes] | None:
    """The next frame (kind, payload), or None at the end of the stream; file
    descriptors that came with it are appended to `fds`."""
    header = _exactly(conn, _HEADER.size, fds)
    if header is None:
        return None
    kind, length = _HEADER.unpack(header)
    payload = _exactly(conn, length, fds)
    return None if payload is None else (kind, payload)


def _exactly(conn: socket.socket, n: int, fds: list | None) -> bytes | None:
    chunks, left = [], n
    while left:
        if fds is None:
            chunk = conn.recv(min(left, 1 << 16))
        else:  # only the first bytes carry descriptors; `recvmsg` takes them
            chunk, ancillary, _, _ = conn.recvmsg(min(left, 1 << 16),
                                                 socket.CMSG_SPACE(8 * 4))
            for level, kind, data in ancillary:
                if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
                    fds.extend(array.array("i", data[:len(data) - len(data) % 4]))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


# -- a command handed to the warm process ------------------------------------------

def forward(argv: list[str], env: dict) -> int | None:
    """Run `jaxchain argv` in the warm process of the environment `env` (this
    process's, as it started), with this process's standard streams: its exit
    status; None when there is no warm process, or it runs another command (then
    run it here)."""
    if not enabled(env):
        return None
    try:
        base = os.path.join(folder(), key(env))
    except OSError:
        return None
    conn = _accepted(base)
    if conn is None:
        return None
    umask = os.umask(0o022)
    os.umask(umask)
    request = {"argv": argv, "cwd": os.getcwd(), "env": env, "umask": umask}
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        send(conn, b"r", json.dumps(request).encode(), fds=(0, 1, 2))
    except OSError:  # it went away before the request: nothing ran there
        conn.close()
        return None
    conn.settimeout(None)
    try:
        frame = receive(conn)
    except KeyboardInterrupt:  # the end of the stream interrupts the command there
        _interrupt(conn)
        print(f"jaxchain {_command_name(argv)}: error: interrupted", file=sys.stderr)
        return 130
    except OSError:
        frame = None
    conn.close()
    if frame is not None and frame[0] == b"s":
        return int(json.loads(frame[1]))
    print(f"jaxchain {_command_name(argv)}: error: the warm process ended during the "
          f"command (JAXCHAIN_SERVER=0 runs commands in their own process)", file=sys.stderr)
    return 1


def _interrupt(conn: socket.socket) -> None:
    """Interrupt the command that `conn` runs (the end of its stream), and wait, at
    most `ANSWER_S`, until the warm process stopped it: an immediate rerun then
    finds it free, not still writing."""
    with contextlib.suppress(OSError, KeyboardInterrupt):
        conn.shutdown(socket.SHUT_WR)
        conn.settimeout(ANSWER_S)
        while receive(conn) is not None:
            pass
    conn.close()


def _accepted(base: str) -> socket.socket | None:
    """A connection to the warm process at `base` that has accepted a command, or
    None (none there, or it runs another command). A warm process that is starting
    or replacing itself (`<base>.starting` names a live process) is waited for."""
    end = time.monotonic() + START_S
    while True:
        conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        conn.settimeout(ANSWER_S)
        try:
            conn.connect(f"{base}.sock")
            answer = receive(conn)
        except OSError:  # no socket yet, refused (gone), or no answer (stopped)
            answer = None
        if answer is not None and answer[0] == b"a":
            return conn
        conn.close()
        if answer is not None and answer[0] == b"b":
            return None
        replacing = answer is not None and answer[0] == b"w"
        if time.monotonic() > end or not (replacing or _starting(base)):
            return None
        time.sleep(0.05)


def _starting(base: str) -> bool:
    """Whether a warm process is starting at `base`: its marker holds the id of a
    live process (or is younger than 5 s, before the id is written)."""
    marker = f"{base}.starting"
    try:
        text = open(marker).read().strip()
        age = time.time() - os.stat(marker).st_mtime
    except OSError:
        return False
    if not text:
        return age < 5
    return alive(int(text)) and age < 120


def alive(pid: int, start: str | None = None) -> bool:
    """Whether process `pid` is alive and, given its `start` (`process_start`),
    still the same process: an id that the system has given to another process
    since (ids are reused, 32768 of them by default on Linux) is not."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's: not a warm process of this user
        return False
    now = process_start(pid)
    return start is None or now is None or now == start


def process_start(pid: int | None = None) -> str | None:
    """When process `pid` (this one by default) started, in the system's clock
    ticks since boot (field 22 of /proc/PID/stat): with its id, it names one
    process. None where the system does not tell (no /proc)."""
    try:
        with open(f"/proc/{pid or 'self'}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return fields[19]  # the fields after the name start at field 3
    except (OSError, IndexError):
        return None


def _command_name(argv: list[str]) -> str:
    return next((a for a in argv if not a.startswith("-")), "").strip() or "command"


def start(env: dict) -> None:
    """Start the warm process of the environment `env` in the background, unless
    one runs or is starting; say so in one line on standard error."""
    try:
        base = os.path.join(folder(), key(env))
        if _listening(f"{base}.sock") or _starting(base):
            return
        with contextlib.suppress(FileNotFoundError):
            os.unlink(f"{base}.starting")  # a failed start
        spawn(base, env)
    except (OSError, ValueError):
        return
    idle = env.get("JAXCHAIN_SERVER_IDLE", f"{IDLE_S:g}")
    print(f"jaxchain: a warm process keeps JAX loaded for the next commands (it stops "
          f"after {idle} idle seconds; 'jaxchain server status' shows it, "
          f"JAXCHAIN_SERVER=0 turns it off)", file=sys.stderr)


def _listening(path: str) -> bool:
    """Whether a warm process listens at `path`; a socket left by one that was
    killed (nobody listens: refused) is removed."""
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(path)
        return True
    except ConnectionRefusedError:
        with contextlib.suppress(OSError):
            os.unlink(path)
        return False
    except OSError:
        return False
    finally:
        probe.close()


def spawn(base: str, env: dict, before=None) -> None:
    """Start the warm process at `base` with the environment `env`, its id in
    `<base>.starting` until it listens; `before()` is called once the marker is
    there (a process that replaces itself removes its files).

    **Raises:** `FileExistsError` when another one is starting."""
    marker = os.open(f"{base}.starting", os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
    try:
        if before is not None:
            before()
        process = subprocess.Popen(
            [sys.executable, "-m", "jaxchain._cli.warm_process", base],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True, close_fds=True, cwd=os.path.dirname(base), env=env)
        os.write(marker, str(process.pid).encode())
    finally:
        os.close(marker)


# -- what the warm processes say of themselves -------------------------------------

def states() -> list[dict]:
    """Each warm process of this user (`<key>.json`, written by it): its process
    id, version, environment, state, idle seconds and memory (read now where the
    system tells, else as it was after its last command). The files of processes
    that are gone are removed."""
    try:
        place = folder()
    except OSError:
        return []
    found = []
    for name in sorted(os.listdir(place)):
        if not name.endswith(".json"):
            continue
        path = os.path.join(place, name)
        try:
            state = json.loads(open(path).read())
        except (OSError, ValueError):
            continue
        if not alive(state["pid"], state.get("start")):
            for suffix in (".json", ".sock", ".pid", ".log"):
                with contextlib.suppress(OSError):
                    os.unlink(path[:-5] + suffix)
            continue
        rss = rss_mb(state["pid"])
        state["rss_mb"] = state.get("rss_mb") if rss is None else rss
        state["idle_s"] = None if state["state"] != "idle" else time.time() - state["since"]
        state["key"] = name[:-5]
        found.append(state)
    return found


def rss_mb(pid: int | None = None) -> float | None:
    """The resident memory of process `pid` (this one by default) in MiB, where the
    system tells it (/proc on Linux); None elsewhere."""
    try:
        with open(f"/proc/{pid or 'self'}/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
