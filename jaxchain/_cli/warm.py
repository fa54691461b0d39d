"""The warm process of the command line: the `jaxchain` console script hands its
command to a process that has JAX and jaxchain imported and the programs of the
earlier commands loaded, so that a small command costs its own work, not the
start of Python, JAX and the libraries that write its results.

- The first command runs in its own process, as always, and then starts the warm
  process in the background (one line on standard error says so). It stops after
  `IDLE_S` seconds without a command (JAXCHAIN_SERVER_IDLE, in seconds).
- A later command with the same Python, the same jaxchain source files
  (`source_identity`) and the same environment variables that set JAX, XLA,
  jaxchain, matplotlib, threads and paths (`key`) is run there, in its own
  working directory and with its whole environment; its standard output, standard
  error and exit status come back to the command as if it had run itself.
- One command at a time: a command that finds the warm process busy runs in its
  own process. Ctrl-C in the command interrupts it in the warm process too.
- JAXCHAIN_SERVER=0 turns it off (the tests do). It lives on POSIX systems only.

This module imports only the standard library and `jaxchain._setup` (no JAX), so
that a command handed over costs about 0.1 s of its own.

Protocol, over a Unix socket in a folder of the user's own (mode 0700): frames of
one byte of kind, four bytes of length and the payload. The warm process sends "a"
when it accepts a command (within `ACCEPT_S`, or the command runs in its own
process and sends nothing); the command then sends "r" with its request (JSON:
argv, cwd, env, whether its output streams are terminals); the warm process
answers "o" and "e" with bytes of standard output and error, and "s" with the exit
status (JSON).
"""

import atexit
import hashlib
import io
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from .._setup import source_identity

#: Seconds a warm process waits for a command before it stops (JAXCHAIN_SERVER_IDLE).
IDLE_S = 600.0

#: The environment variables that are part of the key: a command whose values of
#: these differ from the warm process's starts (or finds) a warm process of its own.
KEY_PREFIXES = ("JAX", "XLA", "TF_", "CUDA", "NVIDIA", "MPL", "PYTHON", "OMP_", "MKL_",
                "OPENBLAS_", "XDG_", "DASK_", "TQDM_", "LD_")
KEY_NAMES = ("HOME", "TMPDIR")

#: Switches of the warm process itself, not part of the key.
SWITCHES = ("JAXCHAIN_SERVER", "JAXCHAIN_SERVER_IDLE")

#: Seconds a command waits to be accepted before it runs in its own process (the
#: warm process is busy with another command).
ACCEPT_S = 0.5

_HEADER = struct.Struct(">cI")


def enabled(env=os.environ) -> bool:
    """Whether commands use a warm process: unless JAXCHAIN_SERVER=0, on systems
    with Unix sockets and user ids."""
    return (env.get("JAXCHAIN_SERVER", "1") != "0" and hasattr(socket, "AF_UNIX")
            and hasattr(os, "getuid"))


def key(env=os.environ) -> str:
    """The key of the warm process that may run a command from `env`: Python and
    its environment (`sys.prefix`: the venv, so its installed packages), the source
    files of jaxchain and the environment variables of `KEY_PREFIXES` and
    `KEY_NAMES` (`SWITCHES` aside)."""
    chosen = {k: v for k, v in env.items()
              if (k.startswith(KEY_PREFIXES) or k in KEY_NAMES) and k not in SWITCHES}
    data = {"prefix": sys.prefix, "python": os.path.realpath(sys.executable),
            "version": sys.version, "source": source_identity(), "env": chosen}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:24]


def folder() -> str:
    """The folder of the warm processes' sockets, the user's own: made with mode
    0700 if missing.

    **Raises:** `OSError` when it belongs to another user or others may enter it."""
    path = os.path.join(tempfile.gettempdir(), f"jaxchain-{os.getuid()}")
    os.makedirs(path, mode=0o700, exist_ok=True)
    info = os.stat(path)
    if info.st_uid != os.getuid() or info.st_mode & 0o077:
        raise OSError(f"{path} is not private to this user")
    return path


def _send(conn: socket.socket, kind: bytes, payload: bytes) -> None:
    conn.sendall(_HEADER.pack(kind, len(payload)) + payload)


def _receive(conn: socket.socket) -> tuple[bytes, bytes] | None:
    """The next frame (kind, payload), or None at the end of the stream."""
    header = _exactly(conn, _HEADER.size)
    if header is None:
        return None
    kind, length = _HEADER.unpack(header)
    payload = _exactly(conn, length)
    return None if payload is None else (kind, payload)


