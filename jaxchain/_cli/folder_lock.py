"""One command at a time per output folder.

A command holds the lock of its --out folder from the moment it claims its results
(`Outputs`) until it ends (`release_folder`, from `record_outputs` at the end of
`main`, whether it ran, failed or was refused): a second command that names the
same folder is refused in one line naming the first (exit status 2), or waits for
it with --wait. The lock is the operating system's (`filelock.FileLock`: flock on
Unix), held by the process that runs the command (its own, or the warm process
that runs it): the kernel releases it when that process ends, even by kill -9, so
a killed command never blocks the next one. Beside it a small file names the
holder (process id, host, command, start time), for the refusal."""

import contextlib
import json
import os
import shlex
import socket
import sys
import time
from pathlib import Path

from .parser import UsageError

#: The lock file in an output folder (left in place: waiters share its inode).
LOCK = ".jaxchain-lock"

#: The file beside it that names the holder, removed when the lock is released.
HOLDER = ".jaxchain-lock.json"

#: How long a refused command waits for a new holder to name itself.
_NAMING_S = 1.0

#: The folders whose lock this process holds: canonical path -> [lock, count] (a
#: command may claim one folder more than once).
_HELD: dict[str, list] = {}


def lock_folder(folder: Path, command: str, *, wait: bool = False) -> None:
    """Take the lock of the output folder `folder` (which exists) for this
    process, until `release_folder`; again in the same process only counts.

    **Arguments:**

    - `folder`: the --out folder.
    - `command`: the command line, recorded for a refused command to name.
    - `wait`: wait for the holder to end instead of refusing.

    **Raises:**

    `UsageError` naming --out and the holder (its process id and command) when
    another process holds the lock and `wait` is False, or when the folder
    cannot be locked.
    """
    import filelock

    key = os.path.realpath(folder)
    if key in _HELD:
        _HELD[key][1] += 1
        return
    lock = filelock.FileLock(os.path.join(key, LOCK), thread_local=False)
    try:
        try:
            lock.acquire(timeout=0)
        except filelock.Timeout:
            holder = _holder(Path(key))
            if not wait:
                raise UsageError(f"--out {folder}: in use by {holder}; give --wait to "
                                 f"wait for it, or choose another --out") from None
            print(f"jaxchain: --out {folder}: waiting for {holder} to end", file=sys.stderr)
            lock.acquire(timeout=-1, poll_interval=0.1)
    except OSError as err:
        raise UsageError(f"--out {folder}: cannot lock it ({err.strerror or err})") from None
    _HELD[key] = [lock, 1]
    record = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
              "since": time.strftime("%Y-%m-%d %H:%M:%S")}
    partial = os.path.join(key, f"{HOLDER}.{os.getpid()}.partial")
    with contextlib.suppress(OSError):
        with open(partial, "w") as f:
            json.dump(record, f)
        os.replace(partial, os.path.join(key, HOLDER))


def release_folder(folder: Path) -> None:
    """Release this process's lock of `folder` (its last claim), removing the file
    that names the holder first. Nothing when this process does not hold it."""
    key = os.path.realpath(folder)
    held = _HELD.get(key)
    if held is None:
        return
    held[1] -= 1
    if held[1] > 0:
        return
    del _HELD[key]
    with contextlib.suppress(OSError):
        os.unlink(os.path.join(key, HOLDER))
    held[0].release()


def command_line(command: str | None, folder: Path) -> str:
    """The command line of this process's command, as the user typed it where this
    process was started by it (the `jaxchain` script, `python -m jaxchain`);
    otherwise the command's name and its folder."""
    argv = sys.argv or [""]
    if Path(argv[0]).name in ("jaxchain", "__main__.py") and command in argv[1:]:
        return shlex.join(["jaxchain", *argv[1:]])
    return f"jaxchain {command} --out {folder}"


def _holder(folder: Path) -> str:
    """The holder of `folder`'s lock in words: "pid N (its command, since T)". A
    holder that has just taken the lock may not have named itself yet, and the
    file of a killed one may remain: a record is believed when its process is
    alive (or on another host); otherwise "another jaxchain command"."""
    deadline = time.monotonic() + _NAMING_S
    while True:
        with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
            record = json.loads((folder / HOLDER).read_text())
            pid = int(record["pid"])
            elsewhere = record.get("host") != socket.gethostname()
            if elsewhere or _alive(pid):
                host = f" on {record['host']}" if elsewhere else ""
                return (f"pid {pid}{host} ({record['command']}, since "
                        f"{record['since']})")
        if time.monotonic() > deadline:
            return "another jaxchain command"
        time.sleep(0.05)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True
