"""The one writer of modelgen's output: whole files and whole folders, never lost, never half-written.

A generated folder ``OUT/<model>/`` is replaced as a unit: the new files are
written into a staging folder next to it (``OUT/.<model>.modelgen-staging-*``)
and swapped in by two renames, so at any moment the folder holds either the
complete old output or the complete new one.

The folder may also hold files modelgen did not write (a user's ``main.c``, a
``build/`` folder).  To tell them apart, every write leaves a manifest,
``OUT/<model>/.modelgen-manifest.json``, with the sha256 of each file written.
On the next write:

- an entry that the manifest does not list is the user's: it is carried over
  into the new folder untouched (it is renamed, never copied or deleted);
- a listed file whose content changed since (the user edited generated code)
  stops the write with a message naming it, unless ``force``;
- a user entry with the name of a file about to be generated stops the write
  unless ``force`` (which overwrites it);
- an existing non-empty folder with no manifest stops the write unless
  ``force``; with ``force`` all its entries count as the user's (kept unless
  they collide with a generated file).

Concurrent writers of one folder are serialized by ``fcntl.flock`` on
``OUT/.<model>.lock``, which is removed when the writer is done (a lock file
left by a killed process is harmless: the next writer reuses it).  A folder
``OUT/.<model>.old`` left by a killed process is recovered by the next writer.
The swap itself runs with SIGINT/SIGTERM/SIGHUP held back, so an interrupt is
acted on only once the folder is whole; an interrupt at any other moment
removes the staging folder and leaves the previous output as it was.  Files and folders get the user's
umask.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shutil
import signal
import stat
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path, PurePosixPath
from typing import Callable, Iterator, Mapping

from modelgen.version import __version__
from modelgen.errors import ModelError

#: Name of the manifest inside every folder modelgen writes.
MANIFEST_NAME = ".modelgen-manifest.json"

#: Infix of staging folder names; only folders so named are ever cleaned up as leftovers.
STAGING_INFIX = "modelgen-staging-"

_HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}


def current_umask() -> int:
    """The process umask (read by setting and restoring it: there is no getter)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def sha256_text(text: str) -> str:
    """The sha256 of ``text`` as written (UTF-8)."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def sha256_file(path: Path) -> str:
    """The sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 16), b""):
            digest.update(chunk)
    return digest.hexdigest()


def manifest_text(files: Mapping[str, str]) -> str:
    """The manifest for ``files`` (name -> text): byte-stable, no timestamps."""
    body = {
        "generator": "modelgen",
        "version": __version__,
        "files": {name: sha256_text(text) for name, text in sorted(files.items())},
    }
    return json.dumps(body, indent=2, sort_keys=True) + "\n"


def read_manifest(folder: Path) -> dict[str, str] | None:
    """Relative path -> sha256 of the files modelgen wrote into ``folder``; None without a manifest."""
    path = Path(folder) / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError):
        raise ModelError(f"{path}: not a modelgen manifest (not valid JSON); remove it or pass --force") from None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        raise ModelError(f"{path}: not a modelgen manifest (no 'files' mapping); remove it or pass --force")
    return {_safe_relative(path, name): digest for name, digest in files.items()}


def _safe_relative(manifest: Path, name: str) -> str:
    """A manifest entry, refused if it points outside its folder (the manifest is untrusted too)."""
    parts = PurePosixPath(name).parts
    if not parts or PurePosixPath(name).is_absolute() or ".." in parts or name != str(PurePosixPath(name)):
        raise ModelError(f"{manifest}: entry {name!r} is not a plain relative path")
    return name


def _entries(folder: Path, owned: set[str], prefix: str = "") -> list[str]:
    """Relative paths of the largest subtrees of ``folder`` that no owned file lies in (the user's entries)."""
    found = []
    with os.scandir(folder) as scan:
        for entry in sorted(scan, key=lambda e: e.name):
            rel = f"{prefix}{entry.name}"
            if rel == MANIFEST_NAME or rel in owned:
                continue
            if entry.is_dir(follow_symlinks=False) and any(o.startswith(rel + "/") for o in owned):
                found += _entries(Path(entry.path), owned, rel + "/")
            else:
                found.append(rel)
    return found


def _collides(user_entry: str, new_files: set[str]) -> bool:
    """True if a user's entry has the path of a new file, or lies on its way."""
    return any(
        user_entry == name or name.startswith(user_entry + "/") or user_entry.startswith(name + "/") for name in new_files
    )


