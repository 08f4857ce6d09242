"""The C navigator: generated from templates around the generated filter, compiled, driven by ctypes.

:func:`generate_c_navigator` writes ``<model>.h/.c`` (modelgen's filter) and
``<model>_navigator.h/.c`` (codegen/backends/c/templates/navigator_header.h.j2,
navigator_source.c.j2) into a folder; :func:`build_c_navigator` compiles them
strictly (C99, -Wall -Wextra -Werror -pedantic) into a shared library;
:func:`fly_c` flies a log with it from its first IMU sample and returns a
:class:`~modelgen.navigator.navigator.Flight` like :func:`~modelgen.navigator.navigator.fly`.
The C aligns itself (roll, pitch and biases at rest, heading from the GNSS
course) by the rules and arithmetic of :func:`~modelgen.navigator.navigator.align`;
Python hands it only the configuration and the logs.
"""

from __future__ import annotations

import ctypes
import hashlib
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import numpy as np

from modelgen.version import __version__
from modelgen.codegen.build import compile_shared_library
from modelgen.codegen.generate import generate_code, template_folder
from modelgen.errors import ModelError
from modelgen.navigator import cconfig
from modelgen.navigator.cconfig_fields import WINDOW_SAMPLES_MIN
from modelgen.navigator.config import NavigatorConfig
from modelgen.navigator.navigator import OUTPUT_FIELDS, Flight, Inputs
from modelgen.navigator.outages import in_outage, outage_windows
from modelgen.navigator.sensors import SENSORS, log_sensors, step_sensors
from modelgen.navigator.spec import SENSOR_BLOCKS, NavigatorSpec
from modelgen.fileio.output import write_atomically
from modelgen.model import wgs84

N_GNSS, N_ALIGNMENT = 13, 8
N_OUTPUT = len(OUTPUT_FIELDS)  # entries of one output record, C and Python alike
#: an output record's entries by name (navigator.OUTPUT_FIELDS; the template's ``out``)
OUT = {name: i for i, name in enumerate(OUTPUT_FIELDS)}
#: the C's counters: the GNSS update's, one per aiding sensor tried at a covariance step (the table's order), predicts
COUNT_NAMES = ("gnss_updates", "gnss_rejected", "gnss_released", "gnss_deweighted", "gnss_quality_skipped",
               *(s.counter for s in step_sensors(SENSORS)), "predicts")
ALIGNMENT_NAMES = ("time", "roll", "pitch", "heading", "rest_end", "rest_samples", "rest_start", "motion_time")
#: IMU samples the C keeps for its alignment by default ({P}_NAV_REST_MAX in the header); a configuration whose
#: rest window needs more is built with a larger ring (:func:`rest_capacity`, -D{P}_NAV_REST_MAX)
REST_MAX = cconfig.REST_MAX
#: the zero-velocity detector's window buffer by default ({P}_NAV_WINDOW_MAX); a configuration whose ZUPT window
#: needs more samples is built with a larger one (:func:`window_capacity`, -D{P}_NAV_WINDOW_MAX)
WINDOW_MAX = cconfig.WINDOW_MAX
#: the C navigator's own statuses after the filter's 1 and 2 (header {P}_NAV_ERR_<name>, rendered from this table):
#: name -> (status, meaning); NO_REST and FEW_REST are explained by the Python rules' diagnosis
NAV_STATUS = {
    "NO_REST": (11, "a used epoch faster than config.heading_speed came before any rest window"),
    "FEW_REST": (12, "fewer than 10 IMU samples in the rest window"),
    "REST_OVERFLOW": (13, "the rest window held more IMU samples than the C navigator was built to keep "
                          "(its ring overflowed)"),
    "AID_SLOT": (14, "an aiding sample named a sensor slot the C navigator does not have"),
    "RECORD_FULL": (15, "the forward record's buffers are full (navigator_set_record)"),
    "GNSS_UPDATE": (16, "an ecef model's GNSS update (dense rows) met a covariance that is not positive"),
    "CARRIED": (17, "a carried state (an aiding sensor's own error) has no steady state at the alignment: its "
                    "Gauss-Markov rate is not positive at the configured parameters"),
}
#: the alignment statuses whose meaning is the error itself
ALIGNMENT_ERRORS = {NAV_STATUS[name][0]: NAV_STATUS[name][1] for name in ("REST_OVERFLOW", "AID_SLOT", "CARRIED")}
#: NAV_ERR_RECORD_FULL of the navigator header.
RECORD_FULL = NAV_STATUS["RECORD_FULL"][0]


