"""The compile cache of modelgen.codegen.build: a hit skips the compiler, any change misses, builders may race.

The compiler is a script that logs each compile (``-shared`` in its
arguments) and then runs the real one, so a test counts compiler runs.  Every
test has its own cache folder ($MODELGEN_CACHE_DIR), never the user's.
"""

from __future__ import annotations

import ctypes
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from modelgen.codegen.build import CACHE_ENV, compile_shared_library, library_cache_folder
from tests.codegen.compile_cache_support import counting_compiler

SOURCE = "int answer(void);\nint answer(void) { return %d; }\n"


@pytest.fixture
def counted_compiler(tmp_path, monkeypatch):
    """CC counts its compiles (tests.codegen.compile_cache_support); the cache is a folder of this test."""
    script, compiles = counting_compiler(tmp_path)
    monkeypatch.setenv("CC", str(script))
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    return compiles


def _source(folder: Path, value: int = 42, header: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "answer.h").write_text(header or "/* answer */\n")
    path = folder / "answer.c"
    path.write_text(SOURCE % value)
    return path


def _answer(library: Path) -> int:
    lib = ctypes.CDLL(str(library))
    lib.answer.restype = ctypes.c_int
    return lib.answer()


@pytest.mark.compile
def test_a_cache_hit_gives_the_same_library_without_running_the_compiler(tmp_path, counted_compiler):
    first = compile_shared_library([_source(tmp_path / "a")], tmp_path / "a" / "liba.so", cache=True)
    assert counted_compiler() == 1
    again = compile_shared_library([_source(tmp_path / "b")], tmp_path / "b" / "libb.so", cache=True)
    assert counted_compiler() == 1  # the same source, flags and compiler: taken from the cache
    assert again.read_bytes() == first.read_bytes() and _answer(again) == 42
    assert [p.suffix for p in library_cache_folder().iterdir()] == [".lib"]  # one entry, no temporary file left


@pytest.mark.compile
def test_other_flags_other_source_or_another_header_miss_the_cache(tmp_path, counted_compiler):
    compile_shared_library([_source(tmp_path / "a")], tmp_path / "a" / "lib.so", cache=True)
    compile_shared_library([_source(tmp_path / "b")], tmp_path / "b" / "lib.so", ("-O1",), cache=True)
    assert counted_compiler() == 2
    changed = compile_shared_library([_source(tmp_path / "c", 7)], tmp_path / "c" / "lib.so", cache=True)
    assert counted_compiler() == 3 and _answer(changed) == 7
    compile_shared_library([_source(tmp_path / "d", header="/* another */\n")], tmp_path / "d" / "lib.so", cache=True)
    assert counted_compiler() == 4
    compile_shared_library([_source(tmp_path / "e")], tmp_path / "e" / "lib.so", cache=False)
    assert counted_compiler() == 5  # without cache=True the compiler always runs
    assert len(list(library_cache_folder().glob("*.lib"))) == 4


USER = "int answer(void);\nint twice(void);\nint twice(void) { return 2 * answer(); }\n"


def _linked_build(folder: Path, value: int) -> Path:
    """libuser.so in ``folder``, linked against libdep.so beside it (answer() = ``value``), as the C++ driver links the C."""
    compile_shared_library([_source(folder / "dep", value)], folder / "libdep.so")  # not cached: one compile each
    user = folder / "user" / "user.c"
    user.parent.mkdir()
    user.write_text(USER)
    flags = ("-O2", f"-L{folder}", "-Wl,--no-as-needed", "-l:libdep.so", "-Wl,-rpath,$ORIGIN")
    return compile_shared_library([user], folder / "libuser.so", flags, cache=True)


@pytest.mark.compile
def test_a_library_linked_from_its_build_folder_is_keyed_by_the_linked_content_not_by_the_folder(tmp_path, counted_compiler):
    first = _linked_build(tmp_path / "a", 42)
    assert counted_compiler() == 2
    again = _linked_build(tmp_path / "b", 42)  # another build folder (-L<folder>), the same library linked
    assert counted_compiler() == 3  # only libdep.so was compiled: libuser.so was a hit
    assert again.read_bytes() == first.read_bytes()
    lib = ctypes.CDLL(str(again))
    assert lib.twice() == 84
    _linked_build(tmp_path / "c", 7)  # the same flags and source, another library at -l:libdep.so
    assert counted_compiler() == 5  # a miss: libuser.so compiled again
    assert len(list(library_cache_folder().glob("*.lib"))) == 2


