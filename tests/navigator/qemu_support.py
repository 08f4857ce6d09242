"""The skip condition every qemu-arm navigator test shares: the ARM toolchain and qemu-arm, required in CI."""

from __future__ import annotations

import os

import pytest

from modelgen.codegen import toolchain


def arm_tools_missing() -> list[str]:
    """The cross compilers and qemu-arm that are not on PATH."""
    return toolchain.missing_tools(toolchain.ARM_EMBEDDED_CC, toolchain.ARM_LINUX_CC, toolchain.QEMU_ARM)


#: Skips locally without the tools; in CI (CI=1/true/yes) a missing tool fails the test instead.
needs_qemu_arm = pytest.mark.skipif(bool(arm_tools_missing()) and os.environ.get("CI", "").lower() not in ("1", "true", "yes"),
                                    reason="ARM toolchain or qemu-arm absent locally (CI installs them)")
