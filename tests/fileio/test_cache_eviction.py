"""The caches' size cap: least recently used entries removed first, and nothing but entries, ever."""

import os
import re

import pytest

from modelgen.errors import ModelError
from modelgen.fileio.cache_eviction import CAP_ENV, DEFAULT_CAP_MB, KINDS, cap_bytes, cached_entries, keep_within_cap

from modelgen.codegen.build import ENTRY_MAGIC as LIBRARY_MAGIC
from modelgen.simulation.trajectory_cache import ENTRY_MAGIC as TRAJECTORY_MAGIC


def entry(root, folder, name, magic, size, used_s):
    """A file at ``root/folder/name`` of ``size`` bytes starting with ``magic``, last used at ``used_s`` (epoch s)."""
    path = root / folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(magic + b"x" * (size - len(magic)))
    os.utime(path, (used_s, used_s))
    return path


def key(digit: str) -> str:
    return digit * 64


def test_the_least_recently_used_entries_of_every_folder_go_first_until_the_cache_fits(tmp_path):
    oldest = entry(tmp_path, "trajectories", f"{key('a')}.trajectory", TRAJECTORY_MAGIC, 4000, 1_000)
    older = entry(tmp_path, "libraries", f"{key('b')}.lib", LIBRARY_MAGIC, 3000, 2_000)
    newer = entry(tmp_path, "generated", f"{key('c')}.1.lib", LIBRARY_MAGIC, 2000, 3_000)
    newest = entry(tmp_path, "libraries", f"{key('d')}.lib", LIBRARY_MAGIC, 1000, 4_000)
    assert [e.path for e in cached_entries(tmp_path)] == [oldest, older, newer, newest]
    removed = keep_within_cap(tmp_path, cap=3500)
    assert removed == [oldest, older]
    assert [e.path for e in cached_entries(tmp_path)] == [newer, newest]
    assert keep_within_cap(tmp_path, cap=3500) == []  # within the cap: nothing more


def test_the_entry_just_stored_stays_even_if_it_alone_is_over_the_cap(tmp_path):
    kept = entry(tmp_path, "trajectories", f"{key('a')}.trajectory", TRAJECTORY_MAGIC, 5000, 1_000)
    other = entry(tmp_path, "libraries", f"{key('b')}.lib", LIBRARY_MAGIC, 100, 2_000)
    assert keep_within_cap(tmp_path, stored=kept, cap=1000) == [other]
    assert kept.exists()


def test_files_that_are_not_entries_are_neither_counted_nor_removed(tmp_path):
    not_ours = [
        entry(tmp_path, "libraries", f"{key('a')}.lib", b"something else entirely", 9000, 1),  # an entry's name only
        entry(tmp_path, "libraries", "mine.lib", LIBRARY_MAGIC, 9000, 1),  # the magic, not an entry's name
        entry(tmp_path, "libraries", f".{key('b')[:16]}-x.tmp", LIBRARY_MAGIC, 9000, 1),  # a temporary being written
        entry(tmp_path, "libraries", f"{key('c')}.trajectory", TRAJECTORY_MAGIC, 9000, 1),  # the wrong folder's kind
        entry(tmp_path, "elsewhere", f"{key('d')}.lib", LIBRARY_MAGIC, 9000, 1),  # not a cache folder
        entry(tmp_path, ".", f"{key('e')}.lib", LIBRARY_MAGIC, 9000, 1),  # the cache root itself
    ]
    target = entry(tmp_path, "outside", "target.lib", LIBRARY_MAGIC, 9000, 1)
    link = tmp_path / "libraries" / f"{key('f')}.lib"
    link.symlink_to(target)  # a link at an entry's name, to a file of the magic
    (tmp_path / "trajectories" / f"{key('0')}.trajectory").mkdir(parents=True)  # a folder at an entry's name
    ours = entry(tmp_path, "libraries", f"{key('9')}.lib", LIBRARY_MAGIC, 100, 2)
    assert [e.path for e in cached_entries(tmp_path)] == [ours]
    assert keep_within_cap(tmp_path, cap=1) == [ours]
    assert all(path.exists() for path in not_ours) and target.exists() and link.is_symlink()
    assert (tmp_path / "trajectories" / f"{key('0')}.trajectory").is_dir()


