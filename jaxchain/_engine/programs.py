"""Traced programs kept on disk beside JAX's compiled ones, so that a warm start does
not trace diffrax's loop again (`jax.export`). What is kept is data: the program
serialised by `jax.export` and the tree structure of its output as JSON
(`tree_json`); nothing read back runs code of the file's own. The folder is checked
first: only this user (or root) may write it (`check_cache_folder`)."""

import contextlib
import functools
import hashlib
import importlib.metadata
import json
import os
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax

from . import tree_json
from .cache_folder import check_cache_folder
from .hashes import canonical
from .._setup import source_identity

#: The packages whose code is part of a traced program, besides jaxchain's own.
PACKAGES = ("jax", "jaxlib", "diffrax", "equinox", "lineax", "optimistix")


@functools.cache
def code_identity() -> dict:
    """The identity of jaxchain's source files (`source_identity`) and the versions
    of `PACKAGES`: a kept program is reused only by the code that traced it."""
    return {"jaxchain": source_identity()} | {
        name: importlib.metadata.version(name) for name in PACKAGES}


_folder: list[Path | None] = [None]
_writable = [False]  # whether this user may write `_folder` (`check_cache_folder`)

#: The kept programs loaded by this process, by folder and key: a second call (the
#: next batch of a sweep) runs the program compiled for the first.
_loaded: dict[tuple[Path, str], Callable | None] = {}


def keep_programs(folder: Path | str | None) -> None:
    """Keep traced programs in `folder` from now on (None: stop). The command line
    keeps them in the folder `traced` of its persistent compilation cache
    (`jaxchain._cli.main.compilation_cache`); the library keeps none unless asked,
    as the key names a user's own friction law or observer by its class, not by its
    code. Another folder (or None) forgets the programs this process loaded: the
    next call of `kept_program` reads its program from the folder again; the same
    folder keeps them (the command line's warm process runs many commands).

    The folder is created (mode 0o700) where it is missing; where it cannot be
    (a read-only cache without it), no program is kept. A folder of root's that
    this user cannot write is read only: programs are read from it, and those
    traced here are not written.

    **Raises:**

    `ValidationError` for a folder that another user owns or can write
    (`check_cache_folder`).
    """
    writable = False
    if folder is not None:
        try:
            writable = check_cache_folder(folder)
            folder = Path(folder)
        except OSError:
            folder = None
    if folder != _folder[0]:
        _loaded.clear()
    _folder[0], _writable[0] = folder, writable


def program_folder() -> Path | None:
    """Where traced programs are kept (`keep_programs`), or None."""
    return _folder[0]