def earth_constants() -> dict[str, str]:
    """The WGS-84 constants the C navigator uses, printed from :mod:`modelgen.model.wgs84` to round-trip exactly."""
    names = ("SEMI_MAJOR_AXIS", "FLATTENING", "EQUATORIAL_GRAVITY", "SOMIGLIANA_K", "GRAVITY_RATIO_M",
             "ECCENTRICITY_SQUARED")
    return {name: repr(float(getattr(wgs84, name))) for name in names}


#: the C navigator's member that holds each sensor block's estimate
SENSOR_TARGETS = {"gyro_bias": "gyro_bias", "accel_bias": "accel_bias", "gyro_scale_factor": "gyro_scale",
                  "accel_scale_factor": "accel_scale"}


def _literal(value: float) -> str:
    return repr(float(value))


def template_context(spec: NavigatorSpec) -> dict:
    """What the navigator templates loop over: the spec's blocks, rows, parameter code and configuration struct."""
    blocks = {kind: {"entries": [(i, a, _literal(sg)) for i, a, sg in zip(b.indices, b.axes, b.signs)],
                     "form": b.form} for kind, b in spec.blocks.items()}
    free = list(spec.free_parameters)
    parameters = [(name, spec.parameter_expressions[name] if name in spec.parameter_expressions
                   else f"cfg->parameters[{free.index(name)}]") for name in spec.parameter_names]
    pos = spec.blocks["position"]
    output = [None, None, None]
    for i, a, sg in zip(pos.indices, pos.axes, pos.signs):
        output[a] = (i, _literal(sg * (-1.0 if a == 2 else 1.0)))
    carried = list(spec.carried)
    return {**aiding_context(), "blocks": blocks, "carried": carried,
            "carried_of": [carried.index(i) if i in carried else -1 for i in range(spec.n_states)], "sensor_targets": [(k, SENSOR_TARGETS[k]) for k in SENSOR_BLOCKS if k in spec.blocks],
            "parameters": parameters, "position_output": output,
            "gnss_rows": [{"kind": r.kind, "axis": r.axis, "sign": _literal(r.sign), "sigma_index": r.sigma_index}
                          for r in spec.gnss_rows],
            "frame": [[_literal(v) for v in row] for row in spec.to_frame], "frame_name": spec.frame,
            "ecef": spec.ecef, "gnss_rotation": _gnss_rotation(spec),
            "rows_max": max(6, len(spec.gnss_rows)), "n_free": len(free), "free_names": ", ".join(free) or "none",
            "config_struct": cconfig.c_struct(spec.name, len(free)), "mechanization_rates": spec.rates_c,
            "config_checks": cconfig.c_checks(spec.name.upper(), len(free)), "window_max": WINDOW_MAX,
            "rest_max": REST_MAX, "nav_status": NAV_STATUS,
            "out": OUT, "n_output": N_OUTPUT}


def _gnss_rotation(spec: NavigatorSpec) -> dict | None:
    """The C's tables of NavigatorSpec.gnss_rotation (an ecef model): per GNSS row its kind (0 velocity, 1 position),
    e-frame axis, sign, the NED axis it is turned along and its sigma index."""
    if not spec.ecef:
        return None
    along = spec.gnss_rotation_rows()
    return {"kind": [int(r.kind == "position") for r in spec.gnss_rows], "axis": [r.axis for r in spec.gnss_rows],
            "sign": [_literal(r.sign) for r in spec.gnss_rows], "ned": [a for a, _ in along],
            "sigma": [s for _, s in along]}


def aiding_context(table=SENSORS) -> dict:
    """What the template emits per aiding sensor of the table (close_chunk), and the counters' and slots' names."""
    slots = [s.name for s in log_sensors(table)]
    entries = []
    for s in step_sensors(table):
        entries.append({"name": s.name, "section": s.section, "meaning": s.meaning, "form": s.form,
                        "condition": s.condition, "enabled": s.enabled, "group": s.group, "axes": list(s.axes),
                        "lever_arm": s.lever_arm, "sigmas": list(s.sigmas), "dof": s.dof,
                        "count": COUNT_NAMES.index(s.counter), "slot": slots.index(s.name) if s.name in slots else None})
    return {"aiding": entries, "aiding_forms": sorted({e["form"] for e in entries}),
            "aiding_groups": sorted({e["group"] for e in entries if e["group"]}), "aid_slots": slots,
            "count_names": list(COUNT_NAMES), "predicts_count": COUNT_NAMES.index("predicts")}