def test_the_cap_comes_from_the_environment_zero_for_none_and_a_bad_value_is_refused_by_name(tmp_path, monkeypatch):
    monkeypatch.delenv(CAP_ENV, raising=False)
    assert cap_bytes() == DEFAULT_CAP_MB * 2**20
    monkeypatch.setenv(CAP_ENV, "3")
    assert cap_bytes() == 3 * 2**20
    big = entry(tmp_path, "libraries", f"{key('a')}.lib", LIBRARY_MAGIC, 4 * 2**20, 1)
    assert keep_within_cap(tmp_path) == [big]
    monkeypatch.setenv(CAP_ENV, "0")
    assert cap_bytes() is None
    kept = entry(tmp_path, "libraries", f"{key('b')}.lib", LIBRARY_MAGIC, 4 * 2**20, 1)
    assert keep_within_cap(tmp_path) == [] and kept.exists()
    for bad in ("-1", "2.5", "lots", "+5", "1_000", "-0", "\u0663", "1e3"):
        monkeypatch.setenv(CAP_ENV, bad)
        with pytest.raises(ModelError, match=re.escape(f"$MODELGEN_CACHE_MAX_MB={bad!r}") + ".*whole number of megabytes"):
            cap_bytes()


def test_the_kinds_are_the_caches_own_folders_and_magic_lines(tmp_path, monkeypatch):
    from modelgen.codegen import build
    from modelgen.simulation import filters, trajectory_cache

    monkeypatch.setenv(build.CACHE_ENV, str(tmp_path))
    folders = {kind.folder: kind for kind in KINDS}
    assert build.library_cache_folder() == tmp_path / "libraries"
    assert filters._generated_files_folder() == tmp_path / "generated"
    assert trajectory_cache.trajectory_cache_folder() == tmp_path / "trajectories"
    assert build.ENTRY_MAGIC.startswith(folders["libraries"].magic) and build.ENTRY_MAGIC.startswith(folders["generated"].magic)
    assert trajectory_cache.ENTRY_MAGIC.startswith(folders["trajectories"].magic)
    stored = build.store_library(build.library_cache_folder(), key("7"), b"a library")
    assert [e.path for e in cached_entries(tmp_path)] == [stored]


def test_a_library_taken_from_the_cache_is_marked_used_and_outlives_a_newer_unused_one(tmp_path, monkeypatch):
    from modelgen.codegen import build

    monkeypatch.setenv(CAP_ENV, "1")  # 1 MB: room for two 400 kB libraries, not three
    folder = tmp_path / "libraries"
    first = build.store_library(folder, key("1"), b"1" * 400_000)
    second = build.store_library(folder, key("2"), b"2" * 400_000)
    os.utime(first, (1_000, 1_000))
    os.utime(second, (2_000, 2_000))
    assert build.cached_library(folder, key("1")) == b"1" * 400_000  # used now: the most recent
    third = build.store_library(folder, key("3"), b"3" * 400_000)
    assert first.exists() and third.exists() and not second.exists()
    assert build.cached_library(folder, key("2")) is None  # removed: a miss, compiled again by the caller


def test_a_compiled_navigators_entry_counts_toward_the_cap_and_goes_when_least_recently_used(tmp_path, monkeypatch):
    """The replay's navigators are compile-cache entries named navigator-<key> (issue 28: they sat outside the cap)."""
    from modelgen.codegen import build

    monkeypatch.setenv(CAP_ENV, "1")  # 1 MB: room for two 400 kB entries, not three
    folder = tmp_path / "libraries"
    navigator = build.store_library(folder, "navigator-" + key("1"), b"n" * 400_000)
    os.utime(navigator, (1_000, 1_000))
    library = build.store_library(folder, key("2"), b"2" * 400_000)
    assert [e.path for e in cached_entries(tmp_path)] == [navigator, library]
    build.store_library(folder, key("3"), b"3" * 400_000)
    assert not navigator.exists() and library.exists()


def test_a_new_trajectory_entry_removes_the_least_recently_used_one_to_fit(tmp_path, monkeypatch):
    from modelgen.codegen.build import CACHE_ENV
    from modelgen.simulation.scenario import load_profile
    from modelgen.simulation.trajectory_cache import cached_trajectory, trajectory_cache_folder

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    path = load_profile("profile_000").path.truncated(60.0)  # a minute of the paper's flight: 0.3 MB at 100 Hz
    cached_trajectory(path, 100.0, 1.0)
    (first,) = trajectory_cache_folder().iterdir()
    os.utime(first, (1_000, 1_000))
    monkeypatch.setenv(CAP_ENV, "1")  # 1 MB: not room for both
    again = cached_trajectory(path, 300.0, 1.0)  # another entry (0.9 MB): kept, the older one removed
    assert not first.exists() and len(list(trajectory_cache_folder().iterdir())) == 1
    assert again.n_samples == 18000


def test_a_bad_cap_is_refused_when_the_cache_is_looked_up_before_any_work(monkeypatch):
    """The cap is read with the cache's folder (before a compile or a trajectory is made), not only once an entry is stored."""
    from modelgen.codegen.build import library_cache_folder
    from modelgen.simulation.trajectory_cache import trajectory_cache_folder

    monkeypatch.setenv(CAP_ENV, "lots")
    for folder in (library_cache_folder, trajectory_cache_folder):
        with pytest.raises(ModelError, match=r"\$MODELGEN_CACHE_MAX_MB='lots'"):
            folder()
