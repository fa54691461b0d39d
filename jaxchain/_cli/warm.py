"""The warm process of the command line, as its commands see it: which warm process
may run a command (`key`), handing a command to it (`forward`), starting one
(`start`) and reading what each one says of itself (`states`). The warm process's
own side is `jaxchain._cli.warm_process`; `jaxchain server` shows and stops them.

- The first command runs in its own process, as always, and then starts the warm
  process in the background (one line on standard error says so). It stops after
  `IDLE_S` seconds without a command (JAXCHAIN_SERVER_IDLE, in seconds), when its
  code or its installed packages change, and on `jaxchain server stop`.
- A later command with the same Python, the same installed packages
  (`_installed_state`), the same jaxchain source files (`source_identity`), the
  same environment (every variable but those of the terminal and the login
  session, `SESSION_NAMES`, and the switches) and the same resource limits,
  nice value and CPU affinity (`process_settings`) runs there (`key`): a warm
  process was started with exactly what a process of the command's own would
  have, so that what libraries read once, at import (zarr's
  ZARR_DEFAULT_ZARR_FORMAT, JAX's and XLA's settings), and what limits a
  process is the command's own. It runs with its own standard input, output and
  error (their file descriptors are passed over the socket), working directory,
  environment, umask and `sys.argv` (the `history` of its results names it);
  its exit status comes back to the command. A command whose settings differ
  runs in its own process and starts a warm process of its own settings, at most
  `MAX_PROCESSES` of them per user (the one idle longest gives way).
- A command with a finite limit of CPU time or memory (`ulimit -t`, `-v`, `-d`:
  `OWN_PROCESS_LIMITS`) always runs in its own process: a warm process's
  earlier commands would count against it.
- One command at a time: a command that finds the warm process running another
  one runs in its own process; one that finds it finishing the previous command,
  or starting, waits for it.
- JAXCHAIN_SERVER=0 turns it off and JAXCHAIN_SERVER=1 on. Unset, it is on except
  under CI (CI set) or a batch scheduler (SLURM_JOB_ID, PBS_JOBID, LSB_JOBID set),
  where a process left behind does harm. It lives on POSIX systems only.

This module imports only the standard library and `jaxchain._setup` (no JAX), so
that a command handed over costs about 0.1 s of its own.

Protocol, over a Unix socket in this user's runtime folder (`folder`, mode 0700,
wherever $TMPDIR points): frames of
one byte of kind, four bytes of length and the payload. The warm process answers
a connection at once (a thread of its own listens): "a" when it will run the
command, "b" when it runs another one, "w" when it is replacing itself. After
"a" the command sends "r" with its request (JSON: argv, argv0, cwd, env, umask)
and its standard input, output and error; the warm process answers "s" with the
exit status (JSON) once the command's output is written and closed, or "e" with
a message (UTF-8) when the request is malformed (nothing ran: the command runs
in its own process).
"""

import array
import contextlib
import hashlib
import json
import os
import signal
import socket
import stat
import struct
import subprocess
import sys
import time

from .._setup import source_identity

#: Seconds a warm process waits for a command before it stops (JAXCHAIN_SERVER_IDLE).
IDLE_S = 600.0

#: The memory a warm process may hold between commands, in MiB
#: (JAXCHAIN_SERVER_MAX_MB): above it after a command, it replaces itself.
MAX_MB = 1024

#: The environment variables that the key leaves out: those of the terminal, the
#: shell and the login session, which differ between two terminals of one user
#: and which nothing that a command runs reads once for all. A command still
#: runs with its own values of these (argparse wraps its help at its COLUMNS).
SESSION_NAMES = frozenset({
    "COLUMNS", "LINES", "TERM", "COLORTERM", "TERM_PROGRAM", "TERM_PROGRAM_VERSION",
    "TERM_SESSION_ID", "VTE_VERSION", "WINDOWID", "DISPLAY", "TMUX", "TMUX_PANE", "STY",
    "WINDOW", "PWD", "OLDPWD", "SHLVL", "_", "GPG_TTY", "XDG_SESSION_ID", "XDG_VTNR",
    "SSH_CLIENT", "SSH_CONNECTION", "SSH_TTY", "SSH_AUTH_SOCK", "SSH_AGENT_PID", "MAIL"})

#: Resource limits that count what a process used over its life or holds: a
#: command with a finite soft limit of one of these runs in its own process, where
#: the limit is its own (a warm process's earlier commands would count too).
OWN_PROCESS_LIMITS = ("RLIMIT_CPU", "RLIMIT_AS", "RLIMIT_DATA")

#: The most warm processes a user has at a time (JAXCHAIN_SERVER_MAX_PROCESSES):
#: to start another, the one idle longest stops; where every one runs a command,
#: none starts.
MAX_PROCESSES = 4

