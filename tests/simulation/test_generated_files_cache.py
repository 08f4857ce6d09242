"""The generated filter files kept on disk: a fresh process takes them instead of generating them again."""

from collections import OrderedDict

import pytest

import modelgen.codegen.generate as generate
from modelgen.codegen.build import CACHE_ENV
from modelgen.simulation import filters


@pytest.fixture
def fresh_process(monkeypatch, tmp_path):
    """An empty cache folder and no files kept in this process; the calls of generate_code counted."""
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(filters, "_GENERATED", OrderedDict())
    calls = []
    real = generate.generate_code
    monkeypatch.setattr(generate, "generate_code", lambda derived: calls.append(1) or real(derived))
    return calls


def test_a_fresh_process_takes_the_files_from_the_disk_instead_of_generating_them(paper_derived, fresh_process,
                                                                                 monkeypatch):
    first = filters.generated_filter_files(paper_derived)
    assert len(fresh_process) == 1
    monkeypatch.setattr(filters, "_GENERATED", OrderedDict())  # another process: only the disk is shared
    again = filters.generated_filter_files(paper_derived)
    assert len(fresh_process) == 1 and again == first


def test_an_entry_that_does_not_verify_is_left_alone_and_the_files_generated_again(paper_derived, fresh_process,
                                                                                monkeypatch, tmp_path):
    first = filters.generated_filter_files(paper_derived)
    (entry,) = (tmp_path / "generated").iterdir()
    entry.write_bytes(entry.read_bytes()[:-10])  # cut short
    monkeypatch.setattr(filters, "_GENERATED", OrderedDict())
    assert filters.generated_filter_files(paper_derived) == first and len(fresh_process) == 2
    assert len(entry.read_bytes()) > 0 and len(list((tmp_path / "generated").iterdir())) == 2  # kept, a new one beside


def test_another_generator_does_not_take_the_files_of_this_one(paper_derived, fresh_process, monkeypatch):
    filters.generated_filter_files(paper_derived)
    monkeypatch.setattr(filters, "_GENERATED", OrderedDict())
    monkeypatch.setattr(filters, "generator_digest", lambda: "another modelgen")
    filters.generated_filter_files(paper_derived)
    assert len(fresh_process) == 2


def test_the_generator_digest_changes_with_a_source_file(tmp_path, monkeypatch):
    package = tmp_path / "modelgen"
    (package / "simulation").mkdir(parents=True)
    (package / "codegen.j2").write_text("{{ a }}", encoding="utf-8")
    monkeypatch.setattr(filters, "__file__", str(package / "simulation" / "filters.py"))
    filters.generator_digest.cache_clear()
    try:
        before = filters.generator_digest()
        filters.generator_digest.cache_clear()
        (package / "codegen.j2").write_text("{{ b }}", encoding="utf-8")
        assert filters.generator_digest() != before
    finally:
        filters.generator_digest.cache_clear()
