"""The command line's cache runs no one else's code (issue 81, item 1). The process
loads what the cache holds (JAX's compiled executables, the kept traced programs of
`kept_program`), so: nothing kept there runs code as it is read (a planted pickle
stays inert), and a cache folder that another user owns or can write is refused,
with exit status 2 and one line naming the folder, as ssh refuses a loose ~/.ssh;
a folder of root's that the user cannot write is read, never written."""

import collections
import contextlib
import io
import json
import os
import pickle
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._cli.main import compilation_cache
from jaxchain._engine.programs import keep_programs, kept_program

SMALL = ["--n-osc", "3", "--t-end", "400", "--transient", "200"]
ROOT = os.getuid() == 0
OTHER_UID = 12345


class _Planted:
    """What another user plants: a pickle whose loading creates `marker`."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return open, (str(self.marker), "w")


def _plant(folder: Path, marker: Path) -> int:
    """Replace every `.tree` file of `folder` with the planted pickle; how many."""
    trees = sorted(folder.glob("*.tree"))
    for tree in trees:
        tree.write_bytes(pickle.dumps(_Planted(marker)))
    return len(trees)


@eqx.filter_jit
def _observed(x, scale):
    return {"sum": jnp.sum(x) * scale, "parts": (x[0], x[1:] * scale)}


@pytest.fixture
def cache_settings():
    """Restore what the command line's cache set up (JAX's settings, the kept
    programs' folder) after a test that points it elsewhere. JAX opens its cache
    once, at a process's first compilation: done here, so that it stays the tests'
    own (conftest.py), not the test's folder."""
    jax.jit(lambda x: x * 3.0 + 1.0)(1.0).block_until_ready()
    saved = (jax.config.jax_compilation_cache_dir,
             jax.config.jax_persistent_cache_min_compile_time_secs)
    yield
    keep_programs(None)
    jax.config.update("jax_compilation_cache_dir", saved[0])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", saved[1])


def test_a_planted_program_file_never_runs(tmp_path, cache_settings):
    """Library level: the kept files of a program are replaced by a pickle whose
    loading would create a marker file; a later process (the folder read again)
    runs nothing of it, and the program still computes `fn`'s values."""
    folder, marker = tmp_path / "traced", tmp_path / "planted-code-ran"
    x = jnp.arange(4.0)
    keep_programs(folder)
    kept_program(_observed, x, 2.0)
    assert _plant(folder, marker) == 1
    keep_programs(None)  # as a later process reads the folder
    keep_programs(folder)
    program = kept_program(_observed, x, 2.0)
    assert not marker.exists()
    got = program(x + 1.0, 2.0)
    expected = _observed(x + 1.0, 2.0)
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(expected)
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(got),
                                                    jax.tree_util.tree_leaves(expected)))
    # the planted file was replaced by data: JSON, not a pickle
    tree = next(folder.glob("*.tree"))
    assert json.loads(tree.read_text())["type"] == "dict"


@pytest.mark.study
def test_the_command_line_runs_no_planted_file(tmp_path, monkeypatch, cache_settings):
    """The audit's case: `jaxchain localized` with its cache in a folder whose kept
    programs' `.tree` files were replaced by a pickle that creates a marker. The
    next command runs none of it, exits 0, and gives the numbers of the first."""
    monkeypatch.setenv("JAXCHAIN_CACHE_DIR", str(tmp_path / "xla"))
    marker = tmp_path / "planted-code-ran"
    docs = []
    for run in ("first", "after the plant"):
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            code = jc.main(["localized", *SMALL, "--json", "--out", str(tmp_path / run)])
        assert not marker.exists()
        assert code == 0
        docs.append(json.loads(printed.getvalue())["runs"][0])
        if run == "first":
            assert _plant(tmp_path / "xla" / "traced", marker) == 2
            keep_programs(None)  # as a later process reads the folder
    for key in ("n_halc", "energy", "amplitudes", "status"):
        assert docs[1][key] == docs[0][key], key


def _loose(tmp_path: Path, case: str) -> tuple[Path, Path]:
    """A cache folder of the kind `case` (one that another user can change), and
    the folder or file that makes it loose."""
    cache = tmp_path / "cache" / "xla"
    (cache / "traced").mkdir(parents=True, mode=0o700)
    (tmp_path / "cache").chmod(0o700)
    cache.chmod(0o700)
    if case == "world-writable":
        cache.chmod(0o777)
        return cache, cache
    if case == "group-writable":
        cache.chmod(0o770)
        return cache, cache
    if case == "traced writable":
        (cache / "traced").chmod(0o777)
        return cache, cache / "traced"
    if case == "folder above writable":
        (tmp_path / "cache").chmod(0o777)  # not sticky: another user renames ours away
        return cache, tmp_path / "cache"
    if case == "file writable, folder open":
        cache.chmod(0o755)
        entry = cache / "jit_run-cache"
        entry.write_bytes(b"compiled")
        entry.chmod(0o666)
        return cache, entry
    if case == "owned by another user":
        os.chown(cache, OTHER_UID, -1)
        return cache, cache
    if case == "file of another user":
        entry = cache / "jit_run-cache"
        entry.write_bytes(b"compiled")
        os.chown(entry, OTHER_UID, -1)
        return cache, entry
    raise AssertionError(case)