def _program_key(fn: Callable, static, treedef, leaves) -> str:
    """The key of the program of `fn` for arguments with this static part (every
    value that is not an array), this tree of arrays and these shapes and dtypes,
    on this backend, with this code (`code_identity`) and these XLA flags."""
    data = {"function": f"{fn.__module__}.{fn.__qualname__}", "static": canonical(static),
            "tree": str(treedef), "arrays": [f"{x.dtype}{list(x.shape)}" for x in leaves],
            "backend": jax.default_backend(), "x64": bool(jax.config.jax_enable_x64),
            "xla_flags": os.environ.get("XLA_FLAGS", ""), "code": code_identity()}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def _write(path: Path, data: bytes) -> None:
    """Write atomically: another process never reads half a file."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def kept_program(fn: Callable, *example) -> Callable | None:
    """`fn` as a program traced once and kept on disk: a function of arguments like
    `example` (the same static values, the same tree, shapes and dtypes of arrays)
    that calls the exported program of `fn` (`jax.export`) under `jax.jit`, so that
    only its compilation remains, which the persistent cache holds too.

    The first call for a key traces `fn` and writes `<key>.jaxexport` (the
    serialised program) and `<key>.tree` (the tree structure of its output as
    JSON, `tree_json`) in `program_folder()`; later processes read them back. A
    program is never reused across other settings, code or package versions
    (`_program_key`); files that do not fit the key's arrays are traced again.

    **Returns:**

    The function, or None when no folder is set (the cache is off), or when `example`
    holds a value that cannot be keyed (`canonical` raises `TypeError`), a
    program that cannot be exported or an output whose tree has no JSON form
    (`tree_json.to_json`): then call `fn` itself.
    """
    folder = program_folder()
    if folder is None:
        return None
    dynamic, static = eqx.partition(example, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    try:
        key = _program_key(fn, static, treedef, leaves)
    except TypeError:
        return None
    if (folder, key) not in _loaded:
        _loaded[folder, key] = _load(fn, folder, key, static, treedef, leaves)
    return _loaded[folder, key]


def _load(fn, folder, key, static, treedef, leaves):
    """The kept program `key` of `fn`, read from `folder` or traced and written
    there; None when it cannot be exported (`kept_program`)."""
    program, tree = folder / f"{key}.jaxexport", folder / f"{key}.tree"
    try:
        exported = jax.export.deserialize(bytearray(program.read_bytes()))
        out_tree = tree_json.from_json(json.loads(tree.read_bytes()))
        if (out_tree.num_leaves != len(exported.out_avals)
                or [(a.shape, a.dtype) for a in exported.in_avals]
                != [(x.shape, x.dtype) for x in leaves]):
            raise ValueError("the files do not fit the key's arrays")
    except Exception:  # missing, partial, unreadable or not this key's: trace again
        exported, out_tree = _export(fn, static, treedef, leaves)
        if exported is None:
            return None
        if _writable[0]:  # else a read-only cache: the program serves this process
            with contextlib.suppress(OSError):  # a full disk: the same
                _write(tree, json.dumps(tree_json.to_json(out_tree)).encode())
                _write(program, exported.serialize())
    call = jax.jit(exported.call)

    def run(*args):
        return jax.tree_util.tree_unflatten(
            out_tree, call(*jax.tree_util.tree_leaves(eqx.filter(args, eqx.is_array))))

    return run


@functools.cache
def _jitted(fn: Callable) -> Callable:
    return eqx.filter_jit(fn)


def compiled(fn: Callable, *args):
    """`fn(*args)` run as one compiled program: its kept program (`kept_program`)
    where programs are kept, so that a warm start neither traces nor compiles it,
    else `eqx.filter_jit(fn)`. For the small programs that prepare a run (the
    initial states of the lanes, their steady sliding): called op by op, each of
    their operations is compiled on its own, 72 programs and about 2 s for the
    initial states of a small ensemble (`benchmarks/fixed_cost.py`).

    **Arguments:**

    - `fn`: a function defined at a module's top level (its name is part of the
        key), of arrays and static values (`eqx.filter_jit`).
    - `args`: its arguments.

    **Returns:**

    What `fn(*args)` returns, its arrays as JAX arrays.

    **Raises:**

    What `fn` raises while it is traced (for example a `ValidationError` of a
    shape), as `fn(*args)` would.
    """
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
        # under a transformation (jax.jvp, jax.vmap, ...): a kept program is an
        # exported one, which forward mode cannot differentiate; trace it here
        return _jitted(fn)(*args)
    program = kept_program(fn, *args)
    return (program or _jitted(fn))(*args)


def _export(fn, static, treedef, leaves):
    """The exported program of `fn` over the arrays `leaves`, and the tree structure
    of its output. (None, None) when it cannot be exported or its output's tree
    has no JSON form (`tree_json.to_json`)."""
    trees = []

    def flat(*arrays):
        out = fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, arrays), static))
        leaves_out, out_tree = jax.tree_util.tree_flatten(out)
        trees.append(out_tree)
        return leaves_out

    shapes = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
    try:
        exported = jax.export.export(jax.jit(flat))(*shapes)
        tree_json.to_json(trees[0])
    except Exception:
        return None, None
    return exported, trees[0]