def plan_carry_over(folder: Path, new_files: set[str], force: bool) -> tuple[list[str], list[str]]:
    """Which entries of the existing ``folder`` are kept, and which ``force`` lets the new files overwrite.

    Returns (carried, overwritten) as relative paths; raises ModelError for
    anything that would lose a user's work without ``force``.
    """
    folder = Path(folder)
    if not folder.exists() and not folder.is_symlink():
        return [], []
    if folder.is_symlink() or not folder.is_dir():
        raise ModelError(f"{folder}: exists and is not a folder; modelgen will not replace it")
    try:
        manifest = read_manifest(folder)
    except ModelError:
        if not force:
            raise
        manifest = None
    owned = set(manifest or {})
    user = _entries(folder, owned)
    if manifest is None and user and not force:
        raise ModelError(
            f"{folder}: exists, is not empty and was not written by modelgen (no {MANIFEST_NAME}); "
            "modelgen never deletes files it did not write: move them away, or pass --force to write into it "
            "(files that do not collide with generated ones are kept)"
        )
    changed = []
    for name in sorted(owned):
        path = folder / name
        if path.is_symlink() or path.is_dir() or (path.exists() and sha256_file(path) != manifest[name]):
            changed.append(name)
    if changed and not force:
        raise ModelError(
            f"{folder / changed[0]}: changed since modelgen wrote it; copy your changes elsewhere, "
            "or pass --force to overwrite it"
        )
    overwritten = [u for u in user if _collides(u, new_files)]
    if overwritten and not force:
        raise ModelError(
            f"{folder / overwritten[0]}: was not written by modelgen and a generated file would replace it; "
            "rename it, or pass --force to overwrite it"
        )
    return [u for u in user if u not in overwritten], overwritten + changed


