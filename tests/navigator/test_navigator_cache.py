"""The replay's compile cache: a relative $MODELGEN_CACHE_DIR is one refusal, a corrupt cached navigator is rebuilt."""

from __future__ import annotations

from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"


@pytest.mark.flight
def test_replay_with_a_relative_cache_dir_is_one_error_line_and_writes_nothing(tmp_path):
    """Run in this process as ``python -m modelgen`` would run it (tests/cli_in_process.py: exit code, outputs)."""
    from cli_in_process import RUN_ENVIRONMENT, run_modelgen

    run = run_modelgen(["replay", DATA / "excerpt.yaml", "--out", "out", "--no-figures"], cwd=tmp_path, timeout=300,
                       environment={**RUN_ENVIRONMENT, "MODELGEN_CACHE_DIR": "relcache"})
    assert run is not None, "modelgen replay ran longer than 300 s"
    assert run.returncode == 2
    errors = [line for line in run.stderr.splitlines() if line.startswith("modelgen: error:")]
    assert errors == ["modelgen: error: $MODELGEN_CACHE_DIR 'relcache' is not an absolute path: the compile cache "
                      "would move with the working folder; give an absolute path"]
    assert "Traceback" not in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.compile
def test_a_corrupt_cached_navigator_is_not_loaded_but_compiled_again(tmp_path, monkeypatch):
    """An entry whose library bytes were damaged after it was written fails its digest: compiled again, not loaded."""
    from modelgen.codegen.build import CACHE_ENV
    from modelgen.fileio.cache_eviction import cached_entries
    from modelgen.navigator.cnav import cache_folder, cached_c_navigator, navigator_key
    from modelgen.navigator.errorstate import model_path
    from modelgen.navigator.spec import navigator_spec

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    model = model_path("ins_gps15_nav", str(DATA / "excerpt.yaml"))
    spec = navigator_spec(model, with_python=False)
    _, hit = cached_c_navigator(spec)
    assert not hit
    # the compile cache's own folder under $MODELGEN_CACHE_DIR, an entry its size cap counts (issue 28: it had its own)
    assert cache_folder() == tmp_path / "cache" / "libraries"
    entries = sorted(cache_folder().glob(navigator_key(model, 1024) + "*.lib"))
    assert len(entries) == 1
    assert [entry.path for entry in cached_entries(tmp_path / "cache")] == entries
    data = bytearray(entries[0].read_bytes())
    data[-100] ^= 0xFF  # one byte of the library itself
    entries[0].write_bytes(bytes(data))
    navigator, hit = cached_c_navigator(spec)
    assert not hit and navigator.size > 0  # compiled again
    assert len(sorted(cache_folder().glob(navigator_key(model, 1024) + "*.lib"))) == 2  # kept under the next name
    _, hit = cached_c_navigator(spec)
    assert hit  # and the good entry is used from then on