def render_navigator(spec: NavigatorSpec) -> dict[str, str]:
    """The navigator's header and source for the spec's model (its generated filter is ``<model>.h``)."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(template_folder())), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True)
    model = spec.name
    context = {"p": model, "P": model.upper(), "version": __version__, "wgs84": earth_constants(),
               **template_context(spec)}
    return {f"{model}_navigator.h": env.get_template("navigator_header.h.j2").render(context),
            f"{model}_navigator.c": env.get_template("navigator_source.c.j2").render(context)}


def generate_c_navigator(spec: NavigatorSpec, folder: Path) -> Path:
    """Write the filter and the navigator C for the spec's (already derived) model into ``folder`` (atomically)."""
    files = {name: text for name, text in generate_code(spec.derived).files.items() if name.endswith((".c", ".h"))}
    files.update(render_navigator(spec))
    return write_atomically(Path(folder), files)


class CNavigator:
    """The compiled navigator library (one model)."""

    def __init__(self, library: Path, spec: NavigatorSpec, rest_max: int = REST_MAX, window_max: int = WINDOW_MAX):
        self.spec = spec
        self.model = spec.name
        self.rest_max = rest_max  # the alignment ring it was built with
        self.window_max = window_max  # the zero-velocity detector's window buffer it was built with
        self.lib = ctypes.CDLL(str(library))
        self.size = int(self._fn("navigator_size", [], ctypes.c_ulong)())
        dp = ctypes.POINTER(ctypes.c_double)
        self.configure = self._fn("navigator_configure", [ctypes.c_void_p, ctypes.c_void_p])
        self.run = self._fn("navigator_run_aided", [ctypes.c_void_p, ctypes.c_long, dp, dp, dp, ctypes.c_long, dp,
                                                    ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_int), dp,
                                                    ctypes.c_long, dp, ctypes.POINTER(ctypes.c_int), dp, dp])
        self.alignment = self._fn("navigator_alignment", [ctypes.c_void_p, dp])
        self.counts = self._fn("navigator_counts", [ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)], None)
        self.set_record = self._fn("navigator_set_record", [ctypes.c_void_p, ctypes.c_void_p])

    def _fn(self, name: str, argtypes: list, restype=ctypes.c_int):
        function = getattr(self.lib, f"{self.model}_{name}")
        function.argtypes = argtypes
        function.restype = restype
        return function


class GeneratedC:
    """The generated C backward pass (``<model>_smooth``, ``<model>_smooth_refer``) in the compiled navigator library.

    Every buffer is the caller's (numpy arrays here, the C allocates nothing): the record's arrays, the
    outputs and the work area ``<model>_smooth_workspace``.
    """

    def __init__(self, navigator: CNavigator):
        self.bind(navigator.lib, navigator.model, navigator.spec.n_states)

    @classmethod
    def of_library(cls, lib: ctypes.CDLL, model: str, n_states: int) -> "GeneratedC":
        """The backward pass of any library with a generated double-precision filter of ``model`` in it."""
        backward = cls.__new__(cls)
        backward.bind(lib, model, n_states)
        return backward

    def bind(self, lib: ctypes.CDLL, model: str, n_states: int) -> None:
        dp, lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_long)
        self.n = n_states
        self.name = f"generated C ({model}_smooth)"
        self._smooth = getattr(lib, f"{model}_smooth")
        self._smooth.argtypes = [ctypes.c_long, dp, dp, dp, dp, lp, dp, dp, lp, ctypes.c_void_p]
        self._smooth.restype = ctypes.c_int
        self._refer = getattr(lib, f"{model}_smooth_refer")
        self._refer.argtypes = [dp, dp, ctypes.c_long, dp]
        self._refer.restype = ctypes.c_int
        # the work area: factor, gain and difference (n x n each) and before (n), doubles
        self._work = np.zeros(3 * self.n * self.n + self.n)

    def smooth(self, arrays) -> tuple[np.ndarray, np.ndarray]:
        steps = len(arrays.P_post)
        n = self.n
        Phi, P_prior, P_post = (np.ascontiguousarray(a, float) for a in (arrays.Phi, arrays.P_prior, arrays.P_post))
        corrections = np.ascontiguousarray(arrays.corrections, float).reshape(-1, n)
        if not len(corrections):
            corrections = np.zeros((1, n))  # a pointer to something; no row is read
        start = np.ascontiguousarray(arrays.start, dtype=ctypes.c_long)
        s = np.zeros((steps, n))
        Ps = np.zeros((steps, n, n))
        failed = ctypes.c_long(-1)
        status = self._smooth(steps, _pointer(Phi), _pointer(P_prior), _pointer(P_post), _pointer(corrections),
                              _pointer(start, ctypes.c_long), _pointer(s), _pointer(Ps), ctypes.byref(failed),
                              self._work.ctypes.data_as(ctypes.c_void_p))
        if status != 0:
            raise ModelError(f"smoother: the generated C backward pass refused the forward record at step "
                             f"{failed.value} (status {status}: {SMOOTH_STATUS.get(status, 'unknown')})")
        return s, Ps

    def refer(self, s: np.ndarray, Ps: np.ndarray, corrections) -> tuple[np.ndarray, np.ndarray]:
        s, Ps = np.array(s, float), np.array(Ps, float)
        rows = np.ascontiguousarray(np.array(list(corrections), float).reshape(-1, self.n))
        status = self._refer(_pointer(s), _pointer(Ps), len(rows), _pointer(rows))
        if status != 0:
            raise ModelError("smoother: the generated C backward pass made a non-finite smoothed error")
        return s, Ps


