"""A machine's cache of whole trajectories: a Monte Carlo worker maps the truth and ideal increments, not makes them.

Every run of a Monte Carlo study flies the same truth and the same ideal IMU
increments (only the sensor errors differ), and every worker of the study
needs them before its first run: 0.7 s of compiled code for a 1-h flight at
300 Hz, the largest part of a fresh worker's set-up.  :func:`cached_trajectory`
keeps them on disk, next to the compile cache of :mod:`modelgen.codegen.build`
(folder ``trajectories`` of ``$MODELGEN_CACHE_DIR``, else
``$XDG_CACHE_HOME/modelgen``, else ``~/.cache/modelgen``), so the workers of
one machine make a flight once and later studies of it not at all; each maps
the entry read-only (the pages are shared by the workers, not copied).

An entry is keyed by a digest of what the arrays are a function of: the
flight path (start state and segments, floats exactly), the IMU and record
rates, the source of the modules that compute them (a modelgen with other
trajectory maths makes other entries), the versions of numpy, numba and
Python, the machine, C library and byte order (float results of compiled
code and libm).  An entry is a header (magic line, then JSON: key, array
shapes and a CRC-32 of the arrays) padded to :data:`HEADER_BYTES`, then the
arrays in native byte order.  It is written to a temporary file and
hard-linked to its name, which never replaces a file: two workers making
the same entry both succeed and one entry stays.  A file at an entry's name
that does not verify (cut short, damaged, not modelgen's) is left alone and
the next name used.  The CRC detects a damaged entry, not a forged one:
whoever can write this folder can also write the compiled libraries beside
it.  Entries larger than :data:`MAX_ENTRY_BYTES` are not kept (made in
memory each time).  Nothing here deletes a file but its own temporary one.

Whatever the path, the trajectory returned holds read-only arrays, so a
compiled function sees one array type (an entry's map and a trajectory made
in memory alike) and nothing can change what other runs read.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import platform
import sys
import zlib
from pathlib import Path

import numpy as np

from modelgen.codegen.build import library_cache_folder
from modelgen.fileio.cache_entry import link_new_entry
from modelgen.fileio.cache_eviction import keep_within_cap, mark_used
from modelgen.simulation import earth, jit, rotation, trajectory as trajectory_module
from modelgen.simulation.trajectory import TRUTH_COLUMNS, FlightPath, Trajectory, generate_trajectory, sample_counts

#: First line of every entry; a new layout of entries changes the number.
ENTRY_MAGIC = b"modelgen-trajectory-cache 1\n"
#: Bytes of an entry before its arrays (magic and JSON, padded with spaces; a page, so the arrays are aligned).
HEADER_BYTES = 4096
#: Names tried for one key: a file at a name that does not verify is left alone and the next is used.
ENTRY_NAMES = 4
#: Larger entries are not kept (a day at 300 Hz is 1.2 GB): made in memory each time.
MAX_ENTRY_BYTES = 512 * 2**20
#: The modules whose code computes a trajectory's numbers (their source is part of the key).
SOURCES = (trajectory_module, earth, rotation, jit)


def trajectory_cache_folder() -> Path:
    """The folder of cached trajectories: ``trajectories`` beside the compile cache's ``libraries``."""
    return library_cache_folder().parent / "trajectories"


def _code_identity() -> str:
    """What else the arrays depend on: the computing modules' source, library versions, machine, libm, byte order."""
    digest = hashlib.sha256()
    for module in SOURCES:
        source = Path(module.__file__).read_bytes()
        digest.update(f"{module.__name__} {len(source)}\n".encode("utf-8"))
        digest.update(source)
    numba_version = jit._numba.__version__ if jit.HAVE_NUMBA else "none"
    return json.dumps({"sources": digest.hexdigest(), "numpy": np.__version__, "numba": numba_version,
                       "python": sys.version, "machine": platform.machine(), "libc": platform.libc_ver(),
                       "byteorder": sys.byteorder})


def trajectory_key(path: FlightPath, imu_rate: float, record_rate: float) -> str:
    """Digest of everything an entry's arrays are a function of (module docstring); every field of the path,
    so a field added to :class:`FlightPath` or :class:`Segment` is in the key without a change here."""
    digest = hashlib.sha256(ENTRY_MAGIC)
    digest.update(json.dumps({"flight": dataclasses.asdict(path), "imu_rate": float(imu_rate), "record_rate": float(record_rate),
                              "code": _code_identity()}).encode("utf-8"))  # floats as their shortest exact text
    return digest.hexdigest()