@pytest.mark.compile
def test_a_corrupt_or_foreign_file_at_an_entry_is_left_alone_and_the_library_compiled_again(tmp_path, counted_compiler):
    compile_shared_library([_source(tmp_path / "a")], tmp_path / "a" / "lib.so", cache=True)
    [entry] = library_cache_folder().glob("*.lib")
    data = bytearray(entry.read_bytes())
    data[-100] ^= 0xFF  # one flipped byte in the library
    entry.write_bytes(bytes(data))
    rebuilt = compile_shared_library([_source(tmp_path / "b")], tmp_path / "b" / "lib.so", cache=True)
    assert counted_compiler() == 2 and _answer(rebuilt) == 42
    assert entry.read_bytes() == bytes(data)  # not ours to delete or overwrite
    second = entry.with_name(entry.name.replace(".lib", ".1.lib"))
    assert second.is_file()
    compile_shared_library([_source(tmp_path / "c")], tmp_path / "c" / "lib.so", cache=True)
    assert counted_compiler() == 2  # the good entry under the next name is used
    foreign = tmp_path / "foreign.so"
    foreign.write_bytes(b"\x7fELF not a modelgen entry")
    os.replace(foreign, second)
    compile_shared_library([_source(tmp_path / "d")], tmp_path / "d" / "lib.so", cache=True)
    assert counted_compiler() == 3
    assert second.read_bytes() == b"\x7fELF not a modelgen entry"


@pytest.mark.compile
def test_two_builders_compiling_the_same_code_at_once_both_succeed_and_one_entry_stays(tmp_path, counted_compiler):
    def build(name: str) -> Path:
        return compile_shared_library([_source(tmp_path / name)], tmp_path / name / "lib.so", cache=True)

    (tmp_path / "barrier").write_text("2")  # each compile waits for the other: both missed the cache
    with ThreadPoolExecutor(2) as pool:
        libraries = list(pool.map(build, ["a", "b"]))
    (tmp_path / "barrier").unlink()
    assert counted_compiler() == 2
    assert [_answer(library) for library in libraries] == [42, 42]
    assert len(list(library_cache_folder().iterdir())) == 1
    compile_shared_library([_source(tmp_path / "c")], tmp_path / "c" / "lib.so", cache=True)
    assert counted_compiler() == 2


def test_the_cache_folder_follows_modelgen_cache_dir_then_xdg_cache_home(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "mine"))
    assert library_cache_folder() == tmp_path / "mine" / "libraries"
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert library_cache_folder() == tmp_path / "xdg" / "modelgen" / "libraries"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")  # not absolute: ignored, as the XDG rule says
    assert library_cache_folder() == Path.home() / ".cache" / "modelgen" / "libraries"


def test_a_relative_modelgen_cache_dir_is_refused_not_put_under_the_working_folder(monkeypatch, tmp_path):
    from modelgen.errors import ModelError

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(CACHE_ENV, "cache-here")
    with pytest.raises(ModelError, match=r"\$MODELGEN_CACHE_DIR 'cache-here' is not an absolute path"):
        library_cache_folder()
    assert not (tmp_path / "cache-here").exists()


@pytest.mark.compile
def test_a_failed_compile_is_not_cached(tmp_path, counted_compiler):
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "bad.c").write_text("int unused(int x) { return 0; }\n")  # -Wextra: unused parameter, -Werror
    from modelgen.errors import ModelError

    for _ in range(2):
        with pytest.raises(ModelError, match="failed"):
            compile_shared_library([folder / "bad.c"], folder / "lib.so", cache=True)
    assert counted_compiler() == 2
    assert not library_cache_folder().exists() or not list(library_cache_folder().glob("*.lib"))