#: The generated filter's status codes as the backward pass returns them.
SMOOTH_STATUS = {1: "non-finite input or result", 2: "a prior covariance is not positive definite",
                 3: "a transition entry outside the pattern of Phi, or correction_start does not index the corrections"}


def capacity_defines(model: str, rest_max: int, window_max: int = WINDOW_MAX) -> tuple[str, str]:
    """The compiler flags that size the C's buffers: the alignment ring and the zero-velocity detector's window."""
    return (f"-D{model.upper()}_NAV_REST_MAX={int(rest_max)}", f"-D{model.upper()}_NAV_WINDOW_MAX={int(window_max)}")


def build_c_navigator(spec: NavigatorSpec, folder: Path, rest_max: int = REST_MAX,
                      window_max: int = WINDOW_MAX) -> CNavigator:
    """Generate, compile (strict C99, -O2) and load the navigator for a spec (ring of ``rest_max`` samples, detector
    window of ``window_max``)."""
    folder = generate_c_navigator(spec, folder)
    model = spec.name
    library = compile_shared_library([folder / f"{model}.c", folder / f"{model}_navigator.c"],
                                     folder / f"lib{model}_navigator.so",
                                     ("-O2", *capacity_defines(model, rest_max, window_max)))
    return CNavigator(library, spec, rest_max, window_max)


def rest_capacity(config: NavigatorConfig, time: np.ndarray) -> int:
    """The alignment ring the C needs for this configuration and log (:func:`modelgen.navigator.cconfig.rest_capacity`)."""
    return cconfig.rest_capacity(config.rest_window, config.still_window, config.zupt_window, time)


def window_capacity(config: NavigatorConfig, time: np.ndarray) -> int:
    """The zero-velocity detector's window buffer the C needs for this configuration and log
    (:func:`modelgen.navigator.cconfig.window_capacity`)."""
    return cconfig.window_capacity(config.zupt_window, time)


def cache_folder() -> Path:
    """Where compiled navigators are kept between runs: the compile cache's folder
    (:func:`modelgen.codegen.build.library_cache_folder`: $MODELGEN_CACHE_DIR, else $XDG_CACHE_HOME/modelgen, else
    ~/.cache/modelgen; under its size cap, every entry verified by its digest before it is loaded)."""
    from modelgen.codegen.build import library_cache_folder

    return library_cache_folder()


def navigator_key(model_file: Path, rest_max: int, window_max: int = WINDOW_MAX) -> str:
    """The cache key of a compiled navigator: what the library is made from, without deriving the model.

    The sha256 of the model file, the navigator templates, the filter's templates and printer (everything under
    modelgen/codegen/backends), modelgen's version, the alignment ring's and detector window's sizes and the compiler's identity.
    """
    from modelgen.codegen.build import STRICT_FLAGS, compiler, compiler_identity
    from modelgen.fileio.datafiles import data_path
    from modelgen.navigator.config_schema import SCHEMA_FILE

    digest = hashlib.sha256(b"modelgen-navigator-library 2\n" + __version__.encode())
    digest.update(Path(model_file).read_bytes())
    backends = Path(__file__).resolve().parent.parent / "codegen" / "backends"  # the filter's templates and printer
    sources = sorted(Path(template_folder()).glob("*.j2")) + sorted(backends.rglob("*.j2")) + sorted(backends.rglob("*.py"))
    here = Path(__file__).resolve().parent
    sources += [here / "spec.py", here / "cconfig.py", here / "cconfig_fields.py", here / "cnav.py", here / "sensors.py",
                here / "ecef.py", here / "config.py"]  # they shape the rendered C
    sources.append(data_path(SCHEMA_FILE))  # the configuration check's bounds (cconfig.bounds)
    codegen = backends.parent  # the mechanization rates' generator and their symbolic source
    sources += [codegen / "mechanization.py", codegen.parent / "derivation" / "mechanization_rates.py"]
    for template in sources:
        digest.update(template.name.encode() + template.read_bytes())
    digest.update(f"\nrest_max {int(rest_max)}\nwindow_max {int(window_max)}\nflags {' '.join(STRICT_FLAGS)} -O2\n".encode())
    digest.update(compiler_identity(compiler()).encode())
    return "navigator-" + digest.hexdigest()