def _shapes(n_samples: int, record_every: int) -> dict[str, tuple[int, int]]:
    """Shapes of an entry's arrays, in file order."""
    return {"truth": (n_samples // record_every + 1, len(TRUTH_COLUMNS)), "delta_theta": (n_samples, 3),
            "delta_velocity": (n_samples, 3)}


def _crc(arrays: list[np.ndarray]) -> int:
    """CRC-32 of the arrays' bytes, one after another."""
    crc = 0
    for array in arrays:
        crc = zlib.crc32(memoryview(np.ascontiguousarray(array)).cast("B"), crc)
    return crc


def _header(key: str, shapes: dict[str, tuple[int, int]], crc: int) -> bytes:
    text = ENTRY_MAGIC + json.dumps({"key": key, "shapes": shapes, "crc32": crc}).encode("ascii") + b"\n"
    if len(text) > HEADER_BYTES:
        raise ValueError("trajectory cache: header longer than its block")
    return text.ljust(HEADER_BYTES, b" ")


def entry_paths(folder: Path, key: str) -> list[Path]:
    """The names one key's entry may have, in the order tried."""
    return [folder / (f"{key}.trajectory" if k == 0 else f"{key}.{k}.trajectory") for k in range(ENTRY_NAMES)]


def _mapped(path: Path, key: str, shapes: dict[str, tuple[int, int]]) -> list[np.ndarray] | None:
    """The arrays of the entry at ``path``, mapped read-only, if it is a whole entry of ``key``; else None."""
    try:
        if not path.is_file():  # a folder or a pipe at an entry's name is not an entry (and is never opened)
            return None
        with path.open("rb") as handle:
            header = handle.read(HEADER_BYTES)
        size = path.stat().st_size
    except OSError:
        return None
    if len(header) != HEADER_BYTES or not header.startswith(ENTRY_MAGIC):
        return None
    try:
        fields = json.loads(header[len(ENTRY_MAGIC):].decode("ascii"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None
    expected = {name: list(shape) for name, shape in shapes.items()}
    if not isinstance(fields, dict) or fields.get("key") != key or fields.get("shapes") != expected:
        return None
    count = sum(rows * columns for rows, columns in shapes.values())
    if size != HEADER_BYTES + 8 * count:
        return None
    try:
        flat = np.memmap(path, dtype=np.float64, mode="r", offset=HEADER_BYTES, shape=(count,))
    except (OSError, ValueError):
        return None
    arrays, start = [], 0
    for rows, columns in shapes.values():
        arrays.append(flat[start:start + rows * columns].reshape(rows, columns))
        start += rows * columns
    if fields.get("crc32") != _crc(arrays):
        return None
    return [np.asarray(a) for a in arrays]  # plain read-only ndarrays over the map (numba types them as such)


def _store(folder: Path, key: str, arrays: list[np.ndarray], shapes: dict[str, tuple[int, int]]) -> list[np.ndarray] | None:
    """Keep ``arrays`` as the entry of ``key``; the entry's arrays, mapped, or None if it could not be kept.

    Written to a temporary file and hard-linked to the first free name (never
    replacing a file); an entry of the same key linked first by another
    worker is used.  Only the temporary file, ours, is removed.  The cache
    is then kept within its size cap, least recently used entries first
    (:func:`modelgen.fileio.cache_eviction.keep_within_cap`).
    """
    def write(handle) -> None:
        handle.write(_header(key, shapes, _crc(arrays)))
        for array in arrays:
            handle.write(memoryview(np.ascontiguousarray(array)).cast("B"))

    def accept(path: Path) -> tuple[Path, list[np.ndarray]] | None:
        mapped = _mapped(path, key, shapes)
        return None if mapped is None else (path, mapped)

    kept = link_new_entry(folder, key, write, entry_paths(folder, key), accept)
    if kept is None:
        return None
    keep_within_cap(folder.parent, stored=kept[0])
    return kept[1]


def _read_only(arrays: list[np.ndarray]) -> list[np.ndarray]:
    for array in arrays:
        array.flags.writeable = False
    return arrays


def cached_trajectory(path: FlightPath, imu_rate: float, record_rate: float, folder: Path | None = None) -> Trajectory:
    """``generate_trajectory(path, imu_rate, record_rate)`` (held), from the cache when it holds the flight.

    A miss makes the trajectory and keeps it (unless larger than
    :data:`MAX_ENTRY_BYTES` or the folder cannot be written: then it is
    returned from memory).  Bit for bit the arrays of
    :func:`~modelgen.simulation.trajectory.generate_trajectory`, read-only.
    ``folder``: the cache folder (default :func:`trajectory_cache_folder`).
    """
    n_samples, record_every = sample_counts(path, imu_rate, record_rate)
    shapes = _shapes(n_samples, record_every)
    folder = trajectory_cache_folder() if folder is None else folder
    key = trajectory_key(path, imu_rate, record_rate)
    arrays = None
    for entry in entry_paths(folder, key):
        if entry.exists():
            arrays = _mapped(entry, key, shapes)
            if arrays is not None:
                mark_used(entry)
                break
    if arrays is None:
        made = generate_trajectory(path, imu_rate, record_rate)
        arrays = [made.truth, made.delta_theta, made.delta_velocity]
        if HEADER_BYTES + sum(8 * a.size for a in arrays) <= MAX_ENTRY_BYTES:
            arrays = _store(folder, key, arrays, shapes) or arrays
    truth, delta_theta, delta_velocity = _read_only(arrays)
    return Trajectory(path, float(imu_rate), record_every, delta_theta, delta_velocity, truth)
