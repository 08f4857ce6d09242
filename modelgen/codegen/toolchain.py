"""The tools around the generated C: sanitizers, ARM cross compilers, qemu, cppcheck.

Everything here drives external programs that Debian packages provide
(``gcc``, ``gcc-arm-none-eabi`` + ``libnewlib-arm-none-eabi``,
``gcc-arm-linux-gnueabihf``, ``qemu-user``, ``cppcheck``, ``binutils``) on a
folder the generator wrote:

* a host build of the filter and the test driver (``c_test_driver.c.j2``) with
  AddressSanitizer and UndefinedBehaviorSanitizer;
* a static ``arm-linux-gnueabihf`` build of the same driver, run by
  ``qemu-arm``;
* a bare-metal Cortex-M4F image (``c_firmware_main.c.j2``: static storage, no
  heap, no I/O) whose link map, section sizes and worst-case stack are read
  back;
* cppcheck over the generated sources.

The scenario goes to the driver as raw native scalars on stdin and the state
after every step comes back the same way, so nothing is lost to printing.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.codegen.build import (
    STRICT_FLAGS, cached_library, compiler, compiler_identity, library_cache_folder, library_key, store_library,
)
from modelgen.codegen.generate import generate_code, render_c_template
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.output import write_atomically, write_bytes_atomically

ARM_EMBEDDED_CC = "arm-none-eabi-gcc"
ARM_EMBEDDED_SIZE = "arm-none-eabi-size"
ARM_LINUX_CC = "arm-linux-gnueabihf-gcc"
QEMU_ARM = "qemu-arm"
CPPCHECK = "cppcheck"
#: Cortex-M4F with its single-precision FPU, hard-float ABI, Thumb-2.
CORTEX_M4F_FLAGS = ("-mcpu=cortex-m4", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-mthumb")
SANITIZER_FLAGS = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g")
#: Symbols a no-heap, no-I/O image must not contain.
FORBIDDEN_SYMBOLS = ("malloc", "free", "calloc", "realloc", "printf", "sprintf", "fprintf", "puts", "_sbrk")
#: cppcheck: every check that is about the code (not about the checker's own
#: configuration).  ``missingIncludeSystem`` only says that cppcheck does not
#: read the system headers (<math.h>), which it never needs to.
CPPCHECK_ARGS = (
    "--enable=warning,style,performance,portability",
    "--std=c99",
    "--error-exitcode=1",
    "--inline-suppr",
    "--quiet",
    "--suppress=missingIncludeSystem",
)


def missing_tools(*names: str) -> list[str]:
    """The named programs that are not on PATH."""
    return [name for name in names if shutil.which(name) is None]


def run(command: list[str], what: str, stdin: bytes | None = None, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """Run ``command``; a non-zero exit raises ModelError with its output."""
    result = subprocess.run(command, input=stdin, capture_output=True, timeout=timeout)
    if result.returncode != 0:
        out = (result.stdout or b"")[-2000:].decode(errors="replace")
        err = (result.stderr or b"")[-4000:].decode(errors="replace")
        raise ModelError(f"{what} failed (exit {result.returncode}): {' '.join(command)}\n{out}\n{err}")
    return result


# -- sources -------------------------------------------------------------------
def write_filter(derived: DerivedModel, options: CodegenOptions, folder: Path) -> Path:
    """Generate the filter for ``options`` into ``folder`` and add the test driver."""
    files = dict(generate_code(derived, options).files)
    files["driver.c"] = render_c_template(derived, options, "c_test_driver.c.j2", **_driver_constants(options))
    files["firmware_main.c"] = render_c_template(derived, options, "c_firmware_main.c.j2", **_driver_constants(options))
    return write_atomically(Path(folder), files)


def _driver_constants(options: CodegenOptions) -> dict[str, str]:
    if options.scalar == "float":
        return {"huge": "1.0e38F", "tiny": "1.0e-39F", "half": "0.5F", "two": "2.0F"}
    return {"huge": "1.0e300", "tiny": "1.0e-310", "half": "0.5", "two": "2.0"}


# -- host and qemu builds --------------------------------------------------------
def build_host_driver(folder: Path, model: str, output: Path, flags: tuple[str, ...] = SANITIZER_FLAGS, optimization: str = "-O0") -> Path:
    """The driver and filter for this machine (by default with ASan + UBSan, unoptimized: fastest to
    build and what the sanitizers see most of)."""
    folder = Path(folder)
    run(
        [compiler(), *STRICT_FLAGS, optimization, *flags, "-I", str(folder), "-o", str(output), str(folder / f"{model}.c"), str(folder / "driver.c"), "-lm"],
        "host build of the test driver",
    )
    return Path(output)


def build_arm_linux_driver(folder: Path, model: str, output: Path) -> Path:
    """The driver and filter for arm-linux-gnueabihf, statically linked (for qemu-arm), through the compile cache.

    The executable is kept in the compile cache (:mod:`modelgen.codegen.build`)
    under a digest of the two sources, the headers beside them, the flags and
    the cross compiler's identity: the same filter flown over another scenario
    (the scenario is the driver's input, not its code) is not built again.
    """
    folder = Path(folder)
    sources = [folder / f"{model}.c", folder / "driver.c"]
    flags = [*STRICT_FLAGS, "-O2", "-static"]
    # -I is the sources' own folder, whose headers the key holds; its path is not part of what is built
    key = library_key(sources, [*flags, "-I<sources>", "-lm"], compiler_identity(ARM_LINUX_CC))
    cache = library_cache_folder()
    payload = cached_library(cache, key)
    if payload is not None:
        write_bytes_atomically(Path(output), payload, mode=0o755)
        return Path(output)
    run([ARM_LINUX_CC, *flags, "-I", str(folder), "-o", str(output), *map(str, sources), "-lm"], "arm-linux-gnueabihf build")
    store_library(cache, key, Path(output).read_bytes())
    return Path(output)


def run_driver(executable: Path, arguments: list[str], stdin: bytes | None = None, qemu: bool = False, timeout: float = 120.0) -> subprocess.CompletedProcess:
    """Run the driver natively or under qemu-arm; raises on a non-zero exit."""
    command = ([QEMU_ARM] if qemu else []) + [str(executable), *arguments]
    return run(command, f"driver {' '.join(arguments)}", stdin=stdin, timeout=timeout)


def encode_scenario(steps: int, parameters: np.ndarray, step: float, x0: np.ndarray, P0: np.ndarray, z: np.ndarray, scalar: str) -> bytes:
    """The driver's ``run`` input: steps, params, T, x0, P0, then z per step (native scalars)."""
    dtype = np.float32 if scalar == "float" else np.float64
    parts = [
        np.array([steps], dtype=np.int32).tobytes(),
        np.asarray(parameters, dtype=dtype).tobytes(),
        np.array([step], dtype=dtype).tobytes(),
        np.asarray(x0, dtype=dtype).tobytes(),
        np.ascontiguousarray(P0, dtype=dtype).tobytes(),
        np.ascontiguousarray(z, dtype=dtype).tobytes(),
    ]
    return b"".join(parts)


@dataclass(frozen=True)
class DriverStep:
    """One step of the driver's output: return codes, x, full P and (UD) D."""

    predict_status: int
    update_status: int
    x: np.ndarray
    P: np.ndarray
    D: np.ndarray | None


def decode_run(data: bytes, n: int, scalar: str, ud: bool) -> list[DriverStep]:
    """Split the driver's ``run`` output into steps."""
    dtype = np.dtype(np.float32 if scalar == "float" else np.float64)
    width = n + n * n + (n if ud else 0)
    record = 8 + width * dtype.itemsize
    if len(data) % record:
        raise ModelError(f"driver output of {len(data)} bytes is not a whole number of {record}-byte steps")
    steps = []
    for k in range(len(data) // record):
        chunk = data[k * record : (k + 1) * record]
        codes = np.frombuffer(chunk[:8], dtype=np.int32)
        values = np.frombuffer(chunk[8:], dtype=dtype).astype(float)
        steps.append(
            DriverStep(
                int(codes[0]),
                int(codes[1]),
                values[:n].copy(),
                values[n : n + n * n].reshape(n, n).copy(),
                values[n + n * n :].copy() if ud else None,
            )
        )
    return steps


# -- Cortex-M4F image -----------------------------------------------------------------
@dataclass(frozen=True)
class SectionSizes:
    """Berkeley sizes (bytes) as arm-none-eabi-size prints them."""

    text: int
    data: int
    bss: int


@dataclass
class FirmwareBuild:
    """What the bare-metal build produced and what was read back from it."""

    elf: Path
    map_file: Path
    image: SectionSizes
    filter_object: SectionSizes
    stack: dict[str, int] = field(default_factory=dict)  # per function, own frame (bytes)
    worst_case_stack: dict[str, int] = field(default_factory=dict)  # per function, with its callees
    unbounded: list[str] = field(default_factory=list)  # functions whose frame is dynamic
    forbidden_symbols: list[str] = field(default_factory=list)


def build_cortex_m4(folder: Path, model: str, out_dir: Path) -> FirmwareBuild:
    """Compile the filter and ``firmware_main.c`` for a Cortex-M4F and link a heap-free image.

    The filter itself is compiled with the strict flags; the firmware main
    (vector table, reset handler) without -pedantic, since a vector table
    needs an object-to-function pointer conversion.  -fno-math-errno lets
    sqrtf become the FPU's vsqrt.f32 instead of a libm call.
    """
    folder, out_dir = Path(folder), Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    common = [*CORTEX_M4F_FLAGS, "-O2", "-fno-math-errno", "-ffunction-sections", "-fdata-sections", "-fstack-usage", "-fcallgraph-info=su", "-Wdouble-promotion"]
    filter_obj, main_obj = out_dir / f"{model}.o", out_dir / "firmware_main.o"
    run([ARM_EMBEDDED_CC, *STRICT_FLAGS, *common, "-I", str(folder), "-c", "-o", str(filter_obj), str(folder / f"{model}.c")], "Cortex-M4F compile of the filter")
    run([ARM_EMBEDDED_CC, "-std=c99", "-Wall", "-Wextra", "-Werror", *common, "-I", str(folder), "-c", "-o", str(main_obj), str(folder / "firmware_main.c")], "Cortex-M4F compile of the firmware main")
    elf, map_file = out_dir / f"{model}_m4.elf", out_dir / f"{model}_m4.map"
    run(
        [ARM_EMBEDDED_CC, *CORTEX_M4F_FLAGS, "-nostartfiles", "--specs=nosys.specs", "-Wl,--gc-sections", "-Wl,-e,Reset_Handler",
         "-Wl,--undefined=firmware_vectors", f"-Wl,-Map={map_file}", "-o", str(elf), str(main_obj), str(filter_obj), "-lm"],
        "Cortex-M4F link",
    )
    build = FirmwareBuild(elf, map_file, section_sizes(elf), section_sizes(filter_obj))
    su, edges = read_stack_usage(out_dir)
    build.stack = {name: size for name, (size, _) in su.items()}
    build.unbounded = sorted(name for name, (_, kind) in su.items() if "dynamic" in kind and "bounded" not in kind)
    build.worst_case_stack = {name: worst_case_stack(name, build.stack, edges) for name in sorted(build.stack)}
    build.forbidden_symbols = forbidden_symbols_in_map(map_file)
    return build


def section_sizes(path: Path) -> SectionSizes:
    """.text, .data, .bss of an object or image (Berkeley format)."""
    out = run([ARM_EMBEDDED_SIZE, "-B", str(path)], "arm-none-eabi-size").stdout.decode()
    lines = [line.split() for line in out.strip().splitlines()]
    text, data, bss = (int(v) for v in lines[1][:3])
    return SectionSizes(text, data, bss)


def read_stack_usage(folder: Path) -> tuple[dict[str, tuple[int, str]], dict[str, set[str]]]:
    """Own frame sizes (from .su files) and call edges (from -fcallgraph-info .ci files)."""
    frames: dict[str, tuple[int, str]] = {}
    for su in sorted(Path(folder).glob("*.su")):
        for line in su.read_text().splitlines():
            location, size, kind = line.rsplit("\t", 2)
            frames[location.rsplit(":", 1)[-1]] = (int(size), kind)
    edges: dict[str, set[str]] = {}
    for ci in sorted(Path(folder).glob("*.ci")):
        for source, target in re.findall(r'edge:\s*\{\s*sourcename:\s*"([^"]+)"\s*targetname:\s*"([^"]+)"', ci.read_text()):
            edges.setdefault(source, set()).add(target)
    return frames, edges


def worst_case_stack(function: str, frames: dict[str, int], edges: dict[str, set[str]], _path: tuple[str, ...] = ()) -> int:
    """Own frame plus the deepest callee chain; a cycle (recursion) is an error.

    A callee without a frame record (a library routine) counts as 0 and is
    visible in the call graph; the generated code calls none.
    """
    if function in _path:
        raise ModelError(f"recursion through {' -> '.join((*_path, function))}: worst-case stack is unbounded")
    callees = edges.get(function, set())
    deepest = max((worst_case_stack(c, frames, edges, (*_path, function)) for c in callees), default=0)
    return frames.get(function, 0) + deepest


def forbidden_symbols_in_map(map_file: Path) -> list[str]:
    """Heap and stdio symbols that the linker pulled into the image."""
    text = Path(map_file).read_text(errors="replace")
    # only what was linked: the map's memory map, after the discarded-sections list
    linked = text.split("Linker script and memory map", 1)[-1]
    found = []
    for name in FORBIDDEN_SYMBOLS:
        if re.search(rf"(?<![\w.]){re.escape(name)}(?![\w])", linked):
            found.append(name)
    return found


# -- static analysis -------------------------------------------------------------------
def run_cppcheck(files: list[Path], include: Path, workers: int = 1) -> list[subprocess.CompletedProcess]:
    """cppcheck with CPPCHECK_ARGS over every preprocessor configuration it would check; raises ModelError on a finding.

    cppcheck checks each file once per configuration (each set of the
    symbols its ``#if`` lines test, ``""`` first), and some configurations
    preprocess to the same text (for the generated C: the lane-pair macro of
    a build without SSE2, every ``__SSE2_MATH__`` variant of a float filter).
    Each file's configurations are the ones cppcheck itself enumerates
    (:func:`cppcheck_configurations`); each distinct preprocessed text of a
    file is checked once, by cppcheck told that configuration
    (:func:`cppcheck_configuration_flags`), with ``workers`` checks at a time.
    """
    from concurrent.futures import ThreadPoolExecutor

    checks = []
    for file in map(Path, files):
        texts: dict[bytes, str] = {}
        for configuration in cppcheck_configurations(file, include):
            texts.setdefault(cppcheck_preprocessed(file, include, configuration), configuration)
        checks += [(file, configuration) for configuration in texts.values()]

    def check(item: tuple[Path, str]) -> subprocess.CompletedProcess:
        file, configuration = item
        return run([CPPCHECK, *CPPCHECK_ARGS, *cppcheck_configuration_flags(configuration), "-I", str(include), str(file)],
                   f"cppcheck ({configuration or 'no symbol defined'})")

    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        return list(pool.map(check, checks))


#: The lines a configuration depends on: preprocessor directives (a line continued with a backslash goes on).
_DIRECTIVE = re.compile(r"\s*#\s*(if|ifdef|ifndef|elif|else|endif|define|undef|include|error)\b")


def cppcheck_configurations(file: Path, include: Path) -> list[str]:
    """The configurations cppcheck checks ``file`` in (``""``: nothing defined), as it lists them itself.

    cppcheck enumerates them from the preprocessor directives of the file and
    of what it includes, before it checks anything; it is asked here about a
    copy of the files with every other line blank (the same directives on
    the same lines), which takes it a tenth of a second instead of seconds
    per configuration.
    """
    import tempfile

    file, include = Path(file).resolve(), Path(include).resolve()
    with tempfile.TemporaryDirectory(prefix="modelgen-cppcheck-") as name:
        root = Path(name)
        mirrors = {folder: root / f"d{i}" for i, folder in enumerate(dict.fromkeys([file.parent, include]))}
        for folder, mirror in mirrors.items():
            for source in [*folder.rglob("*.h"), *([file] if folder == file.parent else [])]:
                target = mirror / source.relative_to(folder)
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(_directives_only(source.read_text(encoding="utf-8", errors="replace")), encoding="utf-8")
        listed = run([CPPCHECK, "--std=c99", "-I", str(mirrors[include]), str(mirrors[file.parent] / file.name)],
                     "cppcheck (its configurations)").stdout.decode(errors="replace")
    prefix = f"Checking {mirrors[file.parent] / file.name}: "
    return ["", *(line[len(prefix):].removesuffix("...") for line in listed.splitlines() if line.startswith(prefix))]


def _directives_only(text: str) -> str:
    """``text`` with its comments and every line that is not a preprocessor directive blanked, lines kept in place."""
    lines, continued, in_comment = [], False, False
    for line in text.splitlines():
        code, i, quote = [], 0, None
        while i < len(line):
            if in_comment:
                end = line.find("*/", i)
                if end < 0:
                    break
                in_comment, i = False, end + 2
                code.append(" ")
            elif quote:
                code.append(line[i : i + 2] if line[i] == "\\" else line[i])
                quote = None if line[i] == quote else quote
                i += 2 if line[i] == "\\" else 1
            elif line.startswith("/*", i):
                in_comment, i = True, i + 2
            elif line.startswith("//", i):
                break
            else:
                quote = line[i] if line[i] in "\"'" else None
                code.append(line[i])
                i += 1
        stripped = "".join(code)
        kept = continued or bool(_DIRECTIVE.match(stripped))
        lines.append(stripped if kept else "")
        continued = kept and line.endswith("\\")
    return "\n".join(lines) + "\n"


def cppcheck_configuration_flags(configuration: str) -> list[str]:
    """cppcheck's options that check one configuration only, as it checks it among all of them.

    ``""`` is the first configuration cppcheck checks (``--max-configs=1``);
    another is its symbols given with ``-D``, each with the empty value a
    configuration gives it unless it names one (``A;B=0`` is ``-DA= -DB=0``).
    """
    if not configuration:
        return ["--max-configs=1", "--suppress=toomanyconfigs"]
    return [f"-D{symbol}" if "=" in symbol else f"-D{symbol}=" for symbol in configuration.split(";")]


def cppcheck_preprocessed(file: Path, include: Path, configuration: str) -> bytes:
    """``file`` as cppcheck preprocesses it in ``configuration`` (``cppcheck -E``)."""
    return run([CPPCHECK, "-E", "--std=c99", *cppcheck_configuration_flags(configuration), "-I", str(include), str(file)],
               "cppcheck -E").stdout