@contextmanager
def folder_lock(folder: Path, path: Path | None = None) -> Iterator[Path]:
    """Hold an exclusive lock on writing ``folder``, waiting for any other writer.

    The lock file is ``path``, by default ``<parent>/.<name>.lock``.  It is
    removed on release; a writer that finds the file it locked already
    unlinked or replaced takes the lock again, so removal is safe.
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    path = Path(path) if path is not None else folder.with_name(f".{folder.name}.lock")
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        except BaseException:
            os.close(fd)
            raise
        if same:
            break
        os.close(fd)
    try:
        yield path
    finally:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
        finally:
            os.close(fd)


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP back until the block is done, then act on them.

    The Python handlers are swapped for one that only records the signal (a
    signal mask would not do: a process-wide signal may go to a BLAS thread,
    and Python then runs its handler in the main thread anyway).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    for signum in _HELD_SIGNALS:
        previous[signum] = signal.signal(signum, lambda number, frame: received.append(number))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        for signum in dict.fromkeys(received):
            signal.raise_signal(signum)


def _apply_umask_to_folder(path: Path) -> None:
    """Give a folder the mode a plain mkdir would (mkdtemp makes it 0700 whatever the umask)."""
    os.chmod(path, 0o777 & ~current_umask())


def _write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with open(path, "x", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
    except OSError as exc:
        if exc.filename is None:  # a write into a full disk names no file: name the one being written
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def _name_final_file(error: BaseException | None, staging: Path | None, final: Callable[[Path], Path]) -> None:
    """An OSError about a file in a staging folder names the file the user asked for (``final`` of it)."""
    if not isinstance(error, OSError) or staging is None:
        return
    for attribute in ("filename", "filename2"):
        name = getattr(error, attribute)
        if isinstance(name, str) and Path(name).is_relative_to(staging):
            setattr(error, attribute, str(final(Path(name))))


def _move_entries(source: Path, target: Path, entries: list[str]) -> list[str]:
    """Rename each entry from ``source`` into ``target`` (same file system); the entries that could not move."""
    stuck = []
    for rel in entries:
        src, dst = source / rel, target / rel
        if not (src.exists() or src.is_symlink()):
            continue
        if dst.exists() or dst.is_symlink():
            stuck.append(rel)
            continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.rename(src, dst)
    return stuck


def _remove_owned(old: Path, owned: set[str], overwritten: list[str]) -> None:
    """Delete what modelgen wrote in ``old`` (and what --force said to overwrite); keep anything else.

    Raises ModelError if something else is still there, leaving it in place.
    """
    for rel in overwritten:
        path = old / rel
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    for rel in sorted(owned | {MANIFEST_NAME}):
        path = old / rel
        if path.is_dir() and not path.is_symlink():
            continue  # a folder where a generated file was: the user's, left for the check below
        if path.exists() or path.is_symlink():
            path.unlink()
    for dirpath, dirnames, filenames in os.walk(old, topdown=False):
        if not os.listdir(dirpath):
            os.rmdir(dirpath)
    if old.exists():
        raise ModelError(f"{old}: kept, because it still holds files modelgen did not write; move them back by hand")


def _remove_staging_leftovers(folder: Path) -> None:
    """Staging folders of an interrupted writer (only modelgen creates names with STAGING_INFIX)."""
    for path in folder.parent.glob(f".{folder.name}.{STAGING_INFIX}*"):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)


def recover_interrupted(folder: Path) -> None:
    """Finish or undo the swap of a writer that was killed (call with the folder's lock held)."""
    folder = Path(folder)
    _remove_staging_leftovers(folder)
    old = folder.with_name(f".{folder.name}.old")
    if not old.is_dir() or old.is_symlink():
        return
    if not folder.exists():
        os.rename(old, folder)  # killed between the two renames: the old output comes back
        return
    try:
        owned = set(read_manifest(old) or {})
    except ModelError:
        owned = set()
    _move_entries(old, folder, _entries(old, owned))
    _remove_owned(old, owned, [])


def _discard_staging(staging: Path | None) -> None:
    """Remove a staging folder that was not committed (modelgen made it); None for the caller to keep."""
    if staging is not None:
        shutil.rmtree(staging, ignore_errors=True)
    return None


class FolderUpdate:
    """Replace ``folder`` by new files in two steps: ``stage`` (writable, checkable), then ``commit``.

    Use as a context manager: it holds the folder's lock, and on leaving it
    (normally, by an exception or by KeyboardInterrupt) removes a staging
    folder that was not committed, so nothing half-written is ever left.
    """

    def __init__(self, folder: Path, force: bool = False) -> None:
        self.folder = Path(folder)
        self.force = force
        self.staging: Path | None = None
        self.files: dict[str, str] = {}
        self._lock = None

    def __enter__(self) -> "FolderUpdate":
        self._lock = folder_lock(self.folder)
        self._lock.__enter__()
        try:
            recover_interrupted(self.folder)
        except BaseException:
            self._lock.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        _name_final_file(exc_info[1] if len(exc_info) > 1 else None, self.staging,
                         lambda path: self.folder / path.relative_to(self.staging))
        try:
            self.staging = _discard_staging(self.staging)
        finally:
            self._lock.__exit__(*exc_info)

    def stage(self, files: Mapping[str, str]) -> Path:
        """Check that nothing of the user's would be lost, then write ``files`` and the manifest into a staging folder."""
        names = set(files)
        for name in names:
            _safe_relative(self.folder / name, name)
        plan_carry_over(self.folder, names, self.force)
        self.staging = Path(tempfile.mkdtemp(prefix=f".{self.folder.name}.{STAGING_INFIX}", dir=self.folder.parent))
        _apply_umask_to_folder(self.staging)
        written = {}
        for name, text in sorted(files.items()):
            _write_text(self.staging / name, text)
            written[name] = text
        _write_text(self.staging / MANIFEST_NAME, manifest_text(written))
        self.files = written
        return self.staging

    def commit(self) -> Path:
        """Swap the staged files in, carrying the user's entries over; return the folder."""
        if self.staging is None:
            raise RuntimeError("commit() without stage()")
        carried, overwritten = plan_carry_over(self.folder, set(self.files), self.force)
        for extra in _entries(self.staging, set(self.files)):  # e.g. __pycache__ from checking the staged code
            path = self.staging / extra
            shutil.rmtree(path) if path.is_dir() and not path.is_symlink() else path.unlink()
        old = self.folder.with_name(f".{self.folder.name}.old")
        with signals_held():
            if self.folder.exists():
                try:
                    owned = set(read_manifest(self.folder) or {})
                except ModelError:
                    owned = set()  # --force over a broken manifest: every entry is the user's
                os.rename(self.folder, old)
                os.rename(self.staging, self.folder)
                self.staging = None
                _move_entries(old, self.folder, carried)
                _remove_owned(old, owned, overwritten)
            else:
                os.rename(self.staging, self.folder)
                self.staging = None
        return self.folder


def write_atomically(folder: Path, files: Mapping[str, str], force: bool = False) -> Path:
    """Replace ``folder`` by ``files`` (name -> text) plus a manifest, keeping the user's own files.

    See the module docstring for what is kept, what is refused and what
    ``force`` overrides.  A failure leaves the previous folder as it was.
    """
    with FolderUpdate(folder, force) as update:
        update.stage(files)
        return update.commit()


def refuse_non_regular(path: Path) -> None:
    """Refuse to replace ``path`` when it exists and is not a regular file (never a device node).

    A rename over a device (``/dev/full``), a named pipe or a socket would
    put a regular file in its place; a symbolic link is refused too (the
    rename would replace the link, not what it points to).
    """
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISREG(mode):
        return
    what = ("a symbolic link" if stat.S_ISLNK(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a named pipe" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
    raise ModelError(f"{path}: is {what}, and modelgen replaces only regular files (even with --force): "
                     "move it away or give another --out")


def write_text_atomically(path: Path, text: str) -> Path:
    """Write one file through a temporary file and a rename: readers see the old or the new text, never a part."""
    return write_bytes_atomically(path, text.encode("utf-8"))


def write_bytes_atomically(path: Path, data: bytes, mode: int = 0o666) -> Path:
    """:func:`write_text_atomically` for bytes; ``mode`` (less the umask) is the file's permissions (0o755 for a library)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir() and not path.is_symlink():
        raise OSError(errno.EISDIR, "is a folder, not a file", str(path))
    refuse_non_regular(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, mode & ~current_umask())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None:  # a write or close into a full disk names no file: name the one being written
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


#: Lock and staging names inside a report folder.
REPORT_LOCK = ".modelgen.lock"
REPORT_STAGING_PREFIX = f".{STAGING_INFIX}"
#: The commit record of a report folder: which staging folder is being moved in, and each file's sha256.
REPORT_COMMIT_RECORD = ".modelgen-commit.json"


def _write_commit_record(folder: Path, staging: Path, files: Mapping[str, str]) -> None:
    """Record, before the first file moves, what the commit will move (written atomically: whole or absent)."""
    body = {"staging": staging.name, "files": dict(sorted(files.items()))}
    write_text_atomically(folder / REPORT_COMMIT_RECORD, json.dumps(body, indent=2, sort_keys=True) + "\n")


def _finish_commit(folder: Path, staging: Path, files: Mapping[str, str], manifest: dict[str, str]) -> None:
    """Move every staged file still in ``staging`` into ``folder``, then the manifest; remove the record and the staging folder.

    The same steps finish a commit whose process was killed halfway
    (:func:`recover_report_commit`): the files already moved are not in
    ``staging`` any more, the rest move now, so the folder ends holding the
    whole new report, never a mix of two runs.
    """
    for rel in files:
        source, target = staging / rel, folder / rel
        if not (source.exists() or source.is_symlink()):
            continue  # moved before the kill
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)  # only planned with force
        os.replace(source, target)
    manifest = {**manifest, **files}
    kept = {k: v for k, v in manifest.items() if (folder / k).is_file()}
    body = {"generator": "modelgen", "version": __version__, "files": dict(sorted(kept.items()))}
    write_text_atomically(folder / MANIFEST_NAME, json.dumps(body, indent=2, sort_keys=True) + "\n")
    (folder / REPORT_COMMIT_RECORD).unlink(missing_ok=True)
    shutil.rmtree(staging, ignore_errors=True)


def recover_report_commit(folder: Path) -> bool:
    """Finish the commit of a report writer that was killed while moving its files in (call with the lock held).

    True if a commit was finished.  A record that cannot be read (it is
    written atomically, so only a hand edit makes one) or names no staging
    folder of this folder is removed, and the staging leftovers with it.
    """
    record = Path(folder) / REPORT_COMMIT_RECORD
    if not record.is_file():
        return False
    try:
        body = json.loads(record.read_text(encoding="utf-8"))
        staging = Path(folder) / body["staging"]
        files = {_safe_relative(record, str(k)): str(v) for k, v in dict(body["files"]).items()}
        if not body["staging"].startswith(REPORT_STAGING_PREFIX) or "/" in body["staging"] or not staging.is_dir():
            raise ValueError("no staging folder")
    except (ValueError, KeyError, TypeError, AttributeError, ModelError):
        record.unlink(missing_ok=True)
        return False
    try:
        manifest = read_manifest(Path(folder)) or {}
    except ModelError:
        manifest = {}
    with signals_held():
        _finish_commit(Path(folder), staging, files, manifest)
    return True


def _owned_unchanged(folder: Path, rel: str) -> bool:
    """True if ``folder/rel`` is a file modelgen wrote and nobody edited: a manifest in one of its parents lists its hash."""
    target = folder / rel
    if not target.is_file() or target.is_symlink():
        return False
    digest = sha256_file(target)
    target = target.absolute()
    for level in target.parents:  # a report written inside another (covariance/ inside run's report/) counts
        try:
            manifest = read_manifest(level) or {}
        except (ModelError, OSError):
            manifest = {}
        if manifest.get(target.relative_to(level).as_posix()) == digest:
            return True
    return False


class ReportUpdate:
    """Write a report folder through a staging folder inside it, then merge the new files in.

    Reports share their folder with whatever else is there (``--out .`` is
    allowed), so unlike ``FolderUpdate`` nothing is carried or removed: the
    new files are renamed into place one by one, a file of the same name is
    replaced only if modelgen wrote it and it was not edited since (or with
    ``force``), and the folder's manifest lists every report file modelgen
    wrote.  All or nothing: before the first file moves, a commit record
    (``.modelgen-commit.json``: the staging folder and each file's sha256)
    is written atomically; a writer killed while moving (SIGKILL: nothing
    runs) leaves the record, and the next writer of the folder finishes the
    commit before anything else, so the folder never stays a mix of two
    runs.  Staging, lock (``.modelgen.lock``) and, if modelgen made the
    folder and wrote nothing, the folder itself are removed on the way out.
    """

    def __init__(self, folder: Path, force: bool = False) -> None:
        self.folder = Path(folder)
        self.force = force
        self.staging: Path | None = None
        self._created = False
        self._lock = None

    def __enter__(self) -> "ReportUpdate":
        if self.folder.exists() and not self.folder.is_dir():
            raise OSError(errno.ENOTDIR, "exists and is not a folder", str(self.folder))
        self._created = not self.folder.exists()
        self.folder.mkdir(parents=True, exist_ok=True)
        self._lock = folder_lock(self.folder, self.folder / REPORT_LOCK)
        self._lock.__enter__()
        try:
            recover_report_commit(self.folder)
            for leftover in self.folder.glob(f"{REPORT_STAGING_PREFIX}*"):
                if leftover.is_dir() and not leftover.is_symlink():
                    shutil.rmtree(leftover)
            self.staging = Path(tempfile.mkdtemp(prefix=REPORT_STAGING_PREFIX, dir=self.folder))
            _apply_umask_to_folder(self.staging)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        _name_final_file(exc_info[1] if len(exc_info) > 1 else None, self.staging, self.final)
        try:
            self.staging = _discard_staging(self.staging)
        finally:
            self._lock.__exit__(*exc_info)
            if self._created and self.folder.is_dir() and not any(self.folder.iterdir()):
                self.folder.rmdir()

    def final(self, path: Path | str) -> Path:
        """Where a file written into the staging folder will be once committed."""
        return self.folder / Path(path).relative_to(self.staging)

    def commit(self) -> list[Path]:
        """Check that no file of the user's would be replaced, then move the staged files in; their final paths."""
        staged = sorted(
            p.relative_to(self.staging).as_posix() for p in self.staging.rglob("*") if p.is_file() or p.is_symlink()
        )
        for rel in staged:
            target = self.folder / rel
            exists = target.exists() or target.is_symlink()
            if exists and not (target.is_dir() and not target.is_symlink()):
                refuse_non_regular(target)  # a device, pipe or link in the report folder is never replaced, even with --force
            if exists and not self.force and (target.is_dir() or not _owned_unchanged(self.folder, rel)):
                raise ModelError(
                    f"{target}: was not written by modelgen, or was edited since; move it away, "
                    "choose another folder with --out, or pass --force to overwrite it"
                )
            for parent in list(PurePosixPath(rel).parents)[:-1]:
                if (self.folder / parent).exists() and not (self.folder / parent).is_dir():
                    raise ModelError(f"{self.folder / parent}: is a file where the report needs a folder")
        try:
            manifest = read_manifest(self.folder) or {}
        except ModelError:
            if not self.force:
                raise
            manifest = {}
        files = {rel: sha256_file(self.staging / rel) for rel in staged}
        staging = self.staging
        with signals_held():
            _write_commit_record(self.folder, staging, files)
            self.staging = None  # the record owns it now: a commit cut short is finished by the next writer
            _finish_commit(self.folder, staging, files, manifest)
        return [self.folder / rel for rel in staged]
