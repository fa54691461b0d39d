"""The warm process of the command line, its own side (`jaxchain._cli.warm` is the
commands' side): it imports JAX, jaxchain and what writing results needs once,
then runs the commands handed to it, one at a time, until it is idle for
`IDLE_S` seconds, stopped (SIGTERM, `jaxchain server stop`: it takes no more
commands and ends once the one it runs has finished) or stale.

- **Answered at once.** A thread of its own accepts each connection and answers
  it: "a" (run here), "b" (another command runs: run in your own process) or "w"
  (replacing itself: wait for the new one). What the process does after a command
  (collecting its garbage, measuring its memory) never makes the next command
  run in its own process; the next one waits for it instead.
- **As a process of its own.** It was started with the environment, resource
  limits, nice value and CPU affinity of the commands it serves (they are part
  of its key, `jaxchain._cli.warm.key`). A command runs with its own standard
  input, output and error (their descriptors, passed over the socket), working
  directory, environment, umask and `sys.argv`; its output is closed before its
  exit status goes back. A malformed request is answered "e" with a message.
- **Bounded.** After a command that leaves it above `MAX_MB` MiB
  (JAXCHAIN_SERVER_MAX_MB), it replaces itself by a fresh process, as gunicorn's
  `max_requests` and Celery's `worker_max_memory_per_child` do.
- **Never stale.** Every two seconds while idle it computes its key again
  (`jaxchain._cli.warm.key`: jaxchain's sources, the installed packages); when
  it changed, it stops, and the next command runs the code installed now.
- **Stoppable.** A command that goes away (Ctrl-C) interrupts its work here, and
  a fresh process replaces this one (an interrupt can leave JAX's caches half
  written); work that does not return to Python within `GRACE_S` seconds (a long
  trajectory in XLA) ends this process at once.
- **Visible.** `<key>.json` says what it is and does (`jaxchain server status`),
  `<key>.log` has one line per command.
"""

import contextlib
import gc
import json
import os
import queue
import signal
import socket
import sys
import threading
import time
import traceback
import warnings

from .._setup import VERSION
from .._sweeps.atomic import write_text
from .warm import IDLE_S, MAX_MB, PACKAGE, key, process_start, receive, rss_mb, send, spawn

#: Seconds between two checks, while idle, that the code and packages are unchanged.
STALE_CHECK_S = 2.0

#: Seconds that an interrupted command may take to stop before the process ends.
GRACE_S = 1.5


