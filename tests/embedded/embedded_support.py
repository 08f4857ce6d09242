"""Shared helpers of the embedded tests: tool checks and generated folders."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path

import pytest

from modelgen.codegen import toolchain
from modelgen.codegen.build import compiler

PACKAGES = "Debian packages gcc-arm-none-eabi libnewlib-arm-none-eabi gcc-arm-linux-gnueabihf qemu-user cppcheck (.ci/run installs them)"


#: In CI (.ci/run installs the toolchain) a missing tool is a failure, never a skip.
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require_tools(*names: str):
    """A skip marker naming the missing tools; the tests run wherever they are installed, and always in CI."""
    missing = toolchain.missing_tools(*names)
    return pytest.mark.skipif(
        bool(missing) and not IN_CI, reason=f"toolchain absent locally: {', '.join(missing)} missing; install {PACKAGES}"
    )


@lru_cache(maxsize=1)
def sanitizers_available() -> bool:
    """Whether the host compiler can build and run an ASan + UBSan program."""
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "probe.c"
        source.write_text("int main(void) { return 0; }\n")
        exe = Path(tmp) / "probe"
        try:
            built = subprocess.run([compiler(), *toolchain.SANITIZER_FLAGS, "-o", str(exe), str(source)], capture_output=True)
        except Exception:
            return False
        return built.returncode == 0 and subprocess.run([str(exe)]).returncode == 0


def in_parallel(function, items):
    """map over this xdist worker's share of the cores (tests/parallel_support.py)."""
    from tests.parallel_support import cores_per_worker

    with ThreadPoolExecutor(max_workers=cores_per_worker()) as pool:
        return list(pool.map(function, items))


def have(*names: str) -> bool:
    return all(shutil.which(n) for n in names)