def _load_payload(payload: bytes, spec: NavigatorSpec, rest_max: int, window_max: int) -> CNavigator:
    """Load a library from its bytes: written to a private temporary file, loaded, the file removed."""
    with tempfile.TemporaryDirectory(prefix="modelgen-navigator-") as folder:
        library = Path(folder) / f"lib{spec.name}_navigator.so"
        library.write_bytes(payload)
        return CNavigator(library, spec, rest_max, window_max)


def cached_c_navigator(spec: NavigatorSpec, echo=lambda message: None,
                       rest_max: int = REST_MAX, window_max: int = WINDOW_MAX) -> tuple[CNavigator, bool]:
    """The compiled navigator for a spec's model file, from the compile cache when its inputs are unchanged.

    Key: :func:`navigator_key`.  The entry is the compile cache's (:mod:`modelgen.codegen.build`): verified by its
    digest before it is loaded (a corrupt or cut-short entry is not loaded: the navigator is compiled again and kept
    under the next name) and kept within the cache's size cap.  Returns the navigator and whether it came from the
    cache.
    """
    from modelgen.codegen.build import cached_library, store_library

    folder = cache_folder()
    key = navigator_key(spec.model_file, rest_max, window_max)
    payload = cached_library(folder, key)
    if payload is not None:
        return _load_payload(payload, spec, rest_max, window_max), True
    echo(f"  generating and compiling the C navigator (once; cached in {folder})")
    with tempfile.TemporaryDirectory(prefix="modelgen-navigator-build-") as build:
        navigator = build_c_navigator(spec, Path(build) / "navigator", rest_max, window_max)
        library = Path(build) / "navigator" / f"lib{navigator.model}_navigator.so"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            store_library(folder, key, library.read_bytes())
        except OSError:  # a cache that cannot be written: the navigator is still here
            pass
    return navigator, False


def config_values(config: NavigatorConfig, spec: NavigatorSpec, time_: np.ndarray) -> dict:
    """The C configuration's field values (cconfig.FIELDS) for a configuration and a log's sample times."""
    from modelgen.navigator.alignment import still_window_samples

    median_dt = float(np.median(np.diff(time_)))
    window = max(WINDOW_SAMPLES_MIN, int(round(config.zupt_window / median_dt)))
    step = max(1, int(round(config.predict_period / median_dt)))
    return cconfig.values(config, spec, window, step, still_window_samples(config, time_))


def _pointer(array: np.ndarray, kind=ctypes.c_double):
    return array.ctypes.data_as(ctypes.POINTER(kind))


@dataclass
class LogArrays:
    """Everything the C navigator is given for one log, as contiguous arrays (shared by ctypes and qemu runs)."""

    cfg: dict  # the configuration's field values (cconfig.FIELDS)
    n_parameters: int  # the model's free parameters (the struct's parameters[] count)
    time: np.ndarray
    force: np.ndarray
    rate: np.ndarray
    t_gnss: np.ndarray
    target: np.ndarray  # int64
    use: np.ndarray  # int32
    gnss: np.ndarray  # (epochs, 13)
    windows: list[tuple[float, float]]
    rest_max: int = REST_MAX  # the alignment ring this log and configuration need (:func:`rest_capacity`)
    window_max: int = WINDOW_MAX  # the detector window buffer they need (:func:`window_capacity`)
    #: the enabled aiding sensors' log samples, merged in time order: time [s], slot (NAV_N_AID order), value [SI]
    aid_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    aid_slot: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    aid_value: np.ndarray = field(default_factory=lambda: np.zeros(0))


