"""How much parallelism a test may use itself, beside the suite's pytest-xdist workers.

The suite runs one xdist worker per core (pyproject.toml, ``-n auto``): a test
that compiles or runs things side by side (a thread pool) takes its share of
the cores, not all of them, so that the machine is not oversubscribed.
"""

from __future__ import annotations

import os


def cores_per_worker() -> int:
    """The cores of this machine divided among the xdist workers of this run (at least 1; all of them without xdist)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    return max(1, cores // max(1, workers))
