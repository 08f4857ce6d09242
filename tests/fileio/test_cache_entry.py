"""The cache-entry writer: written once, linked without replacing, a foreign file left alone."""

from pathlib import Path

from modelgen.fileio.cache_entry import link_new_entry


def _names(folder: Path) -> list[Path]:
    return [folder / "entry", folder / "entry.1", folder / "entry.2"]


def _accept_ours(path: Path) -> Path | None:
    return path if path.read_bytes() == b"payload" else None


def test_entry_is_linked_to_the_first_free_name_and_no_temporary_file_stays(tmp_path):
    kept = link_new_entry(tmp_path, "k" * 64, lambda handle: handle.write(b"payload"), _names(tmp_path), _accept_ours)
    assert kept == tmp_path / "entry"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry"]


def test_a_foreign_file_at_an_entry_name_is_left_alone_and_the_next_name_used(tmp_path):
    (tmp_path / "entry").write_bytes(b"the user's own file")
    kept = link_new_entry(tmp_path, "k" * 64, lambda handle: handle.write(b"payload"), _names(tmp_path), _accept_ours)
    assert kept == tmp_path / "entry.1"
    assert (tmp_path / "entry").read_bytes() == b"the user's own file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry", "entry.1"]


def test_an_existing_entry_that_verifies_is_used_instead_of_a_second_copy(tmp_path):
    (tmp_path / "entry").write_bytes(b"payload")
    kept = link_new_entry(tmp_path, "k" * 64, lambda handle: handle.write(b"payload"), _names(tmp_path), _accept_ours)
    assert kept == tmp_path / "entry"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry"]


def test_no_free_name_gives_none_and_leaves_every_file(tmp_path):
    for path in _names(tmp_path):
        path.write_bytes(b"not ours")
    kept = link_new_entry(tmp_path, "k" * 64, lambda handle: handle.write(b"payload"), _names(tmp_path), _accept_ours)
    assert kept is None
    assert all(path.read_bytes() == b"not ours" for path in _names(tmp_path))
    assert len(list(tmp_path.iterdir())) == 3


def test_a_failing_writer_leaves_no_temporary_file(tmp_path):
    def write(handle):
        raise OSError("disk full")

    assert link_new_entry(tmp_path, "k" * 64, write, _names(tmp_path), _accept_ours) is None
    assert list(tmp_path.iterdir()) == []
