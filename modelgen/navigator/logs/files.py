"""Opening untrusted log files: size limits, gzip without decompression bombs, text decoding.

Every reader goes through here, so that an absurd file is one clear refusal
before anything large is allocated: a file (or a bag folder's files together)
larger than :data:`MAX_LOG_BYTES`, or a gzip stream that would expand beyond
it, is refused naming the file and the limit.
"""

from __future__ import annotations

import zlib
from pathlib import Path

from modelgen.errors import ModelError

#: Largest log modelgen reads, on disk and after gunzip [bytes] (2 GiB: a day of 200 Hz IMU as CSV).
MAX_LOG_BYTES = 2 * 1024**3
GZIP_MAGIC = b"\x1f\x8b"
_CHUNK = 1 << 20


def _mebibytes(n: int) -> str:
    return f"{n / 1024**2:.0f} MiB" if n >= 1024**2 else f"{n} bytes"


def check_size(path: Path, limit: int = MAX_LOG_BYTES) -> int:
    """The size of a file, or of all files under a folder; refused above ``limit``."""
    try:
        if path.is_dir():
            size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
        else:
            size = path.stat().st_size
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if size > limit:
        raise ModelError(f"{path}: {_mebibytes(size)} is larger than the {_mebibytes(limit)} a log may have")
    return size


def read_bytes(path: Path, limit: int = MAX_LOG_BYTES) -> bytes:
    """The file's bytes, gunzipped if they start with the gzip magic; refused above ``limit`` either way."""
    check_size(path, limit)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if raw[:2] != GZIP_MAGIC:
        return raw
    return _gunzip(path, raw, limit)


def _gunzip(path: Path, raw: bytes, limit: int) -> bytes:
    """Decompress every gzip member of ``raw`` in 1 MiB pieces, refusing beyond ``limit``."""
    parts: list[bytes] = []
    total = 0
    pending = raw
    try:
        while pending:
            stream = zlib.decompressobj(16 + zlib.MAX_WBITS)
            while True:
                piece = stream.decompress(pending, _CHUNK)
                total += len(piece)
                if total > limit:
                    raise ModelError(f"{path}: expands beyond the {_mebibytes(limit)} a log may have (gzip)")
                parts.append(piece)
                pending = stream.unconsumed_tail
                if stream.eof or (not piece and not pending):
                    break
            if not stream.eof:
                raise ModelError(f"{path}: is not a valid gzip file (the stream is cut short)")
            pending = stream.unused_data
            if pending and pending[:2] != GZIP_MAGIC:
                raise ModelError(f"{path}: is not a valid gzip file (data after the gzip stream)")
    except zlib.error as exc:
        raise ModelError(f"{path}: is not a valid gzip file ({exc})") from None
    return b"".join(parts)


def read_text(path: Path, limit: int = MAX_LOG_BYTES) -> str:
    """The file's UTF-8 text (gunzipped if gzip); refused if it is not UTF-8 text."""
    raw = read_bytes(path, limit)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{path}: is not UTF-8 text (byte {exc.start})") from None