#: The largest frame that a warm process reads (a request holds the arguments and
#: the environment, which the system bounds to a few MiB).
MAX_FRAME = 16 * 2**20

#: Switches of the warm process itself (JAXCHAIN_SERVER, JAXCHAIN_SERVER_IDLE,
#: JAXCHAIN_SERVER_MAX_MB, JAXCHAIN_SERVER_MAX_PROCESSES), not part of the key.
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

#: The folder of the jaxchain package that this module belongs to.
PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def enabled(env=os.environ) -> bool:
    """Whether commands use a warm process: JAXCHAIN_SERVER=1 turns it on, =0 off;
    unset, on unless one of `NO_SERVER_WHERE` is set. Only on systems with Unix
    sockets and user ids, and never for a process with a finite limit of
    `OWN_PROCESS_LIMITS`."""
    if not (hasattr(socket, "AF_UNIX") and hasattr(os, "getuid")) or limited():
        return False
    switch = env.get("JAXCHAIN_SERVER", "")
    if switch in ("0", "1"):
        return switch == "1"
    return not any(env.get(name) for name in NO_SERVER_WHERE)


def limited() -> bool:
    """Whether this process has a finite soft limit of `OWN_PROCESS_LIMITS`."""
    try:
        import resource
    except ImportError:  # no resource limits on this system
        return False
    return any(resource.getrlimit(getattr(resource, name))[0] != resource.RLIM_INFINITY
               for name in OWN_PROCESS_LIMITS if hasattr(resource, name))


def process_settings() -> dict:
    """What limits this process or where it runs, besides its environment: every
    resource limit (soft and hard), the nice value and the CPU affinity, where
    the system has them. A process started by this one inherits them."""
    found: dict = {}
    with contextlib.suppress(ImportError):
        import resource

        found["limits"] = {name: list(resource.getrlimit(getattr(resource, name)))
                           for name in sorted(dir(resource)) if name.startswith("RLIMIT_")}
    with contextlib.suppress(AttributeError, OSError):
        found["nice"] = os.getpriority(os.PRIO_PROCESS, 0)
    with contextlib.suppress(AttributeError, OSError):
        found["affinity"] = sorted(os.sched_getaffinity(0))
    return found


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
    """The key of the warm process that may run a command from `env` in this
    process: Python and its environment (`sys.prefix`), the installed packages
    (`_installed_state` of `paths`), the source files of jaxchain
    (`source_identity`), the environment variables (all but `SESSION_NAMES` and
    the switches) and the process's limits, nice value and CPU affinity
    (`process_settings`)."""
    chosen = {k: v for k, v in env.items()
              if k not in SESSION_NAMES and not k.startswith(SWITCH_PREFIX)}
    data = {"prefix": sys.prefix, "python": os.path.realpath(sys.executable),
            "version": sys.version, "source": source_identity(),
            "installed": _installed_state(paths), "env": chosen,
            "process": process_settings()}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:24]


def installation() -> dict:
    """This installation of jaxchain: its Python environment and package folder
    (`jaxchain server stop` stops only the warm processes of this one)."""
    return {"prefix": sys.prefix, "package": PACKAGE}


def folder() -> str:
    """The folder of this user's warm processes, whatever $TMPDIR is: `jaxchain`
    in the user's runtime folder, $XDG_RUNTIME_DIR or else /run/user/UID (each
    where it is a folder of the user's own that no one else may enter, as the XDG
    Base Directory specification requires), else /tmp/jaxchain-UID; made with
    mode 0700 if missing. Not in the home folder, which a cluster's nodes may
    share (a process id names a process of one machine only).

    **Raises:** `OSError` when it is a link, belongs to another user or others may
    enter it."""
    uid = os.getuid()
    for runtime in (os.environ.get("XDG_RUNTIME_DIR", ""), f"/run/user/{uid}"):
        if os.path.isabs(runtime) and _private(runtime):
            path = os.path.join(runtime, "jaxchain")
            break
    else:
        path = f"/tmp/jaxchain-{uid}"
    os.makedirs(path, mode=0o700, exist_ok=True)
    if not _private(path):  # a link or folder planted by another user is refused
        raise OSError(f"{path} is not private to this user")
    return path