class _Warm:
    """The warm process at `<base>.sock`: its settings from the environment it was
    started with, and what it is doing."""

    def __init__(self, base: str):
        self.base = base
        self.env = dict(os.environ)  # before `configure` adds to it
        self.paths = list(sys.path)
        self.key = key(self.env, self.paths)
        self.idle_s = float(self.env.get("JAXCHAIN_SERVER_IDLE", IDLE_S))
        self.max_mb = float(self.env.get("JAXCHAIN_SERVER_MAX_MB", MAX_MB))
        self.lock = threading.Lock()
        self.busy = False  # a command accepted and not yet answered
        self.closing = b""  # b"w" replacing itself, b"b" stopping: the answer from now on
        self.commands: queue.Queue = queue.Queue()
        self.stopped = threading.Event()
        self.replacing = threading.Lock()
        self.served = 0
        self.started = time.time()

    # -- what it says of itself ----------------------------------------------------

    def state(self, state: str, **extra) -> None:
        """Write `<base>.json` (`jaxchain._cli.warm.states` reads it)."""
        record = {"pid": os.getpid(), "start": process_start(), "version": VERSION,
                  "prefix": sys.prefix, "package": PACKAGE,
                  "python": sys.executable, "state": state, "since": time.time(),
                  "started": self.started, "served": self.served, "rss_mb": rss_mb(),
                  "max_mb": self.max_mb, "idle_limit_s": self.idle_s} | extra
        write_text(f"{self.base}.json", json.dumps(record))

    def log(self, text: str) -> None:
        with open(f"{self.base}.log", "a", encoding="utf-8") as f:
            f.write(f"{time.strftime('%Y-%m-%dT%H:%M:%S')} {text}\n")

    # -- the listener thread ---------------------------------------------------------

    def listen(self, server: socket.socket) -> None:
        """Answer every connection at once; queue the one command it accepts."""
        while True:
            try:
                conn, _ = server.accept()
            except OSError:  # the socket was closed: replacing or stopping
                return
            with self.lock:  # stopped: it takes no more commands
                answer = self.closing or (b"b" if self.busy or self.stopped.is_set() else b"a")
                self.busy = self.busy or answer == b"a"
            try:
                send(conn, answer)
            except OSError:  # the command gave up waiting
                if answer == b"a":
                    with self.lock:
                        self.busy = False
                conn.close()
                continue
            if answer == b"a":
                self.commands.put(conn)
            else:
                conn.close()

    # -- the main thread -------------------------------------------------------------

    def loop(self, main) -> str:
        """Run the accepted commands until idle, stopped, stale, over the memory
        bound or interrupted: which of these ended it."""
        last = checked = time.monotonic()
        self.state("idle")
        while True:
            try:
                try:
                    conn = self.commands.get(timeout=0.5)
                except queue.Empty:
                    now = time.monotonic()
                    reason = ("stopped" if self.stopped.is_set() else
                              "idle" if now - last > self.idle_s else None)
                    if reason is None and now - checked > STALE_CHECK_S:
                        checked = now
                        reason = "stale" if key(self.env, self.paths) != self.key else None
                    if reason is None:
                        continue
                    with self.lock:  # no command accepted now is left unserved
                        if self.busy:
                            continue
                        self.closing = b"b"
                    return reason
                ended = self.serve_one(conn, main)
                if ended:
                    return ended
                gc.collect()  # the command's cycles, after its status went back
            except KeyboardInterrupt:  # a command that went away as it ended
                return "interrupted"
            last = time.monotonic()

    def serve_one(self, conn: socket.socket, main) -> str | None:
        """Run one command from `conn` and answer its exit status: why this process
        must now be replaced (and answers "w" from then on), or None. An
        interrupted command may have left JAX's caches half written; a process
        above its memory bound keeps it."""
        fds: list[int] = []
        request = error = None
        try:
            conn.settimeout(5.0)  # the request follows at once, or the command went away
            frame = receive(conn, fds)
            conn.settimeout(None)
            if frame is not None:
                request = _request(frame, fds)
        except OSError:
            pass
        except ValueError as err:  # a malformed request: answered, nothing run
            error = str(err)
        if request is None:
            for fd in fds:
                with contextlib.suppress(OSError):
                    os.close(fd)
            with self.lock:
                self.busy = False
            if error is not None:
                self.log(f"refused pid={os.getpid()}: a malformed request: {error}")
                with contextlib.suppress(OSError):
                    send(conn, b"e", f"a malformed request: {error}".encode())
            conn.close()
            return None
        self.state("busy", command=request["argv"])
        started = time.monotonic()
        done = threading.Event()
        done.interrupted = False  # set by `watch`
        done.lock = threading.Lock()  # `watch` interrupts only a command not done
        threading.Thread(target=self.watch, args=(conn, done), daemon=True).start()
        status = _run(main, request, fds, done)
        ended = ("interrupted" if status == 130 or done.interrupted
                 else "memory" if self.over_bound() else None)
        with self.lock:
            self.served += 1
            if ended:
                self.closing = b"w"
        self.state("replacing" if ended else "idle")  # before the status: a command's
        with self.lock:                               # next step sees it served
            self.busy = False
        with contextlib.suppress(OSError):
            send(conn, b"s", json.dumps(status).encode())
        with contextlib.suppress(OSError):
            conn.shutdown(socket.SHUT_RDWR)  # wakes the watch thread
        conn.close()
        self.log(f"served pid={os.getpid()} status={status} "
                 f"seconds={time.monotonic() - started:.2f} rss_mb={rss_mb() or 0:.0f} "
                 f"argv={json.dumps(request['argv'])}")
        return ended

    def over_bound(self) -> bool:
        """Whether the memory held after a command is above the bound, once its
        garbage is collected and freed memory handed back (glibc's malloc_trim)."""
        rss = rss_mb()
        if rss is None or rss <= self.max_mb:
            return False
        gc.collect()
        with contextlib.suppress(OSError, AttributeError):
            import ctypes

            ctypes.CDLL("libc.so.6").malloc_trim(0)
        rss = rss_mb()
        return rss is not None and rss > self.max_mb

    def watch(self, conn: socket.socket, done: threading.Event) -> None:
        """The command went away before its status (Ctrl-C): nothing more reaches its
        streams, its work is interrupted, and if that takes longer than `GRACE_S`
        (XLA does not return to Python), this process ends and a fresh one
        replaces it."""
        with contextlib.suppress(OSError):
            conn.recv(1)
        with done.lock:
            if done.is_set():
                return
            done.interrupted = True
            null = os.open(os.devnull, os.O_RDWR)
            for fd in (0, 1, 2):
                os.dup2(null, fd)
            os.close(null)
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
        if not done.wait(GRACE_S):
            self.log(f"interrupted pid={os.getpid()}: the work did not stop within "
                     f"{GRACE_S} s; replaced")
            self.replace()

    # -- ending ----------------------------------------------------------------------

    def remove_files(self) -> None:
        """Remove this process's socket, process id and state (those still its own)."""
        with contextlib.suppress(OSError, ValueError):
            if int(open(f"{self.base}.pid").read()) != os.getpid():
                return
        for suffix in (".sock", ".pid", ".json"):
            with contextlib.suppress(OSError):
                os.unlink(f"{self.base}{suffix}")

    def replace(self) -> None:
        """End this process at once, a fresh one started in its place with the
        environment this one was started with: its marker first, so that a
        command that comes meanwhile waits for it, then this process's files
        removed, then the new process started. Once: a second caller (the main
        thread and `watch`) waits here for the end of the process."""
        self.replacing.acquire()
        with contextlib.suppress(OSError):
            os.unlink(f"{self.base}.starting")
        # not for code that changed since, nor for a process told to stop
        if key(self.env, self.paths) == self.key and not self.stopped.is_set():
            with contextlib.suppress(OSError):
                spawn(self.base, self.env, before=self.remove_files)
        self.remove_files()
        os._exit(0)