def log_arrays(config: NavigatorConfig, inputs: Inputs, spec: NavigatorSpec) -> LogArrays:
    """The log laid out for the C navigator: every IMU sample and every GNSS epoch inside the IMU span."""
    g = inputs.gnss
    time_, force, rate = (np.ascontiguousarray(a, dtype=float) for a in (inputs.time, inputs.force, inputs.rate))
    windows = outage_windows(config.outage_schedule, config.outage_windows, inputs.first_epoch, float(g.time[-1]))
    outage = in_outage(g.time, windows)
    epochs = np.arange(len(g.time))
    target = np.searchsorted(time_, g.time[epochs]).astype(np.int64)
    epochs, target = epochs[target < len(time_)], target[target < len(time_)]
    gnss = np.column_stack([g.latitude, g.longitude, g.height, g.velocity, g.quality, g.sigma_position,
                            g.sigma_velocity])[epochs]
    contiguous = np.ascontiguousarray
    values = config_values(config, spec, time_)
    aid_time, aid_slot, aid_value = aiding_samples(inputs, values)
    return LogArrays(values, len(spec.free_parameters), time_, force, rate,
                     contiguous(g.time[epochs]), contiguous(target), contiguous((~outage[epochs]).astype(np.int32)),
                     contiguous(gnss), windows, rest_capacity(config, time_), window_capacity(config, time_),
                     aid_time, aid_slot, aid_value)


