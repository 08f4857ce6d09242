"""The navigator on ARM: a Cortex-M4F build with a single-precision filter, and the drive under qemu-arm.

Precision split (a design decision, stated in the report): the error-state
filter -- nearly all of the arithmetic (discretize, predict, update) -- is
generated in single precision (``CodegenOptions(scalar="float")``, the FPU's
format); the mechanization keeps latitude, longitude, height, velocity and
attitude in double, because a float latitude resolves only 1e-7 rad (0.6 m)
and a 100 Hz integration of float velocity increments loses centimetres per
minute.  On the Cortex-M4F that double part is software floating point (a few
hundred operations per IMU sample).

:func:`embedded_replay` builds both, runs the whole drive under qemu-arm
(arm-linux-gnueabihf, static) and compares every output epoch's antenna
position with the double-precision C navigator on the host.
"""

from __future__ import annotations

import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import numpy as np

from modelgen.version import __version__
from modelgen.codegen import toolchain
from modelgen.codegen.build import STRICT_FLAGS
from modelgen.codegen.generate import generate_code, harness_folder
from modelgen.codegen.options import CodegenOptions
from modelgen.errors import ModelError
from modelgen.navigator import cconfig
from modelgen.navigator.cnav import N_OUTPUT, REST_MAX, WINDOW_MAX, LogArrays, capacity_defines, render_navigator
from modelgen.navigator.spec import NavigatorSpec

MAX_IMU, MAX_EPOCHS, MAX_AID = 60000, 2500, 60000
CORTEX_M4F_COMMON = (*toolchain.CORTEX_M4F_FLAGS, "-O2", "-fno-math-errno", "-ffunction-sections", "-fdata-sections",
                     "-fstack-usage", "-fcallgraph-info=su")


@dataclass
class EmbeddedReplay:
    """Sizes, stack and the float-against-double comparison over the log."""

    text: int
    data: int
    bss: int
    navigator_struct_bytes: int
    worst_case_stack: dict[str, int]
    forbidden_symbols: list[str]
    max_position_difference_m: float
    outage_end_differences_m: list[float] = field(default_factory=list)


def write_sources(spec: NavigatorSpec, folder: Path) -> str:
    """Float filter, navigator and qemu driver sources into ``folder`` (the spec's derived model); the model name."""
    name = spec.name
    folder.mkdir(parents=True, exist_ok=True)
    for file_name, text in generate_code(spec.derived, CodegenOptions(scalar="float")).files.items():
        if file_name.endswith((".c", ".h")):
            (folder / file_name).write_text(text)
    for file_name, text in render_navigator(spec).items():
        (folder / file_name).write_text(text)
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(harness_folder())), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True)
    driver = env.get_template("navigator_driver.c.j2").render(p=name, P=name.upper(), version=__version__,
                                                              max_imu=MAX_IMU, max_epochs=MAX_EPOCHS, max_aid=MAX_AID)
    (folder / "navigator_driver.c").write_text(driver)
    return name


def encode(a: LogArrays) -> bytes:
    """The driver's stdin (layout in modelgen/codegen/backends/c/harness/navigator_driver.c.j2)."""
    if len(a.time) > MAX_IMU or len(a.t_gnss) > MAX_EPOCHS or len(a.aid_time) > MAX_AID:
        raise ModelError(f"embedded replay: the driver holds at most {MAX_IMU} IMU samples, {MAX_EPOCHS} epochs and "
                         f"{MAX_AID} aiding samples (this log: {len(a.time)}, {len(a.t_gnss)}, {len(a.aid_time)})")
    config = cconfig.pack(a.cfg, a.n_parameters)
    parts = [struct.pack("<4q", len(a.time), len(a.t_gnss), len(config), len(a.aid_time)), config]
    for array in (a.time, a.force, a.rate, a.t_gnss, a.target.astype(float), a.use.astype(float), a.gnss,
                  a.aid_time, a.aid_slot.astype(float), a.aid_value):
        parts.append(np.ascontiguousarray(array, dtype="<f8").tobytes())
    return b"".join(parts)


def cortex_m4f_build(folder: Path, name: str, out_dir: Path,
                     rest_max: int = REST_MAX,
                     window_max: int = WINDOW_MAX) -> tuple[toolchain.SectionSizes, dict[str, int], list[str]]:
    """Compile filter and navigator for the Cortex-M4F: sizes, worst-case stack of the two calls, heap symbols.

    ``rest_max``, ``window_max``: the alignment ring and detector window the configuration needs
    (:func:`modelgen.navigator.cnav.rest_capacity`, :func:`~modelgen.navigator.cnav.window_capacity`), passed as
    ``-D<P>_NAV_REST_MAX`` and ``-D<P>_NAV_WINDOW_MAX`` as to the host build, so that the sizes are those of the
    navigator that flies.
    """
    objects = []
    for source in (f"{name}.c", f"{name}_navigator.c"):
        obj = out_dir / source.replace(".c", ".o")
        toolchain.run([toolchain.ARM_EMBEDDED_CC, *STRICT_FLAGS, *CORTEX_M4F_COMMON, *capacity_defines(name, rest_max, window_max),
                       "-I", str(folder), "-c", "-o",
                       str(obj), str(folder / source)], f"Cortex-M4F compile of {source}")
        objects.append(obj)
    sizes = [toolchain.section_sizes(o) for o in objects]
    total = toolchain.SectionSizes(sum(s.text for s in sizes), sum(s.data for s in sizes), sum(s.bss for s in sizes))
    frames, edges = toolchain.read_stack_usage(out_dir)
    stack = {f: size for f, (size, _) in frames.items()}
    worst = {f"{name}_navigator_{call}": toolchain.worst_case_stack(f"{name}_navigator_{call}", stack, edges)
             for call in ("imu", "epoch")}
    nm = toolchain.run(["arm-none-eabi-nm", "-u", *map(str, objects)], "arm-none-eabi-nm").stdout.decode()
    forbidden = sorted({s for s in toolchain.FORBIDDEN_SYMBOLS for line in nm.split() if line == s})
    return total, worst, forbidden