def _request(frame: tuple[bytes, bytes], fds: list[int]) -> dict:
    """The request of a command (`jaxchain._cli.warm.forward`) in `frame`, checked.

    **Raises:** `ValueError` naming what is wrong: not a request ("r"), not three
    file descriptors, not JSON, or a field missing or of the wrong type."""
    kind, payload = frame
    if kind != b"r":
        raise ValueError(f"a frame of kind {kind!r}, not 'r'")
    if len(fds) != 3:
        raise ValueError(f"{len(fds)} file descriptors, not 3 (standard input, output, error)")
    try:
        request = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as err:
        raise ValueError(f"not JSON ({err})") from None
    if not isinstance(request, dict):
        raise ValueError("not a JSON object")
    fields = {"argv": list, "cwd": str, "env": dict, "umask": int}
    for name, kind_ in fields.items():
        if not isinstance(request.get(name), kind_) or isinstance(request[name], bool):
            raise ValueError(f"{name!r} missing or not a {kind_.__name__}")
    if not all(isinstance(a, str) for a in request["argv"]):
        raise ValueError("'argv' holds a value that is not a string")
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in request["env"].items()):
        raise ValueError("'env' holds a name or value that is not a string")
    if not 0 <= request["umask"] <= 0o777:
        raise ValueError(f"'umask' {request['umask']} out of 0 ... 0o777")
    if not isinstance(request.setdefault("argv0", "jaxchain"), str):
        raise ValueError("'argv0' is not a string")
    return request


