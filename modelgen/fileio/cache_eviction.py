"""A size cap on modelgen's on-disk caches: the least recently used entries go first, and only entries.

The compile cache, the generated files and the trajectory cache
(``libraries``, ``generated`` and ``trajectories`` under
``$MODELGEN_CACHE_DIR``, else ``$XDG_CACHE_HOME/modelgen``, else
``~/.cache/modelgen``) gain an entry for every new model, option set and
flight; a trajectory of a long flight is hundreds of megabytes.  After a
process stores an entry, :func:`keep_within_cap` removes the least recently
used entries of the whole cache until the entries together fit in the cap:
``$MODELGEN_CACHE_MAX_MB`` megabytes (2**20 bytes), :data:`DEFAULT_CAP_MB`
when unset, no cap for ``0``.  An entry's modification time is its last use:
a cache that takes an entry marks it (:func:`mark_used`).

Only entries are ever removed: a regular file of one of the three folders
whose name is an entry name (a 64-digit hexadecimal key, ``navigator-`` first
for a compiled navigator's, an optional ``.k`` for the further names a key
may use, then the kind's suffix) and
whose first bytes are the kind's magic line (:data:`KINDS`; any layout
version of it, so that entries an older modelgen left behind are counted
and removed too).  Any other file, a folder, a link, a temporary file being
written, is neither counted nor touched.  The entry just stored is kept
even if it alone is larger than the cap.  Removing an entry another process
has mapped or opened is safe (POSIX keeps the file until it is closed); a
process that looks for an entry removed meanwhile makes it again.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from modelgen.errors import ModelError

#: Environment variable: the cap in megabytes (2**20 bytes); 0 for no cap.
CAP_ENV = "MODELGEN_CACHE_MAX_MB"
#: The cap when the variable is unset: room for a few long flights and many compiled filters.
DEFAULT_CAP_MB = 4096


@dataclass(frozen=True)
class EntryKind:
    """Entries of one cache folder: their names end with ``suffix`` and their files start with ``magic``."""

    folder: str
    suffix: str
    magic: bytes


#: Every kind of entry under the cache root (the magic lines without their layout number).
KINDS = (
    EntryKind("libraries", ".lib", b"modelgen-library-cache "),
    EntryKind("generated", ".lib", b"modelgen-library-cache "),
    EntryKind("trajectories", ".trajectory", b"modelgen-trajectory-cache "),
)

#: An entry's name without its suffix: a key (64 hexadecimal digits; a compiled navigator's key
#: says what it is, ``navigator-`` first) and the further names a key may use (``.k``).
_ENTRY_NAME = re.compile(r"(navigator-)?[0-9a-f]{64}(\.[0-9]+)?")


@dataclass(frozen=True)
class CachedEntry:
    """One entry on disk: its path, size in bytes and last use (modification time, ns)."""

    path: Path
    size: int
    used_ns: int


def cap_bytes() -> int | None:
    """The cap from :data:`CAP_ENV` in bytes (None: no cap); a value that is not a whole number >= 0 is refused."""
    text = os.environ.get(CAP_ENV, "").strip()
    if not text:
        return DEFAULT_CAP_MB * 2**20
    megabytes = int(text) if re.fullmatch(r"[0-9]{1,12}", text) else -1  # ASCII digits only: not "+5", "1_000", "-0"
    if megabytes < 0:
        raise ModelError(f"${CAP_ENV}={text!r}: the cache's size cap must be a whole number of megabytes "
                         f"(0 for no cap)")
    return megabytes * 2**20 if megabytes else None


def is_entry(path: Path, kind: EntryKind) -> bool:
    """Whether ``path`` is an entry of ``kind``: an entry's name, a regular file, the kind's magic first."""
    name = path.name
    if not name.endswith(kind.suffix) or not _ENTRY_NAME.fullmatch(name[:-len(kind.suffix)]):
        return False
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):  # a link or a folder at an entry's name is not ours
            return False
        with path.open("rb") as handle:
            return handle.read(len(kind.magic)) == kind.magic
    except OSError:
        return False


def cached_entries(root: Path, kinds: tuple[EntryKind, ...] = KINDS) -> list[CachedEntry]:
    """Every entry under ``root`` (module docstring), least recently used first."""
    found = []
    for kind in kinds:
        try:
            paths = list((root / kind.folder).iterdir())
        except OSError:
            continue
        for path in paths:
            if is_entry(path, kind):
                try:
                    status = os.lstat(path)
                except OSError:
                    continue
                found.append(CachedEntry(path, status.st_size, status.st_mtime_ns))
    return sorted(found, key=lambda entry: (entry.used_ns, entry.path.name))


def keep_within_cap(root: Path, stored: Path | None = None, cap: int | None = None,
                    kinds: tuple[EntryKind, ...] = KINDS) -> list[Path]:
    """Remove the least recently used entries under ``root`` until they fit in ``cap``; the paths removed.

    ``cap`` defaults to :func:`cap_bytes` (None: nothing is removed);
    ``stored`` (the entry just written) is never removed.  An entry that
    cannot be removed (gone already, no permission) is passed over.
    """
    cap = cap_bytes() if cap is None else cap
    if cap is None:
        return []
    entries = cached_entries(root, kinds)
    total = sum(entry.size for entry in entries)
    removed = []
    for entry in entries:
        if total <= cap:
            break
        if stored is not None and entry.path == stored:
            continue
        try:
            entry.path.unlink()
        except FileNotFoundError:
            pass  # another process removed it first
        except OSError:
            continue
        total -= entry.size
        removed.append(entry.path)
    return removed


def mark_used(path: Path) -> None:
    """Record a use of the entry at ``path`` (its modification time set to now); one it cannot mark stays as is."""
    try:
        os.utime(path)
    except OSError:
        pass