def embedded_replay(spec: NavigatorSpec, arrays: LogArrays, reference: np.ndarray,
                    outage_ends: list[int] | None = None) -> EmbeddedReplay:
    """Build for Cortex-M4F and for qemu-arm, fly ``arrays`` under qemu, compare with ``reference`` outputs."""
    missing = toolchain.missing_tools(toolchain.ARM_EMBEDDED_CC, toolchain.ARM_LINUX_CC, toolchain.QEMU_ARM)
    if missing:
        raise ModelError(f"embedded replay needs {', '.join(missing)}")
    from modelgen.navigator.cnav import capacities
    from modelgen.navigator.mechanization import radii

    built = capacities(arrays.rest_max, arrays.window_max)  # the buffers this build gets
    refused = cconfig.check(arrays.cfg, built)  # the C's own check, before a build
    if refused is not None:
        raise ModelError(f"embedded replay: the C navigator refuses its configuration field {refused.name} = "
                         f"{arrays.cfg[refused.name]!r}: it must be {cconfig.describe(refused, built)}")

    with tempfile.TemporaryDirectory(prefix="modelgen-nav-arm-") as work:
        folder, build = Path(work) / "src", Path(work) / "m4"
        build.mkdir()
        name = write_sources(spec, folder)
        sizes, worst, forbidden = cortex_m4f_build(folder, name, build, arrays.rest_max, arrays.window_max)
        exe = Path(work) / "navigator_arm"
        toolchain.run([toolchain.ARM_LINUX_CC, *STRICT_FLAGS, "-O2", "-static",
                       *capacity_defines(name, arrays.rest_max, arrays.window_max),
                       "-I", str(folder), "-o", str(exe),
                       str(folder / f"{name}.c"), str(folder / f"{name}_navigator.c"),
                       str(folder / "navigator_driver.c"), "-lm"], "arm-linux-gnueabihf build of the navigator")
        result = toolchain.run_driver(exe, [], stdin=encode(arrays), qemu=True, timeout=600.0)
        struct_size = _struct_size(folder, name, Path(work), arrays.rest_max, arrays.window_max)
    out = np.frombuffer(result.stdout, dtype="<f8")
    if out.size != N_OUTPUT * len(arrays.t_gnss):
        raise ModelError(f"embedded replay: the driver wrote {out.size} values, expected {N_OUTPUT * len(arrays.t_gnss)}")
    out = out.reshape(-1, N_OUTPUT)
    out = out[~np.isnan(out[:, 0])][: len(reference)]  # the navigator aligns itself: no record before
    if len(out) != len(reference) or not np.array_equal(out[:, 0], reference[:, 0]):
        raise ModelError("embedded replay: the qemu-arm run's output epochs differ from the reference's "
                         f"({len(out)} records against {len(reference)})")
    rm, rn = radii(float(reference[0, 1]))
    north = (out[:, 1] - reference[:, 1]) * rm
    east = (out[:, 2] - reference[:, 2]) * rn * np.cos(reference[:, 1])
    up = out[:, 3] - reference[:, 3]
    distance = np.sqrt(north**2 + east**2 + up**2)
    return EmbeddedReplay(sizes.text, sizes.data, sizes.bss, struct_size, worst, forbidden, float(distance.max()),
                          [float(distance[i]) for i in (outage_ends or [])])


def _struct_size(folder: Path, name: str, work: Path, rest_max: int = REST_MAX, window_max: int = WINDOW_MAX) -> int:
    """sizeof the navigator struct on the Cortex-M4F (float filter), from a compile-time constant in an object."""
    probe = work / "probe.c"
    probe.write_text(f'#include "{name}_navigator.h"\nconst unsigned long navigator_bytes = sizeof({name}_navigator);\n')
    obj = work / "probe.o"
    toolchain.run([toolchain.ARM_EMBEDDED_CC, *toolchain.CORTEX_M4F_FLAGS, "-std=c99", *capacity_defines(name, rest_max, window_max),
                   "-I", str(folder), "-c", "-o",
                   str(obj), str(probe)], "struct size probe")
    out = toolchain.run(["arm-none-eabi-objdump", "-s", "-j", ".rodata", str(obj)], "objdump").stdout.decode()
    words = [line.split()[1] for line in out.splitlines() if line.startswith(" 0000")]
    if not words:
        raise ModelError("embedded replay: could not read the navigator struct size")
    return int.from_bytes(bytes.fromhex(words[0]), "little")
