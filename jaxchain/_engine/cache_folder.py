"""Who may write a cache folder whose files this process loads: JAX's persistent
compilation cache holds compiled machine code that the process runs, and the kept
traced programs (`programs.keep_programs`) become that code. As ssh refuses a loose
`~/.ssh`, a folder that another user owns or can write is refused: what they put
there would run as the user of this process."""

import os
import stat
from pathlib import Path

from .._errors import ValidationError

#: How to get out of a refusal, the end of its one line.
FIX = ("use a folder that only you can write: remove it, or set JAXCHAIN_CACHE_DIR to "
       "another folder (an empty value turns the cache off)")


def check_cache_folder(folder: Path | str) -> bool:
    """Check that only this user (or root) can change what `folder` holds; create it
    (mode 0o700) where it is missing.

    Refused: a folder, or a folder above it, owned by another user than this one
    and root; a folder, or one above it, that its group or other users can write
    (a folder above it may be a sticky one such as /tmp, in which no one renames
    another's entries); an entry of the folder owned by another user, or one that
    others can write while they may enter the folder. A folder of root's that this
    user cannot write (a cache shared on a cluster, filled by its administrator) is
    accepted for reading.

    **Arguments:**

    - `folder`: the cache folder.

    **Returns:**

    Whether this user may write to `folder`; False for a folder of root's that only
    root writes, which is then read only.

    **Raises:**

    `ValidationError` naming the loose folder or file and the fix (`FIX`);
    `OSError` where `folder` is missing and cannot be created.
    """
    path = Path(os.path.realpath(folder))
    for above in reversed(path.parents):  # from the root down, before creating anything
        if above.exists():
            _check(path, above, sticky_ok=True)
    if not path.is_dir():
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
    info = _check(path, path, sticky_ok=False)
    others_enter = info.st_mode & (stat.S_IXGRP | stat.S_IXOTH)
    with os.scandir(path) as entries:
        for entry in entries:
            entry_info = entry.stat(follow_symlinks=False)
            if entry_info.st_uid not in (os.getuid(), 0):
                _refuse(path, entry.path, f"is owned by another user (uid {entry_info.st_uid})")
            if others_enter and entry_info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
                _refuse(path, entry.path, "can be written by other users "
                                                f"(mode {stat.filemode(entry_info.st_mode)})")
    return info.st_uid == os.getuid() and bool(info.st_mode & stat.S_IWUSR)


def _check(folder: Path, path: Path, sticky_ok: bool) -> os.stat_result:
    """The status of `path`, the cache `folder` or a folder above it, which only
    this user or root may write."""
    info = path.stat()
    if info.st_uid not in (os.getuid(), 0):
        _refuse(folder, path, f"is owned by another user (uid {info.st_uid})")
    if info.st_mode & (stat.S_IWGRP | stat.S_IWOTH) and not (
            sticky_ok and info.st_mode & stat.S_ISVTX):
        _refuse(folder, path, "can be written by other users "
                              f"(mode {stat.filemode(info.st_mode)})")
    return info


def _refuse(folder: Path, path, why: str):
    where = "it" if Path(path) == folder else path
    raise ValidationError(f"refused the cache folder {folder}: {where} {why}, and what "
                          f"the cache holds runs as you; {FIX}")