def _exactly(conn: socket.socket, n: int) -> bytes | None:
    chunks, left = [], n
    while left:
        chunk = conn.recv(min(left, 1 << 16))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


# -- the command's side ------------------------------------------------------------

def forward(argv: list[str], env: dict) -> int | None:
    """Run `jaxchain argv` in the warm process of the environment `env` (this
    process's, as it started): its exit status, with its output written to this
    process's standard output and error; None when there is no warm process, or
    it is busy (then run it here)."""
    if not enabled(env):
        return None
    try:
        path = os.path.join(folder(), f"{key(env)}.sock")
        conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        conn.settimeout(ACCEPT_S)
        conn.connect(path)
        # Accepted first, then the request: a command that gave up waiting (busy)
        # has sent nothing, so the warm process never runs it a second time.
        first = _receive(conn)
        if first is None or first[0] != b"a":
            return None
        request = {"argv": argv, "cwd": os.getcwd(), "env": env,
                   "tty": [_isatty(sys.stdout), _isatty(sys.stderr)]}
        _send(conn, b"r", json.dumps(request).encode())
    except OSError:  # no warm process, a stale socket, or busy past ACCEPT_S
        return None
    conn.settimeout(None)
    try:
        while (frame := _receive(conn)) is not None:
            kind, payload = frame
            if kind == b"s":
                return int(json.loads(payload))
            stream = sys.stdout if kind == b"o" else sys.stderr
            stream.buffer.write(payload)
            stream.flush()
    except KeyboardInterrupt:  # closing the socket interrupts the command there
        conn.close()
        print(f"jaxchain {_command_name(argv)}: error: interrupted", file=sys.stderr)
        return 130
    print(f"jaxchain {_command_name(argv)}: error: the warm process ended during the "
          f"command (JAXCHAIN_SERVER=0 runs commands in their own process)", file=sys.stderr)
    return 1


def _command_name(argv: list[str]) -> str:
    return next((a for a in argv if not a.startswith("-")), "").strip() or "command"


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def start(env: dict) -> None:
    """Start the warm process of the environment `env` in the background, unless
    one runs or is starting; say so in one line on standard error."""
    try:
        base = os.path.join(folder(), key(env))
        if _alive(f"{base}.sock"):
            return
        marker = f"{base}.starting"
        try:  # one starter at a time; a marker older than a minute is a failed start
            if time.time() - os.stat(marker).st_mtime < 60:
                return
            os.unlink(marker)
        except FileNotFoundError:
            pass
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        subprocess.Popen([sys.executable, "-m", "jaxchain._cli.warm", base],
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True, close_fds=True,
                         cwd=os.path.dirname(base), env=env)
    except OSError:
        return
    idle = env.get("JAXCHAIN_SERVER_IDLE", f"{IDLE_S:g}")
    print(f"jaxchain: a warm process keeps JAX loaded for the next commands (it stops "
          f"after {idle} idle seconds; JAXCHAIN_SERVER=0 turns it off)", file=sys.stderr)


def _alive(path: str) -> bool:
    """Whether a warm process listens at `path`; a socket left by one that was
    killed is removed."""
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(path)
        return True
    except FileNotFoundError:
        return False
    except OSError:  # refused: nobody listens there any more
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        return False
    finally:
        probe.close()


def command() -> None:
    """The `jaxchain` console script: the command in the warm process (`forward`),
    or here (`jaxchain._cli.main.run_here`), after which the warm process is
    started for the next commands (`start`). The process then ends without the
    interpreter's teardown (`os._exit`, after the exit functions and a flush of
    standard output and error): freeing every module and the JAX runtime's
    objects one by one took 0.7 s and serves nothing, as every file is written
    and closed by then (`benchmarks/fixed_cost.py`)."""
    argv, env = sys.argv[1:], dict(os.environ)  # the environment before the command's set-up
    status = forward(argv, env)
    if status is None:
        from .main import run_here

        status = run_here(argv)
        if enabled(env) and status in (0, 1) and argv and not argv[0].startswith("-"):
            start(env)
    try:
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:  # the reader of our output went away: nothing to say
        pass
    os._exit(status)


# -- the warm process's side --------------------------------------------------------

