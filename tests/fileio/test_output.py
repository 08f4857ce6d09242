"""Output is never lost: user files kept, edits refused, staging never left, writers serialized, umask kept."""

from __future__ import annotations

import errno
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from modelgen.fileio import output
from modelgen.errors import ModelError
from modelgen.fileio.output import MANIFEST_NAME, FolderUpdate, write_atomically, write_text_atomically

FILES = {"m.c": "int m;\n", "m.h": "extern int m;\n", "README.md": "# m\n"}


def leftovers(root: Path) -> list[str]:
    """Hidden staging, backup, lock or temporary entries anywhere under ``root``."""
    return sorted(str(p.relative_to(root)) for p in root.rglob(".*") if p.name != MANIFEST_NAME)


def test_manifest_lists_every_written_file_with_its_sha256(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    assert set(manifest["files"]) == set(FILES)
    assert manifest["files"]["m.c"] == output.sha256_text("int m;\n")
    assert manifest["generator"] == "modelgen" and manifest["version"]
    assert leftovers(tmp_path) == []


def test_manifest_is_byte_stable_from_run_to_run(tmp_path):
    first = write_atomically(tmp_path / "m", FILES) / MANIFEST_NAME
    text = first.read_text()
    assert (write_atomically(tmp_path / "m", FILES) / MANIFEST_NAME).read_text() == text


def test_user_files_and_folders_are_carried_over_to_the_new_output(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    (folder / "main.c").write_text("int main(void) { return 0; }\n")
    (folder / "build").mkdir()
    (folder / "build" / "m.o").write_bytes(b"\x7fELF")
    (folder / "build" / "deep").mkdir()
    os.symlink("m.c", folder / "link")
    write_atomically(folder, {**FILES, "m.c": "int m = 1;\n"})
    assert (folder / "m.c").read_text() == "int m = 1;\n"
    assert (folder / "main.c").read_text() == "int main(void) { return 0; }\n"
    assert (folder / "build" / "m.o").read_bytes() == b"\x7fELF" and (folder / "build" / "deep").is_dir()
    assert os.readlink(folder / "link") == "m.c"
    assert leftovers(tmp_path) == []


def test_a_generated_file_no_longer_generated_is_removed_but_user_files_stay(tmp_path):
    folder = write_atomically(tmp_path / "m", {**FILES, "old.txt": "x"})
    (folder / "mine.txt").write_text("mine")
    write_atomically(folder, FILES)
    assert not (folder / "old.txt").exists() and (folder / "mine.txt").read_text() == "mine"


def test_an_edited_generated_file_stops_the_write_unless_forced(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    (folder / "m.c").write_text("int m; /* my fix */\n")
    with pytest.raises(ModelError, match=r"m\.c: changed since modelgen wrote it.*--force"):
        write_atomically(folder, {**FILES, "m.h": "new\n"})
    assert (folder / "m.c").read_text() == "int m; /* my fix */\n" and (folder / "m.h").read_text() == FILES["m.h"]
    assert leftovers(tmp_path) == []
    write_atomically(folder, FILES, force=True)
    assert (folder / "m.c").read_text() == FILES["m.c"]


def test_a_user_file_with_a_generated_name_stops_the_write_unless_forced(tmp_path):
    folder = write_atomically(tmp_path / "m", {"m.c": "int m;\n"})
    (folder / "m.h").write_text("my header\n")
    with pytest.raises(ModelError, match=r"m\.h: was not written by modelgen.*--force"):
        write_atomically(folder, FILES)
    assert (folder / "m.h").read_text() == "my header\n"
    write_atomically(folder, FILES, force=True)
    assert (folder / "m.h").read_text() == FILES["m.h"]


def test_a_folder_without_manifest_is_refused_and_force_keeps_the_files_it_does_not_overwrite(tmp_path):
    folder = tmp_path / "m"
    folder.mkdir()
    (folder / "notes.txt").write_text("notes")
    (folder / "m.c").write_text("hand-written\n")
    with pytest.raises(ModelError, match=r"m: exists, is not empty and was not written by modelgen"):
        write_atomically(folder, FILES)
    assert (folder / "m.c").read_text() == "hand-written\n"
    write_atomically(folder, FILES, force=True)
    assert (folder / "notes.txt").read_text() == "notes" and (folder / "m.c").read_text() == FILES["m.c"]


def test_an_empty_existing_folder_is_written_without_force(tmp_path):
    (tmp_path / "m").mkdir()
    assert (write_atomically(tmp_path / "m", FILES) / "m.c").is_file()


def test_an_output_path_that_is_a_file_is_refused_and_kept(tmp_path):
    (tmp_path / "m").write_text("precious")
    with pytest.raises(ModelError, match="exists and is not a folder"):
        write_atomically(tmp_path / "m", FILES, force=True)
    assert (tmp_path / "m").read_text() == "precious"


def test_a_manifest_pointing_outside_its_folder_is_refused(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    (tmp_path / "victim").write_text("keep")
    (folder / MANIFEST_NAME).write_text(json.dumps({"files": {"../victim": output.sha256_text("keep")}}))
    with pytest.raises(ModelError, match="not a plain relative path"):
        write_atomically(folder, FILES)
    assert (tmp_path / "victim").read_text() == "keep"


def test_a_full_disk_leaves_the_previous_output_whole_and_no_staging(tmp_path, monkeypatch):
    folder = write_atomically(tmp_path / "m", FILES)
    calls = []
    real = output._write_text

    def fill_up(path, text):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, text)

    monkeypatch.setattr(output, "_write_text", fill_up)
    with pytest.raises(OSError) as raised:
        write_atomically(folder, {name: "new\n" for name in FILES})
    assert raised.value.errno == errno.ENOSPC
    assert {p.name: p.read_text() for p in folder.iterdir() if p.name != MANIFEST_NAME} == FILES
    assert leftovers(tmp_path) == []


def test_files_and_folders_get_the_users_umask(tmp_path):
    previous = os.umask(0o027)
    try:
        folder = write_atomically(tmp_path / "m", FILES)
        report = write_text_atomically(tmp_path / "r" / "README.md", "x\n")
    finally:
        os.umask(previous)
    assert folder.stat().st_mode & 0o777 == 0o750
    assert (folder / "m.c").stat().st_mode & 0o777 == 0o640
    assert report.stat().st_mode & 0o777 == 0o640


def test_a_staged_update_that_is_not_committed_leaves_the_old_output(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    with FolderUpdate(folder) as update:
        staged = update.stage({name: "broken\n" for name in FILES})
        (staged / "__pycache__").mkdir()  # what checking the staged code leaves
    assert (folder / "m.c").read_text() == FILES["m.c"]
    assert leftovers(tmp_path) == []


def test_a_commit_drops_what_checking_left_in_the_staging_folder(tmp_path):
    with FolderUpdate(tmp_path / "m") as update:
        staged = update.stage(FILES)
        (staged / "__pycache__").mkdir()
        (staged / "libm.so").write_bytes(b"")
        folder = update.commit()
    assert sorted(p.name for p in folder.iterdir()) == sorted([*FILES, MANIFEST_NAME])


def test_a_writer_killed_between_the_renames_is_recovered_by_the_next(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    (folder / "main.c").write_text("mine")
    os.rename(folder, tmp_path / ".m.old")  # killed after the first rename
    (tmp_path / f".m.{output.STAGING_INFIX}abc").mkdir()
    write_atomically(folder, FILES)
    assert (folder / "main.c").read_text() == "mine"
    assert leftovers(tmp_path) == []


def test_a_writer_killed_after_the_swap_gives_back_the_user_files_it_was_moving(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    old = write_atomically(tmp_path / ".m.old", FILES)
    (old / "main.c").write_text("mine")  # not yet moved into the new folder
    write_atomically(folder, FILES)
    assert (folder / "main.c").read_text() == "mine"
    assert leftovers(tmp_path) == []


def _writer(folder: str, label: str, rounds: int) -> None:
    for k in range(rounds):
        write_atomically(Path(folder), {f"f{i}.txt": f"{label} {k}\n" * 2000 for i in range(20)})


def test_concurrent_writers_are_serialized_and_leave_one_whole_output(tmp_path):
    folder = tmp_path / "m"
    for _ in range(3):
        ctx = multiprocessing.get_context("fork")
        workers = [ctx.Process(target=_writer, args=(str(folder), f"w{w}", 3)) for w in range(8)]
        for w in workers:
            w.start()
        for w in workers:
            w.join(60)
        assert [w.exitcode for w in workers] == [0] * 8
        texts = {p.read_text() for p in folder.glob("f*.txt")}
        assert len(texts) == 1 and len(list(folder.glob("f*.txt"))) == 20  # all from one writer
        assert leftovers(tmp_path) == []


SLOW_WRITER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from modelgen.fileio.output import write_atomically

    class Slow(dict):
        def items(self):
            for i in range(1000):
                if i == 3:
                    print("writing", flush=True)
                time.sleep(0.01)
                yield f"f{i}.txt", "new"

    try:
        write_atomically(Path(sys.argv[1]), Slow(x=1))
    except KeyboardInterrupt:
        sys.exit(130)
    """
)


def test_sigint_while_writing_leaves_the_previous_output_and_no_staging(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WRITER, str(folder)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    proc.send_signal(signal.SIGINT)
    assert proc.wait(30) == 130
    assert {p.name for p in folder.iterdir()} == {*FILES, MANIFEST_NAME}
    assert leftovers(tmp_path) == []


def test_sigint_during_the_swap_is_acted_on_after_it(tmp_path):
    folder = write_atomically(tmp_path / "m", FILES)
    with pytest.raises(KeyboardInterrupt):
        with FolderUpdate(folder) as update:
            update.stage({name: "new\n" for name in FILES})
            real = os.rename

            def rename_then_interrupt(src, dst):
                real(src, dst)
                os.kill(os.getpid(), signal.SIGINT)  # held back until the swap is done
                time.sleep(0.01)

            os.rename = rename_then_interrupt
            try:
                update.commit()
            finally:
                os.rename = real
    assert {p.read_text() for p in folder.iterdir() if p.name != MANIFEST_NAME} == {"new\n"}
    assert leftovers(tmp_path) == []


# -- report folders: shared with the user's files, merged file by file ---------------------------

from modelgen.fileio.output import ReportUpdate  # noqa: E402


def _report(folder, files, force=False):
    with ReportUpdate(folder, force) as staged:
        for name, text in files.items():
            (staged.staging / name).parent.mkdir(parents=True, exist_ok=True)
            (staged.staging / name).write_text(text)
        return staged.commit()


def test_a_report_replaces_its_own_files_and_keeps_the_users(tmp_path):
    (tmp_path / "README.md").write_text("the user's project")
    _report(tmp_path, {"verification.md": "v1", "sub/table.csv": "1"})
    _report(tmp_path, {"verification.md": "v2", "sub/table.csv": "2"})
    assert (tmp_path / "verification.md").read_text() == "v2" and (tmp_path / "sub" / "table.csv").read_text() == "2"
    assert (tmp_path / "README.md").read_text() == "the user's project"
    assert leftovers(tmp_path) == []


def test_a_report_never_replaces_a_user_file_of_the_same_name_without_force(tmp_path):
    (tmp_path / "README.md").write_text("the user's project")
    with pytest.raises(ModelError, match=r"README\.md: was not written by modelgen.*--force"):
        _report(tmp_path, {"README.md": "report", "other.md": "x"})
    assert (tmp_path / "README.md").read_text() == "the user's project"
    assert not (tmp_path / "other.md").exists() and leftovers(tmp_path) == []
    _report(tmp_path, {"README.md": "report"}, force=True)
    assert (tmp_path / "README.md").read_text() == "report"


def test_an_edited_report_file_is_not_replaced_without_force(tmp_path):
    _report(tmp_path, {"summary.md": "v1"})
    (tmp_path / "summary.md").write_text("my notes")
    with pytest.raises(ModelError, match="edited since"):
        _report(tmp_path, {"summary.md": "v2"})
    assert (tmp_path / "summary.md").read_text() == "my notes"


def test_a_nested_report_written_separately_counts_as_modelgens(tmp_path):
    _report(tmp_path / "covariance", {"table2.md": "alone"})
    _report(tmp_path, {"covariance/table2.md": "from run"})
    _report(tmp_path / "covariance", {"table2.md": "alone again"})
    assert (tmp_path / "covariance" / "table2.md").read_text() == "alone again"


def test_a_report_that_fails_leaves_no_folder_it_created(tmp_path):
    with pytest.raises(RuntimeError):
        with ReportUpdate(tmp_path / "report") as staged:
            (staged.staging / "half.md").write_text("half")
            raise RuntimeError("the analysis failed")
    assert not (tmp_path / "report").exists()


def _report_run(folder, texts, kill_after_moves=None, force=False):
    """Write a report of ``texts`` (name -> text) through ReportUpdate; in a child killed (os._exit, as SIGKILL: nothing runs) after ``kill_after_moves`` moves."""
    import modelgen.fileio.output as output

    with output.ReportUpdate(folder, force=force) as staged:
        for name, text in texts.items():
            (staged.staging / name).parent.mkdir(parents=True, exist_ok=True)
            (staged.staging / name).write_text(text)
        if kill_after_moves is not None:
            moves = []
            real_replace = os.replace

            def replace_then_die(source, target):
                if ".modelgen-staging" in str(source):  # a staged file moving in (not the record's own rename)
                    if len(moves) == kill_after_moves:
                        os._exit(9)
                    moves.append(target)
                real_replace(source, target)

            output.os.replace = replace_then_die  # the child's own module: the parent's is untouched
        return staged.commit()


@pytest.mark.parametrize("kill_after_moves", [0, 1, 2])
def test_a_report_commit_killed_between_moves_is_finished_by_the_next_writer_never_a_mix(tmp_path, kill_after_moves):
    """SIGKILL mid-commit (issue 28: trade's new summary.md beside the old trade.csv, then exit 2 until --force)."""
    folder = tmp_path / "trade"
    first = {"summary.md": "run 1\n", "trade.csv": "a\n1\n", "figures/f.txt": "fig 1\n"}
    second = {"summary.md": "run 2\n", "trade.csv": "a\n2\n", "figures/f.txt": "fig 2\n"}
    _report_run(folder, first)
    pid = os.fork()
    if pid == 0:  # the writer that is killed while moving its files in
        try:
            _report_run(folder, second, kill_after_moves=kill_after_moves)
        finally:
            os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 9
    assert (folder / ".modelgen-commit.json").is_file()  # the record of the commit cut short
    from modelgen.fileio.output import ReportUpdate

    with ReportUpdate(folder):  # the next writer (any report into the folder) finishes it first
        pass
    assert {name: (folder / name).read_text() for name in second} == second
    assert not (folder / ".modelgen-commit.json").exists()
    assert not [p.name for p in folder.iterdir() if p.name.startswith(".modelgen-staging")]
    _report_run(folder, first)  # and a third run needs no --force: the manifest knows every file
    assert {name: (folder / name).read_text() for name in first} == first


def test_a_report_commit_record_that_names_no_staging_folder_is_dropped(tmp_path):
    from modelgen.fileio.output import REPORT_COMMIT_RECORD, ReportUpdate

    folder = tmp_path / "r"
    _report_run(folder, {"a.txt": "1\n"})
    (folder / REPORT_COMMIT_RECORD).write_text('{"staging": "../elsewhere", "files": {"a.txt": "0"}}')
    with ReportUpdate(folder):
        pass
    assert not (folder / REPORT_COMMIT_RECORD).exists()
    assert (folder / "a.txt").read_text() == "1\n"


# -- issue 28 minors: only regular files are replaced; a full disk names the file -----------------------------


def _non_regular(tmp_path, kind):
    path = tmp_path / f"target_{kind}"
    if kind == "pipe":
        os.mkfifo(path)
    else:
        (tmp_path / "elsewhere.txt").write_text("the link's target")
        os.symlink(tmp_path / "elsewhere.txt", path)
    return path


@pytest.mark.parametrize("kind", ["pipe", "link"])
def test_a_file_write_never_replaces_what_is_not_a_regular_file(tmp_path, kind):
    """Issue 28: ``derive --out /dev/full --force`` put a regular file where the device node was."""
    path = _non_regular(tmp_path, kind)
    with pytest.raises(ModelError, match=r"is (a named pipe|a symbolic link), and modelgen replaces only regular files"):
        write_text_atomically(path, "text")
    assert path.is_symlink() if kind == "link" else path.is_fifo()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("kind", ["pipe", "link"])
def test_a_report_never_replaces_what_is_not_a_regular_file_even_with_force(tmp_path, kind):
    path = _non_regular(tmp_path, kind)
    with pytest.raises(ModelError, match=r"is (a named pipe|a symbolic link), and modelgen replaces only regular files"):
        _report(tmp_path, {path.name: "report"}, force=True)
    assert path.is_symlink() if kind == "link" else path.is_fifo()
    assert leftovers(tmp_path) == []


class _FullDisk:
    """A file object whose writes fail as on a full disk: ENOSPC naming no file (what close() and write() raise)."""

    def __init__(self, handle):
        self.handle = handle

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.handle.close()

    def write(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_names_the_file_being_written_and_leaves_no_temporary_file(tmp_path, monkeypatch):
    real = os.fdopen
    monkeypatch.setattr(output.os, "fdopen", lambda fd, mode: _FullDisk(real(fd, mode)))
    with pytest.raises(OSError) as raised:
        write_text_atomically(tmp_path / "summary.md", "text")
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(tmp_path / "summary.md")
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_in_a_staged_output_names_the_final_file_not_the_staging_one(tmp_path, monkeypatch):
    real = open

    def full_open(path, mode="r", *args, **kwargs):
        handle = real(path, mode, *args, **kwargs)
        return _FullDisk(handle) if "x" in mode else handle

    monkeypatch.setattr(output, "open", full_open, raising=False)
    with pytest.raises(OSError) as raised:
        write_atomically(tmp_path / "m", FILES)
    assert raised.value.errno == errno.ENOSPC
    written = Path(raised.value.filename)
    assert written.parent == tmp_path / "m" and written.name in FILES  # where the user will look, not .m.staging-*/
    assert leftovers(tmp_path) == []


def test_a_full_disk_in_a_report_names_the_final_file(tmp_path):
    with pytest.raises(OSError) as raised:
        with ReportUpdate(tmp_path / "r") as staged:
            raise OSError(errno.ENOSPC, "No space left on device", str(staged.staging / "figure.png"))
    assert raised.value.filename == str(tmp_path / "r" / "figure.png")
    assert leftovers(tmp_path) == []