def _private(path: str) -> bool:
    """Whether `path` is a folder (not a link) of this user that no one else may
    enter or change."""
    try:
        info = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & 0o077


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
    descriptors that came with it are appended to `fds`.

    **Raises:** `ValueError` for a frame longer than `MAX_FRAME` (not read)."""
    header = _exactly(conn, _HEADER.size, fds)
    if header is None:
        return None
    kind, length = _HEADER.unpack(header)
    if length > MAX_FRAME:
        raise ValueError(f"a frame of {length} bytes (at most {MAX_FRAME})")
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
    process's, as it started) and of this process's limits, nice value and CPU
    affinity (`key`), with this process's standard streams, working directory,
    umask and `sys.argv[0]`: its exit status; None when there is no such warm
    process, it runs another command or it refused the request (then run it
    here)."""
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
    request = {"argv": argv, "argv0": sys.argv[0] if sys.argv else "jaxchain",
               "cwd": os.getcwd(), "env": env, "umask": umask}
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
    except (OSError, ValueError):
        frame = None
    conn.close()
    if frame is not None and frame[0] == b"s":
        return int(json.loads(frame[1]))
    if frame is not None and frame[0] == b"e":  # refused before it ran: run it here
        return None
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
        except (OSError, ValueError):  # no socket yet, refused (gone), no answer (stopped)
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
    since (ids are reused, 32768 of them by default on Linux) is not, and
    neither is a process that ended and that its parent has not yet reaped (a
    zombie: a container's first process may never reap it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's: not a warm process of this user
        return False
    fields = _stat(pid)
    if fields is None:  # the system does not tell
        return True
    return fields[0] not in ("Z", "X") and (start is None or fields[19] == start)


def process_start(pid: int | None = None) -> str | None:
    """When process `pid` (this one by default) started, in the system's clock
    ticks since boot (field 22 of /proc/PID/stat): with its id, it names one
    process. None where the system does not tell (no /proc)."""
    fields = _stat(pid)
    return None if fields is None else fields[19]


def _stat(pid: int | None) -> list[str] | None:
    """The fields of /proc/PID/stat after the name (its state first, then from
    field 4 on), or None where the system does not tell."""
    try:
        with open(f"/proc/{pid or 'self'}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return fields if len(fields) > 19 else None


def _command_name(argv: list[str]) -> str:
    return next((a for a in argv if not a.startswith("-")), "").strip() or "command"


def start(env: dict) -> None:
    """Start the warm process of the environment `env` (and of this process's
    limits, nice value and CPU affinity) in the background, unless one runs or is
    starting; say so in one line on standard error. Where the user has
    `MAX_PROCESSES` already (JAXCHAIN_SERVER_MAX_PROCESSES), the one idle longest
    is stopped first, and none starts when every one runs a command."""
    import fcntl

    try:
        place = folder()
        base = os.path.join(place, key(env))
        if _listening(f"{base}.sock") or _starting(base):
            return
        lock = os.open(os.path.join(place, "start.lock"), os.O_CREAT | os.O_RDWR, 0o600)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX)  # one start at a time: the count holds
            if _starting(base) or not _room(place, _max_processes(env)):
                return
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"{base}.starting")  # a failed start
            spawn(base, env)
        finally:
            os.close(lock)
    except (OSError, ValueError):
        return
    idle = env.get("JAXCHAIN_SERVER_IDLE", f"{IDLE_S:g}")
    print(f"jaxchain: a warm process keeps JAX loaded for the next commands (it stops "
          f"after {idle} idle seconds; 'jaxchain server status' shows it, "
          f"JAXCHAIN_SERVER=0 turns it off)", file=sys.stderr)


def _max_processes(env: dict) -> int:
    """The most warm processes a user may have (JAXCHAIN_SERVER_MAX_PROCESSES, at
    least 1; `MAX_PROCESSES` unset or unreadable)."""
    try:
        return max(1, int(env.get("JAXCHAIN_SERVER_MAX_PROCESSES", MAX_PROCESSES)))
    except ValueError:
        return MAX_PROCESSES


def _room(place: str, most: int) -> bool:
    """Whether one more warm process may start in `place`, where at most `most`
    may live: those idle longest are stopped (SIGTERM) to make room; False when
    the others run commands."""
    found = states()
    starting = [name for name in os.listdir(place)
                if name.endswith(".starting") and _starting(os.path.join(place, name[:-9]))]
    extra = len(found) + len(starting) + 1 - most
    idle = sorted((s for s in found if s["state"] == "idle"), key=lambda s: -s["idle_s"])
    if extra > len(idle):
        return False
    for state in idle[:max(extra, 0)]:
        with contextlib.suppress(ProcessLookupError):
            if alive(state["pid"], state.get("start")):
                os.kill(state["pid"], signal.SIGTERM)
    return True


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
    id, version, installation, state, idle seconds, memory (read now where the
    system tells, else as it was after its last command) and key. The files of
    processes that are gone (a zombie included) are removed."""
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
            pid = state["pid"]
        except (OSError, ValueError, TypeError, KeyError):
            continue
        if not isinstance(pid, int):
            continue
        if not alive(pid, state.get("start")):
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