def aiding_samples(inputs: Inputs, values: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The enabled log sensors' samples (inputs.aiding) merged in time order: time, slot, value (contiguous)."""
    parts = []
    for slot, sensor in enumerate(log_sensors(SENSORS)):
        log = inputs.aiding.get(sensor.stream)
        if log is not None and values[sensor.enabled]:
            parts.append((np.asarray(log.time, float), np.full(len(log.time), slot, np.int32),
                          np.asarray(log.value, float)))
    if not parts:
        return np.zeros(0), np.zeros(0, np.int32), np.zeros(0)
    t, s, v = (np.concatenate(p) for p in zip(*parts))
    order = np.argsort(t, kind="stable")
    return (np.ascontiguousarray(t[order]), np.ascontiguousarray(s[order], dtype=np.int32),
            np.ascontiguousarray(v[order]))


def alignment_error(config: NavigatorConfig, inputs: Inputs, status: int) -> ModelError:
    """The error for a C navigator status: an alignment failure is explained by the Python rules' own diagnosis."""
    if status in ALIGNMENT_ERRORS:
        return ModelError(f"{inputs.gnss.path}: C navigator alignment: {ALIGNMENT_ERRORS[status]}")
    if status in (NAV_STATUS["NO_REST"][0], NAV_STATUS["FEW_REST"][0]):
        return not_aligned_error(config, inputs)
    return ModelError(f"C navigator: a filter step failed (status {status})")


def configuration_error(config: NavigatorConfig, field_values: dict, status: int, rest_max: int,
                        window_max: int = WINDOW_MAX) -> ModelError:
    """The error for a configuration the C navigator refused (its NAV_ERR_CONFIG_* status): the field's key and line,
    its value and bounds (:func:`modelgen.navigator.cconfig.refusal`)."""
    item = cconfig.CONFIG_STATUS.get(status)
    if item is None:
        return ModelError(f"{config.path}: the C navigator refused its configuration with status {status}, "
                          "which names no configuration field (a navigator built by another modelgen?)")
    return cconfig.refusal(config.path, item, field_values[item.name], capacities(rest_max, window_max), "C", status)


def capacities(rest_max: int = REST_MAX, window_max: int = WINDOW_MAX) -> dict[str, int]:
    """The C navigator's capacities that bound configuration fields (cconfig.Field maximum / minimum names)."""
    return {"WINDOW_MAX": window_max, "REST_MAX": rest_max}


def not_aligned_error(config: NavigatorConfig, inputs: Inputs) -> ModelError:
    """Why the C navigator did not align: the same rules in Python (:mod:`modelgen.navigator.alignment`) say why."""
    from modelgen.navigator.alignment import align

    try:
        align(config, inputs)
    except ModelError as error:
        return error
    return ModelError(f"{inputs.gnss.path}: the C navigator did not align where the Python rules align "
                      "(an internal disagreement; please report it)")


def flight_from_outputs(out: np.ndarray, arrays: LogArrays, inputs: Inputs, counts: dict[str, int],
                        alignment: dict[str, float], estimated: tuple[str, ...] = ()) -> Flight:
    """A Flight from the C output records (rows before the alignment and after the log's end dropped)."""
    out = out[~np.isnan(out[:, 0])]
    nis = out[(out[:, OUT["in_outage"]] == 0) & ~np.isnan(out[:, OUT["nis"]]), OUT["nis"]]
    return Flight(out, arrays.windows, inputs.first_epoch, alignment["time"], list(nis),
                  float(arrays.cfg["gate_gnss"]), counts, list(inputs.notes), alignment, estimated=estimated)


#: Entries of a recorded nominal state (NAV_RECORD_NOMINAL): the navigation vector, then the sensor estimates, then
#: the carried estimates (NavigatorSpec.carried).
NAV_SIZE = 10
RECORD_SENSORS = ("gyro_bias", "accel_bias", "gyro_scale_factor", "accel_scale_factor")


class RecordStruct(ctypes.Structure):
    """<model>_navigator_record: the forward record's buffers (the caller's), capacities and counts."""

    _fields_ = [("step_capacity", ctypes.c_long), ("correction_capacity", ctypes.c_long),
                ("output_capacity", ctypes.c_long), ("Phi", ctypes.POINTER(ctypes.c_double)),
                ("P_prior", ctypes.POINTER(ctypes.c_double)), ("P_post", ctypes.POINTER(ctypes.c_double)),
                ("correction_start", ctypes.POINTER(ctypes.c_long)), ("corrections", ctypes.POINTER(ctypes.c_double)),
                ("nominal", ctypes.POINTER(ctypes.c_double)), ("output_step", ctypes.POINTER(ctypes.c_long)),
                ("output_corrections_before", ctypes.POINTER(ctypes.c_long)), ("steps", ctypes.c_long),
                ("n_corrections", ctypes.c_long), ("outputs", ctypes.c_long)]


@dataclass
class RecordBuffers:
    """The numpy arrays a C forward record is written into, sized from the log and the configuration."""

    Phi: np.ndarray
    P_prior: np.ndarray
    P_post: np.ndarray
    correction_start: np.ndarray
    corrections: np.ndarray
    nominal: np.ndarray
    output_step: np.ndarray
    output_corrections_before: np.ndarray

    @classmethod
    def sized(cls, arrays: "LogArrays", n: int, table=SENSORS, n_carried: int = 0) -> "RecordBuffers":
        """Capacities: a covariance step closes every predict_samples IMU samples or at a GNSS epoch (steps <=
        n_imu / predict_samples + epochs + the alignment's), each step tries every step sensor once and each
        epoch makes at most one GNSS update (corrections <= steps x step sensors + epochs), one output per epoch."""
        epochs = len(arrays.t_gnss)
        steps = len(arrays.time) // max(1, int(arrays.cfg["predict_samples"])) + epochs + 2
        corrections = steps * len(step_sensors(table)) + epochs
        return cls(np.zeros((steps, n, n)), np.zeros((steps, n, n)), np.zeros((steps, n, n)),
                   np.zeros(steps + 1, dtype=ctypes.c_long), np.zeros((max(corrections, 1), n)),
                   np.zeros((max(epochs, 1), NAV_SIZE + 12 + n_carried)), np.zeros(max(epochs, 1), dtype=ctypes.c_long),
                   np.zeros(max(epochs, 1), dtype=ctypes.c_long))

    def structure(self) -> RecordStruct:
        return RecordStruct(len(self.P_post), len(self.corrections), len(self.nominal), _pointer(self.Phi),
                            _pointer(self.P_prior), _pointer(self.P_post), _pointer(self.correction_start, ctypes.c_long),
                            _pointer(self.corrections), _pointer(self.nominal), _pointer(self.output_step, ctypes.c_long),
                            _pointer(self.output_corrections_before, ctypes.c_long), 0, 0, 0)


def forward_record_from_c(buffers: RecordBuffers, counts: RecordStruct, spec: NavigatorSpec, arrays: "LogArrays",
                          out: np.ndarray, lever: np.ndarray):
    """The C's forward record as a :class:`modelgen.navigator.smoother.ForwardRecord` (the smoother's input).

    ``out``: the C's output rows (all epochs, NaN before the alignment): the recorded outputs are its aligned
    rows in order; each becomes an output row again by the navigator's own row function at its IMU sample.
    """
    from functools import partial

    from modelgen.navigator.navigator import _apply_correction, _row
    from modelgen.navigator.smoother import ForwardRecord, OutputSnapshot

    steps, n_corrections, outputs = counts.steps, counts.n_corrections, counts.outputs
    aligned = np.flatnonzero(~np.isnan(out[:, 0]))
    if steps < 1 or outputs != len(aligned):
        raise ModelError(f"smoother: the C navigator's forward record holds {outputs} outputs for {len(aligned)} "
                         "aligned epochs")
    record = ForwardRecord()
    record.feedback = partial(_apply_correction, spec)
    start = buffers.correction_start[:steps + 1]
    for k in range(steps):
        record.transitions.append(buffers.Phi[k].copy() if k else None)
        record.priors.append(buffers.P_prior[k].copy())
        record.posteriors.append(buffers.P_post[k].copy())
        record.corrections.append([buffers.corrections[i].copy() for i in range(start[k], start[k + 1])])
    if start[steps] != n_corrections:
        raise ModelError("smoother: the C navigator's forward record does not index its corrections")
    for i, j in enumerate(aligned):
        row = out[j]
        nominal = buffers.nominal[i]
        sensors = {name: nominal[NAV_SIZE + 3 * b:NAV_SIZE + 3 * b + 3].copy() for b, name in enumerate(RECORD_SENSORS)}
        sensors["carried"] = nominal[NAV_SIZE + 12:NAV_SIZE + 12 + len(spec.carried)].copy()
        k = int(arrays.target[j])
        record.outputs.append(OutputSnapshot(int(buffers.output_step[i]), int(buffers.output_corrections_before[i]),
                                             nominal[:NAV_SIZE].copy(), sensors,
                                             partial(_row, spec, float(arrays.time[k]), lever, arrays.rate[k],
                                                     bool(row[OUT["in_outage"]]), int(row[OUT["gnss_used"]]),
                                                     float(row[OUT["nis"]]), int(row[OUT["gnss_quality"]]))))
    return record


def fly_c(config: NavigatorConfig, inputs: Inputs, navigator: CNavigator, record: bool = False) -> tuple[Flight, float]:
    """Fly the log with the C navigator; return the flight and the CPU time of the C run [s].

    ``record``: also keep the forward record the smoother needs, in buffers sized from the log and the
    configuration (:class:`RecordBuffers`; the C allocates nothing); the flight carries it as ``forward_record``.
    """
    a = log_arrays(config, inputs, navigator.spec)
    if a.rest_max > navigator.rest_max:
        raise ModelError(f"{config.path}: this configuration's rest window needs an alignment ring of {a.rest_max} IMU "
                         f"samples; the C navigator was built with {navigator.rest_max} (cached_c_navigator(rest_max=))")
    if a.window_max > navigator.window_max:
        raise ModelError(f"{config.path}: this configuration's zero-velocity window needs a detector buffer of "
                         f"{a.window_max} IMU samples; the C navigator was built with {navigator.window_max} "
                         "(cached_c_navigator(window_max=))")
    built = capacities(navigator.rest_max, navigator.window_max)
    refused = cconfig.check(a.cfg, built)  # the C's own check, before packing (a count past 32 bits would wrap)
    if refused is not None:
        raise cconfig.refusal(config.path, refused, a.cfg[refused.name], built, "C")
    state = ctypes.create_string_buffer(navigator.size)
    struct = cconfig.to_structure(a.cfg, a.n_parameters)
    status = navigator.configure(state, ctypes.byref(struct))
    if status:
        raise configuration_error(config, a.cfg, status, navigator.rest_max, navigator.window_max)
    buffers = counts = None
    if record:
        buffers = RecordBuffers.sized(a, navigator.spec.n_states, n_carried=len(navigator.spec.carried))
        counts = buffers.structure()
        if navigator.set_record(state, ctypes.byref(counts)):
            raise ModelError("smoother: the C navigator refused the forward record's buffers")
    out = np.full((len(a.t_gnss), N_OUTPUT), np.nan)
    cpu = time.process_time()
    status = navigator.run(state, len(a.time), _pointer(a.time), _pointer(a.force), _pointer(a.rate),
                           len(a.t_gnss), _pointer(a.t_gnss), _pointer(a.target, ctypes.c_long),
                           _pointer(a.use, ctypes.c_int), _pointer(a.gnss), len(a.aid_time), _pointer(a.aid_time),
                           _pointer(a.aid_slot, ctypes.c_int), _pointer(a.aid_value), _pointer(out))
    cpu = time.process_time() - cpu
    if status == RECORD_FULL:
        raise ModelError("smoother: the C navigator's forward record was full (RecordBuffers.sized's bound is wrong)")
    if status:
        raise alignment_error(config, inputs, status)
    result = np.full(N_ALIGNMENT, np.nan)
    if not navigator.alignment(state, _pointer(result)):
        raise not_aligned_error(config, inputs)
    raw = (ctypes.c_long * len(COUNT_NAMES))()
    navigator.counts(state, raw)
    alignment = {name: float(v) for name, v in zip(ALIGNMENT_NAMES, result)}
    flight = flight_from_outputs(out, a, inputs, dict(zip(COUNT_NAMES, (int(v) for v in raw))), alignment,
                                 navigator.spec.estimated_sensors)
    if record:
        flight.forward_record = forward_record_from_c(buffers, counts, navigator.spec, a, out,
                                                      np.asarray(config.lever_arm, float))
    return flight, cpu


