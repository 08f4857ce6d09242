"""The disk cache of the generated modules' compiled predict kernels (modelgen.codegen.kernel_cache).

With $MODELGEN_KERNEL_CACHE_DIR set, a kernel one process compiled is loaded
from disk by another process, which loads the module from another path, and
computes the same numbers; the cache is keyed by the module's
exact text; unset, nothing is written; a relative folder is refused and a
folder that cannot be written leaves the kernel compiled in memory.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from modelgen.codegen import build
from modelgen.codegen.kernel_cache import KERNEL_CACHE_ENV, disk_cached_kernel, kernel_source
from modelgen.errors import ModelError
from tests.codegen.test_python_filter_class import arguments, py  # noqa: F401 (fixtures)

pytest.importorskip("numba")

REPO = Path(__file__).resolve().parents[2]


def fresh_load(text: str, folder: Path, monkeypatch):
    """The module of ``text`` loaded from its own file in ``folder`` by a process that has compiled no kernel yet."""
    monkeypatch.setattr(build, "_COMPILED_PREDICT_BY_TEXT", {})
    folder.mkdir()
    (folder / "m.py").write_text(text)
    return build.load_python_module(folder / "m.py")


def predicted(module, a):
    x, P = np.empty(18), np.empty((18, 18))
    assert module._compiled_predict(a["x"], a["P"], a["Phi"], a["Qd"], x, P, True)
    return x, P


#: Run in a fresh process: load the module at argv[1], call its kernel on the arrays saved in argv[2], save the
#: result beside them and print numba's cache hits and misses of that call.
OTHER_PROCESS = """
import sys
import numpy as np
from modelgen.codegen.build import load_python_module
module = load_python_module(sys.argv[1])
a = np.load(sys.argv[2])
x, P = np.empty(18), np.empty((18, 18))
assert module._compiled_predict(a["x"], a["P"], a["Phi"], a["Qd"], x, P, True)
np.savez(sys.argv[3], x=x, P=P)
stats = module._compiled_predict.stats
print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
"""


def test_a_kernel_compiled_by_one_process_is_loaded_from_disk_by_another_with_the_same_numbers(
        py, arguments, tmp_path, monkeypatch):  # noqa: F811
    monkeypatch.setenv(KERNEL_CACHE_ENV, str(tmp_path / "kernels"))
    text = Path(py.__file__).read_text()
    first = fresh_load(text, tmp_path / "first", monkeypatch)
    first_result = predicted(first, arguments)
    assert sum(first._compiled_predict.stats.cache_misses.values()) == 1
    assert not first._compiled_predict.stats.cache_hits
    (tmp_path / "second").mkdir()
    (tmp_path / "second" / "m.py").write_text(text)  # another path: another module name in the other process
    np.savez(tmp_path / "inputs.npz", **{k: arguments[k] for k in ("x", "P", "Phi", "Qd")})
    done = subprocess.run([sys.executable, "-c", OTHER_PROCESS, str(tmp_path / "second" / "m.py"),
                           str(tmp_path / "inputs.npz"), str(tmp_path / "result.npz")],
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["1", "0"]  # one cache hit, nothing compiled
    second_result = np.load(tmp_path / "result.npz")
    assert np.array_equal(second_result["x"], first_result[0]) and np.array_equal(second_result["P"], first_result[1])


def test_the_kernel_is_compiled_from_a_copy_named_by_the_sha256_of_the_exact_text(tmp_path):
    text = b"x = 1\n"
    path = kernel_source(tmp_path, text)
    assert path.name == f"kernel_{hashlib.sha256(text).hexdigest()}.py" and path.read_bytes() == text
    assert kernel_source(tmp_path, text + b"\n") != path  # another text, another file
    path.write_bytes(b"x = 2\n")  # a copy that is not the text (cut short, edited) is written again
    assert kernel_source(tmp_path, text) == path and path.read_bytes() == text


def test_without_the_folder_the_kernel_stays_in_memory_and_nothing_is_written(py, monkeypatch, tmp_path):  # noqa: F811
    monkeypatch.delenv(KERNEL_CACHE_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    kernel = py._compiled_predict
    assert disk_cached_kernel(kernel, b"any text") is kernel
    assert not list(tmp_path.iterdir())


def test_a_relative_kernel_cache_folder_is_refused(py, monkeypatch):  # noqa: F811
    monkeypatch.setenv(KERNEL_CACHE_ENV, "kernels")
    with pytest.raises(ModelError, match=r"\$MODELGEN_KERNEL_CACHE_DIR 'kernels' is not an absolute path"):
        disk_cached_kernel(py._compiled_predict, b"any text")


def test_a_folder_that_cannot_be_written_leaves_the_kernel_compiled_in_memory(py, monkeypatch, tmp_path):  # noqa: F811
    (tmp_path / "a-file").write_text("not a folder")
    monkeypatch.setenv(KERNEL_CACHE_ENV, str(tmp_path / "a-file"))
    kernel = py._compiled_predict
    assert disk_cached_kernel(kernel, b"any text") is kernel