@pytest.mark.parametrize("case", [
    "world-writable", "group-writable", "traced writable", "folder above writable",
    "file writable, folder open",
    pytest.param("owned by another user", marks=pytest.mark.skipif(
        not ROOT, reason="giving a folder to another user needs root")),
    pytest.param("file of another user", marks=pytest.mark.skipif(
        not ROOT, reason="giving a file to another user needs root")),
])
def test_a_loose_cache_folder_is_refused(tmp_path, monkeypatch, capsys, cache_settings,
                                         case):
    """A cache folder that another user owns or can write (itself, its `traced`
    folder, a folder above it, a file in it) is refused before anything runs: exit
    status 2, one line naming the cache folder, what is loose and the fix; no
    output folder is made."""
    cache, loose = _loose(tmp_path, case)
    monkeypatch.setenv("JAXCHAIN_CACHE_DIR", str(cache))
    assert jc.main(["localized", *SMALL, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"jaxchain localized: error: refused the cache folder {cache}")
    assert str(loose) in err and "JAXCHAIN_CACHE_DIR" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not ROOT, reason="a folder of root's that the user cannot write "
                                     "needs root to make")
def test_a_read_only_cache_of_root_is_read_never_written(tmp_path, monkeypatch,
                                                         cache_settings):
    """A cache shared on a cluster: root's folder, mode 0o755, that this user (here
    uid 12345) cannot write. It is accepted: the kept programs are read from it,
    a program traced here is not written into it, and JAX writes no executable
    (its minimum compile time infinite); a folder of another user is refused."""
    cache = tmp_path / "xla"
    traced = cache / "traced"
    x = jnp.arange(4.0)
    keep_programs(traced)  # root fills the cache
    kept_program(_observed, x, 2.0)
    keep_programs(None)
    for folder in (tmp_path, cache, traced):
        folder.chmod(0o755)
    kept = sorted(traced.iterdir())
    monkeypatch.setattr(os, "getuid", lambda: OTHER_UID)
    monkeypatch.setenv("JAXCHAIN_CACHE_DIR", str(cache))
    assert compilation_cache() == str(cache)
    assert jax.config.jax_persistent_cache_min_compile_time_secs == float("inf")
    got = kept_program(_observed, x, 2.0)(x, 2.0)
    assert np.array_equal(got["sum"], _observed(x, 2.0)["sum"])
    other = jnp.arange(5.0)  # another shape: traced here, not written there
    assert np.array_equal(kept_program(_observed, other, 2.0)(other, 2.0)["sum"],
                          _observed(other, 2.0)["sum"])
    assert sorted(traced.iterdir()) == kept
    os.chown(cache, OTHER_UID + 1, -1)  # another user's folder, read only or not
    with pytest.raises(jc.ValidationError, match="owned by another user"):
        keep_programs(traced)


def test_a_tree_file_names_only_data_and_imported_modules():
    """The `.tree` file is data: jaxchain's outputs (`Observables`, the observers'
    dicts, tuples) come back as the same tree structure; a file that names
    anything but a builtin container or an `eqx.Module` subclass of a module
    already imported is refused, and reading it imports nothing."""
    from jaxchain._engine import tree_json
    from jaxchain._engine.observables import Observables

    fields = [f.name for f in Observables.__dataclass_fields__.values()]
    outputs = [Observables(**dict.fromkeys(fields, jnp.zeros(2))),
               {"b": (jnp.zeros(1), None, [jnp.zeros(2)]), "a": jnp.zeros(3)},
               (jnp.zeros(2), jnp.zeros(2))]
    for out in outputs:
        treedef = jax.tree_util.tree_structure(out)
        data = json.loads(json.dumps(tree_json.to_json(treedef)))
        assert tree_json.from_json(data) == treedef
    leaf = {"type": "tuple", "aux": None, "children": ["*"]}
    for name in ("os:system", "subprocess:Popen", "builtins:eval", "this:x",
                 "jaxchain._engine.programs:keep_programs"):
        with pytest.raises(ValueError):
            tree_json.from_json(dict(leaf, type=name))
    assert "this" not in sys.modules  # `import this` prints the Zen
    # a node, or a static field, of no JSON form: the program is not kept
    for out in (collections.OrderedDict(a=jnp.zeros(1)), _WithStatic(jnp.zeros(1), print)):
        with pytest.raises(TypeError):
            tree_json.to_json(jax.tree_util.tree_structure(out))


class _WithStatic(eqx.Module):
    x: jax.Array
    fn: object = eqx.field(static=True)


def test_a_run_differentiated_in_forward_mode_is_traced_not_read_from_the_cache(
        tmp_path, cache_settings):
    """Once a command has kept programs in this process (`keep_programs`), a run
    under `jax.jvp` still differentiates: the kept programs are exported ones, which
    forward mode cannot differentiate, so a traced argument skips them. The
    derivative equals the one without kept programs (the same program, bit for
    bit)."""
    def final_velocity(v_d):  # the exact engine, whose default adjoint is forward
        params = jc.ChainParams(n_osc=1, v_d=v_d)
        obs = jc.simulate(params, jnp.array([[0.5], [0.0]]), throw=False,
                          engine=jc.Exact(jc.NonsmoothOptions(t_end=20.0, transient=10.0)))
        return obs.amplitudes[0]

    plain = jax.jvp(final_velocity, (1.5,), (1.0,))
    keep_programs(tmp_path / "kept")
    try:
        kept = jax.jvp(final_velocity, (1.5,), (1.0,))
    finally:
        keep_programs(None)
    assert np.isfinite(float(plain[1])) and float(kept[1]) == float(plain[1])