def _run(main, request: dict, fds: list[int], done: threading.Event) -> int:
    """`main(argv)` with the command's standard streams (`fds`), working directory,
    environment, umask and `sys.argv` (the `history` of its results names the
    command, not this process), all restored after it: its exit status."""
    saved = [os.dup(fd) for fd in (0, 1, 2)]
    saved_env, saved_cwd, saved_argv = dict(os.environ), os.getcwd(), sys.argv
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
        os.close(fd)
    sys.stdout.reconfigure(line_buffering=sys.stdout.isatty())  # as in a process of its own
    umask = os.umask(request["umask"])
    sys.argv = [request["argv0"], *request["argv"]]
    try:
        os.environ.clear()
        os.environ.update(request["env"])
        os.chdir(request["cwd"])
        try:
            with warnings.catch_warnings():  # each command's warnings its own, as shown once
                return main(request["argv"])
        except SystemExit as exit_:  # --help, --version, a usage error of argparse
            return exit_.code if isinstance(exit_.code, int) else int(exit_.code is not None)
        except KeyboardInterrupt:  # interrupted after `main` returned, or before it ran
            return 130
        except BaseException:  # JAXCHAIN_TRACEBACK=1, a working directory gone: as its own
            traceback.print_exc()  # process would show it, and this one goes on
            return 1
    finally:
        while True:  # `watch` interrupts nothing once this is set
            try:
                with done.lock:
                    done.set()
                break
            except KeyboardInterrupt:
                continue
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        for target, fd in enumerate(saved):
            os.dup2(fd, target)
            os.close(fd)
        os.environ.clear()
        os.environ.update(saved_env)
        os.chdir(saved_cwd)
        os.umask(umask)
        sys.argv = saved_argv


def _serve(base: str) -> None:
    """Be the warm process at `<base>.sock`: import what the commands use, listen,
    and run each command as `run_here` would, until idle, stopped, stale or over
    its memory bound (then replaced). Its process id is in `<base>.pid`."""
    warm = _Warm(base)
    if warm.key != os.path.basename(base):  # the code changed since it was started
        with contextlib.suppress(OSError):
            os.unlink(f"{base}.starting")
        return
    write_text(f"{base}.pid", str(os.getpid()))
    with contextlib.suppress(OSError):
        if os.stat(f"{base}.log").st_size > 2**20:  # the log of the last commands only
            os.unlink(f"{base}.log")
    # Stopped (SIGTERM): the loop ends at its next wait. An exception raised by
    # the handler could land in a callback whose exceptions Python ignores.
    signal.signal(signal.SIGTERM, lambda *_: warm.stopped.set())  # the loop closes
    # Ctrl-C in a command reaches the command here as SIGINT (`_Warm.watch`), even
    # where the process that started this one ignored it (a background job).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    warm.state("starting")
    from .common import RESULT_MODULES
    from .main import main
    from .._setup import configure

    configure()
    for name in RESULT_MODULES:  # what writing results imports, once for all commands
        __import__(name)
    gc.freeze()  # what the imports made: never collected
    gc.set_threshold(50_000, 50, 100)  # as `run_here`
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(f"{base}.sock.{os.getpid()}")
    os.replace(f"{base}.sock.{os.getpid()}", f"{base}.sock")  # appears whole, ready
    server.listen(8)
    threading.Thread(target=warm.listen, args=(server,), daemon=True).start()
    with contextlib.suppress(OSError):
        os.unlink(f"{base}.starting")
    warm.log(f"listening pid={os.getpid()} key={warm.key}")
    ended = "stopped"
    try:
        ended = warm.loop(main)
    finally:
        warm.log(f"ended pid={os.getpid()}: {ended}")
        with warm.lock:
            warm.closing = warm.closing or b"b"
        if ended in ("memory", "interrupted") and not warm.stopped.is_set():
            warm.replace()  # a fresh process in its place, unless it was told to stop
        with contextlib.suppress(OSError):
            server.shutdown(socket.SHUT_RDWR)  # wakes the listener thread
        server.close()
        warm.remove_files()
    os._exit(0)  # no teardown of the JAX runtime: nothing is left to write


if __name__ == "__main__":
    _serve(sys.argv[1])
