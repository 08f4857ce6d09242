"""One entry of an on-disk cache, written once and never replacing a file.

The compile cache (:mod:`modelgen.codegen.build`) and the trajectory cache
(:mod:`modelgen.simulation.trajectory_cache`) keep entries that several
processes may write at the same moment and that a user may have put a file of
their own beside.  An entry is therefore written to a temporary file of ours,
then hard-linked to the first of its candidate names that is free: a link
fails rather than replace a file, so an entry another process linked first is
used if it verifies, and a file that does not verify is left alone and the
next name tried.  Only the temporary file, ours, is ever removed.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, TypeVar

T = TypeVar("T")


def link_new_entry(folder: Path, key: str, write: Callable[[BinaryIO], None], names: Iterable[Path],
                   accept: Callable[[Path], T | None]) -> T | None:
    """Write an entry with ``write`` and link it to the first free name of ``names``; ``accept`` of the entry kept.

    ``accept(path)`` verifies the entry at ``path`` (ours just linked, or one
    already there) and returns what the caller uses, or None to try the next
    name.  None when no name yields an accepted entry or the cache cannot be
    written (read-only, no room, no hard links): the caller then goes on
    without the cache.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, temporary = tempfile.mkstemp(prefix=f".{key[:16]}-", suffix=".tmp", dir=folder)
    except OSError:
        return None
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        for path in names:
            try:
                os.link(temporary, path)
            except FileExistsError:
                pass  # another process's entry, or a file not ours: used if it verifies, else the next name
            except OSError:
                return None
            accepted = accept(path)
            if accepted is not None:
                return accepted
        return None
    except OSError:
        return None
    finally:
        Path(temporary).unlink(missing_ok=True)