class _Stream(io.TextIOBase):
    """Standard output or error of the command being served: text sent to it in
    frames of `kind`, a terminal if the command's own stream is one."""

    def __init__(self, conn, kind: bytes, tty: bool, lock: threading.Lock):
        self._conn, self._kind, self._tty, self._lock = conn, kind, tty, lock

    def write(self, text: str) -> int:
        with self._lock:
            try:
                _send(self._conn, self._kind, text.encode())
            except OSError:  # the command went away; its interrupt follows
                pass
        return len(text)

    def isatty(self) -> bool:
        return self._tty

    @property
    def encoding(self) -> str:
        return "utf-8"


def serve(base: str) -> None:
    """Be the warm process at `<base>.sock`: import what the commands use, listen,
    and run each command as `run_here` would, until `IDLE_S` seconds pass without
    one (or SIGTERM). Its process id is in `<base>.pid` from its start."""
    import contextlib

    path = f"{base}.sock"
    # First, so that whoever started it can stop it; renamed into place whole.
    partial = Path(f"{base}.pid.{os.getpid()}.tmp")
    partial.write_text(str(os.getpid()))
    os.replace(partial, f"{base}.pid")
    # Stopped (SIGTERM): the loop ends at its next wait. An exception raised by
    # the handler could land in a callback whose exceptions Python ignores.
    signal.signal(signal.SIGTERM, lambda *_: _stopped.set())
    # Ctrl-C in a command reaches the command here as SIGINT (`_run_one`), even
    # where the process that started this one ignored it (a background job).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _listen(base, path)
    finally:
        for name in (path, f"{base}.pid", f"{base}.starting"):
            with contextlib.suppress(OSError):
                os.unlink(name)


#: Set by SIGTERM: the warm process stops at its next wait for a command.
_stopped = threading.Event()


def _listen(base: str, path: str) -> None:
    import gc

    from .common import RESULT_MODULES
    from .main import main
    from .._setup import configure

    configure()
    for name in RESULT_MODULES:  # what writing results imports, once for all commands
        __import__(name)
    gc.freeze()  # what the imports made: never collected
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(f"{path}.{os.getpid()}")
    os.replace(f"{path}.{os.getpid()}", path)  # appears whole, ready to accept
    if os.path.exists(f"{base}.starting"):
        os.unlink(f"{base}.starting")
    server.listen(8)
    server.settimeout(1.0)  # waits of a second, to see `_stopped` and the idle time
    idle = float(os.environ.get("JAXCHAIN_SERVER_IDLE", IDLE_S))
    last = time.monotonic()
    while True:
        try:
            conn, _ = server.accept()
        except TimeoutError:
            if time.monotonic() - last > idle or _stopped.is_set():
                return
            continue
        last = time.monotonic()
        try:
            _run_one(conn, main)
        except (KeyboardInterrupt, OSError):  # an interrupt after its command; a lost command
            pass
        finally:
            conn.close()
        gc.collect()  # the command's cycles, after its status went back
        last = time.monotonic()
        if _stopped.is_set():
            return


def _run_one(conn: socket.socket, main) -> None:
    """Run one command from `conn` in this process, with its environment, working
    directory and output streams, and send its exit status."""
    import contextlib

    _send(conn, b"a", b"")
    conn.settimeout(5.0)  # the request follows at once, or the command went away
    frame = _receive(conn)
    conn.settimeout(None)
    if frame is None or frame[0] != b"r":
        return
    request = json.loads(frame[1])
    lock, done = threading.Lock(), threading.Event()

    main_thread = threading.main_thread().ident

    def watch():  # the command went away (Ctrl-C): interrupt it here too
        with contextlib.suppress(OSError):
            conn.recv(1)
        if not done.is_set():  # a signal, which also wakes a thread waiting on a lock
            signal.pthread_kill(main_thread, signal.SIGINT)

    threading.Thread(target=watch, daemon=True).start()
    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    out, err = (_Stream(conn, kind, tty, lock) for kind, tty in zip((b"o", b"e"), request["tty"]))
    try:
        os.environ.clear()
        os.environ.update(request["env"])
        os.chdir(request["cwd"])
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(request["argv"])
            except SystemExit as exit_:  # --help, --version
                status = exit_.code if isinstance(exit_.code, int) else int(exit_.code is not None)
    finally:
        done.set()
        os.environ.clear()
        os.environ.update(saved_env)
        os.chdir(saved_cwd)
    with lock:
        _send(conn, b"s", json.dumps(status).encode())


if __name__ == "__main__":
    serve(sys.argv[1])
