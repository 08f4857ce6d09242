"""The Kalman filters the filter loop can run, behind one small protocol.

The filter loop (``modelgen.simulation.filter_loop``) needs only this from a
filter:

    transition(parameters, period) -> (Phi, Qd)   discretize F, G, Q at an operating point
    predict(Phi, Qd)                               x = Phi x, P = Phi P Phi^T + Qd
    update(z, H, R)                                Joseph-form update; raises ModelError
                                                   on a refused input, state unchanged
    state, covariance                              copies of x and P
    set_state(x)                                   overwrite x (closed-loop reset)

Three implementations plug in:

* :class:`ReferenceFilter` -- ``modelgen.derivation.reference`` (dense numpy) with
  ``modelgen.derivation.discretization`` and ``modelgen.derivation.symbolic``;
* :class:`GeneratedPythonFilter` -- a module written by ``modelgen generate``
  (``generated/<model>/<model>.py``: parameter_vector, system_matrix,
  noise_input_matrix, noise_psd, discretize, predict, update);
* :class:`GeneratedCFilter` -- the compiled generated C (``<model>.c``) through
  ``modelgen.codegen.build.CompiledFilter`` (ctypes).  The C update takes H and
  R from its own matrices, evaluated at the parameters of the last
  :meth:`transition`, which is where the filter loop also takes H and R from.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import json
import pickle
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol

import numpy as np

from modelgen.derivation import reference
from modelgen.errors import ModelError

if TYPE_CHECKING:  # sympy-based, named in annotations only: a run of the compiled loop imports no sympy
    from modelgen.derivation.symbolic import DerivedModel
    from modelgen.simulation.model_outline import ModelOutline


class KalmanFilter(Protocol):
    """What the filter loop needs from a filter (see the module docstring)."""

    def transition(self, parameters: Mapping[str, float], period: float) -> tuple[np.ndarray, np.ndarray]: ...

    def predict(self, transition_matrix: np.ndarray, process_noise: np.ndarray) -> None: ...

    def update(self, measurement: np.ndarray, measurement_matrix: np.ndarray, measurement_noise: np.ndarray) -> None: ...

    @property
    def state(self) -> np.ndarray: ...

    @property
    def covariance(self) -> np.ndarray: ...

    def set_state(self, x: np.ndarray) -> None: ...


def check_finite_measurement(z: np.ndarray, H: np.ndarray, R: np.ndarray, where: str) -> None:
    """Refuse a measurement that would poison the filter (NaN/inf anywhere)."""
    for label, value in (("measurement", z), ("measurement matrix", H), ("measurement noise", R)):
        if not np.all(np.isfinite(value)):
            raise ModelError(f"{where}: non-finite {label} refused ({np.asarray(value).ravel()[:6]}...)")


class ReferenceFilter:
    """Dense numpy filter: derivation + Taylor discretization + modelgen.derivation.reference."""

    name = "reference"

    def __init__(self, derived: DerivedModel, x0: np.ndarray, P0: np.ndarray, taylor_order: int = 9):
        self.derived = derived
        self.matrices = ModelMatrices(derived)
        self.taylor_order = taylor_order
        self._x = np.array(x0, float)
        self._P = np.array(P0, float)

    def transition(self, parameters, period):
        # imported here: it brings scipy.linalg, which a worker flying the generated C never needs
        from modelgen.derivation.discretization import taylor_discretization, taylor_process_noise

        m = self.matrices(parameters)
        phi, gamma = taylor_discretization(m["F"], m["G"], period, self.taylor_order)
        return phi, taylor_process_noise(gamma, m["Q"], period)

    def predict(self, transition_matrix, process_noise):
        self._x = transition_matrix @ self._x
        P = reference.predict_covariance(self._P, transition_matrix, process_noise)
        self._P = 0.5 * (P + P.T)

    def update(self, measurement, measurement_matrix, measurement_noise):
        check_finite_measurement(measurement, measurement_matrix, measurement_noise, "reference filter")
        x, P = reference.update(self._x, self._P, measurement, measurement_matrix, measurement_noise)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise ModelError("reference filter: update produced non-finite values; state kept")
        self._x, self._P = x, 0.5 * (P + P.T)

    @property
    def state(self):
        return self._x.copy()

    @property
    def covariance(self):
        return self._P.copy()

    def set_state(self, x):
        self._x = np.array(x, float)


class GeneratedPythonFilter:
    """The generated Python module (``modelgen generate``) behind the protocol."""

    name = "generated-python"

    def __init__(self, module, x0: np.ndarray, P0: np.ndarray):
        for needed in ("parameter_vector", "system_matrix", "noise_input_matrix", "noise_psd", "discretize",
                       "predict", "update", "measurement_variance"):
            if not hasattr(module, needed):
                raise ModelError(f"generated module {getattr(module, '__name__', module)!r} lacks {needed}()")
        self.module = module
        self._x = np.array(x0, float)
        self._P = np.array(P0, float)

    def transition(self, parameters, period):
        g = self.module
        p = g.parameter_vector({k: v for k, v in parameters.items() if k in g.PARAMETER_NAMES})
        return g.discretize(g.system_matrix(p), g.noise_input_matrix(p), g.noise_psd(p), period)

    def predict(self, transition_matrix, process_noise):
        self._x, self._P = self.module.predict(self._x, self._P, transition_matrix, process_noise)

    def update(self, measurement, measurement_matrix, measurement_noise):
        check_finite_measurement(measurement, measurement_matrix, measurement_noise, "generated Python filter")
        try:
            self._x, self._P = self.module.update(self._x, self._P, np.asarray(measurement, float),
                                                  measurement_matrix, np.diag(measurement_noise).copy())
        except ValueError as exc:
            raise ModelError(f"generated Python filter refused the update: {exc}") from None

    @property
    def state(self):
        return self._x.copy()

    @property
    def covariance(self):
        return self._P.copy()

    def set_state(self, x):
        self._x = np.array(x, float)


class GeneratedCFilter:
    """The compiled generated C filter (ctypes, ``modelgen.codegen.build``) behind the protocol.

    The C computes its own transition in :meth:`transition` (matrices_evaluate +
    discretize); :meth:`predict` applies that transition.  Its update uses H and
    R from the same evaluated matrices, so every model measurement must be
    present (a subset of rows is refused).
    """

    name = "generated-c"

    def __init__(self, compiled, x0: np.ndarray, P0: np.ndarray):
        self.compiled = compiled
        self._last_transition: np.ndarray | None = None
        status = self.compiled.set_state(np.asarray(x0, float), np.asarray(P0, float))
        if status:
            raise ModelError(f"generated C filter refused the initial covariance (status {status})")

    def transition(self, parameters, period):
        known = {name for name, _ in self.compiled.params._fields_}
        self.compiled.set_parameters({k: float(v) for k, v in parameters.items() if k in known})
        status = self.compiled.discretize(period)
        if status != 0:
            raise ModelError(f"generated C filter refused the step T = {period} (status {status})")
        self._last_transition = self.compiled.Phi
        return self._last_transition, self.compiled.Qd

    def predict(self, transition_matrix, process_noise):
        if self._last_transition is None or not np.array_equal(transition_matrix, self._last_transition):
            raise ModelError("generated C filter: predict() applies the transition computed by its own transition()")
        status = self.compiled.predict()
        if status:
            raise ModelError(f"generated C filter: predict returned status {status}")

    def update(self, measurement, measurement_matrix, measurement_noise):
        check_finite_measurement(measurement, measurement_matrix, measurement_noise, "generated C filter")
        if len(measurement) != self.compiled.nm:
            raise ModelError(f"generated C filter: needs all {self.compiled.nm} measurements, got {len(measurement)}")
        status = self.compiled.update(np.asarray(measurement, float))
        if status != 0:
            raise ModelError(f"generated C filter refused the update (status {status}); state kept")

    @property
    def state(self):
        return self.compiled.x

    @property
    def covariance(self):
        return self.compiled.P

    def set_state(self, x):
        self.compiled.set_estimate(np.asarray(x, float))


# -- the generated C filter, laid out for the compiled loop --------------------------------------


@dataclass
class NativeFilter:
    """One generated C filter instance laid out for the compiled loop: structs, views, function pointers."""

    compiled: Any  # modelgen.codegen.build.CompiledFilter
    functions: tuple  # evaluate, discretize, predict, update_masked, get_covariance (ctypes, void* arguments)
    addresses: np.ndarray  # params, matrices, transition, filter, workspace (uint64)
    parameters: np.ndarray  # view of the params struct (model parameter order)
    state: np.ndarray  # view of filter.x
    transition_matrix: tuple  # (view of transition.Phi, its stored entries; their rows, columns; a dense (n, n) to expand into)
    filter_bytes: np.ndarray  # the filter struct as bytes (snapshot / restore around a gated update)

    @classmethod
    def of(cls, compiled: Any) -> "NativeFilter":
        """Views and fresh function pointers (their own argtypes) on a loaded :class:`CompiledFilter`."""
        lib, model = compiled.lib, compiled.model
        if compiled.options.ud or compiled.dtype != np.float64:
            raise ModelError("native filter loop: needs the default (double, non-UD) generated C filter")

        def function(name: str, argtypes: list, restype=ctypes.c_int):
            fn = lib[f"{model}_{name}"]  # a new function object: CompiledFilter's own keep their argtypes
            fn.argtypes, fn.restype = argtypes, restype
            return fn

        void = ctypes.c_void_p
        functions = (
            function("matrices_evaluate", [void, void]),
            function("discretize", [void, ctypes.c_double, void, void]),
            function("predict", [void, void, void]),
            function("update_masked", [void] * 7),
            function("get_covariance", [void, void], None),
        )
        addresses = np.array([ctypes.addressof(s) for s in (compiled.params, compiled.matrices, compiled.transition,
                                                            compiled.filter, compiled.workspace)], dtype=np.uint64)
        n_parameters = len(compiled.params._fields_)
        parameters = np.ctypeslib.as_array((ctypes.c_double * n_parameters).from_address(int(addresses[0])))
        size = ctypes.sizeof(compiled.filter)
        filter_bytes = np.ctypeslib.as_array((ctypes.c_uint8 * size).from_address(int(addresses[3])))
        state = np.ctypeslib.as_array(compiled.filter.x)
        stored = np.ctypeslib.as_array(compiled.transition.Phi)  # Phi compressed to its structural nonzeros
        rows, cols = compiled.phi_entries
        if stored.shape != rows.shape:
            raise ModelError("native filter loop: the transition's Phi does not match its layout")
        transition_matrix = (stored, rows, cols, np.zeros((compiled.n, compiled.n)))
        return cls(compiled, functions, addresses, parameters, state, transition_matrix, filter_bytes)


class NativeFilterMaker:
    """``filter_factory(derived, "c", ...)``: a maker of generated C filters (x0, P0) -> filter.

    Calling it gives the Python loop's :class:`~modelgen.simulation.filters.GeneratedCFilter`;
    the streaming driver asks :meth:`native` for the compiled loop's view of one
    (:mod:`modelgen.simulation.native_loop`).
    """

    name = "generated-c"

    def __init__(self, library, model_name: str, sizes, parameter_names: list[str]):
        self.library, self.model_name, self.sizes, self.parameter_names = library, model_name, sizes, parameter_names

    def __call__(self, x0: np.ndarray, P0: np.ndarray) -> "GeneratedCFilter":
        from modelgen.codegen.build import CompiledFilter  # sibling layer, imported where used

        return GeneratedCFilter(CompiledFilter(self.library, self.model_name, self.sizes, self.parameter_names), x0, P0)

    def native(self, x0: np.ndarray, P0: np.ndarray) -> NativeFilter:
        """A fresh filter set to (x0, P0), laid out for the compiled loop."""
        return NativeFilter.of(self(x0, P0).compiled)


IMPLEMENTATIONS = ("c", "python", "reference")


#: The generated files of the last few models, by a digest of the model's declaration (see generated_filter_files).
_GENERATED: "OrderedDict[str, dict[str, str]]" = OrderedDict()
GENERATED_KEPT = 4


#: what the generated files are made from besides the model: modelgen's own sources and data, and the
#: libraries that shape the generated text (pinned, but a new install is a new generator)
_GENERATOR_SUFFIXES = (".py", ".j2", ".yaml", ".json")
_GENERATOR_LIBRARIES = ("sympy", "jinja2", "numpy")


@functools.lru_cache(maxsize=1)
def generator_digest() -> str:
    """Digest of everything besides the model that :func:`generated_filter_files`' text depends on.

    Every source, template and data file of the modelgen package (their paths
    and contents: 10 ms) and the versions of Python and of the libraries that
    shape the text.  Conservative: any change to modelgen is a new generator.
    """
    import importlib.metadata
    import platform

    package = Path(__file__).resolve().parents[1]  # the modelgen package
    digest = hashlib.sha256(b"modelgen generated-files 1\n")
    versions = [platform.python_version()] + [importlib.metadata.version(name) for name in _GENERATOR_LIBRARIES]
    digest.update(repr(versions).encode("utf-8"))
    for path in sorted(package.rglob("*")):
        if path.suffix in _GENERATOR_SUFFIXES and "__pycache__" not in path.parts and path.is_file():
            content = path.read_bytes()
            digest.update(f"\n{path.relative_to(package).as_posix()} {len(content)}\n".encode("utf-8"))
            digest.update(content)
    return digest.hexdigest()


def _generated_files_folder() -> Path:
    """The on-disk cache of generated files: ``generated`` beside the compile cache's ``libraries``."""
    from modelgen.codegen.build import library_cache_folder  # sibling layer, imported where used

    return library_cache_folder().parent / "generated"


def _cached_files(key: str) -> dict[str, str] | None:
    """The generated files of ``key`` from the on-disk cache, or None (absent, or an entry that does not verify)."""
    from modelgen.codegen.build import cached_library  # an entry store of any payload: magic, key, digest

    payload = cached_library(_generated_files_folder(), key)
    if payload is None:
        return None
    try:
        files = json.loads(payload.decode("utf-8"))
    except ValueError:
        return None
    if not (isinstance(files, dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in files.items())):
        return None
    return files


def _store_files(key: str, files: dict[str, str]) -> None:
    """Keep ``files`` as the on-disk entry of ``key`` (never replacing a file; a cache that cannot be written is
    left without it)."""
    from modelgen.codegen.build import store_library

    store_library(_generated_files_folder(), key, json.dumps(files, sort_keys=True).encode("utf-8"))


def generated_filter_files(derived: DerivedModel) -> dict[str, str]:
    """The files ``modelgen generate`` writes for the model (default options): name -> text.

    Plain text: a Monte Carlo client generates them once and ships them with
    its tasks, so that a worker only writes and compiles (or takes from the
    compile cache) the very code the client would fly.  The last few models'
    files are kept in this process, by a digest of the model's declaration
    (what the code is generated from): ``modelgen simulate`` generates the
    code for its own flight, and its Monte Carlo ships the same files without
    generating them again (half a second for the paper's model).  They are
    also kept on disk, beside the compile cache
    (:func:`modelgen.codegen.build.library_cache_folder`), keyed by that
    digest and :func:`generator_digest`, in entries verified as the compile
    cache's are (:func:`~modelgen.codegen.build.store_library`: written once,
    never replaced; one that does not verify is ignored): a fresh ``modelgen simulate`` of a model it flew before takes
    them from there instead of generating them (0.3 s of its start).
    """
    key = hashlib.sha256(pickle.dumps(derived.model)).hexdigest()
    if key in _GENERATED:
        _GENERATED.move_to_end(key)
    else:
        on_disk = hashlib.sha256(f"{key}\n{generator_digest()}".encode("ascii")).hexdigest()
        files = _cached_files(on_disk)
        if files is None:
            # sibling layer, imported only when the files are generated (its imports, jinja2 and the backends, are
            # 0.3 s a fresh ``modelgen simulate`` with the files on disk does without)
            from modelgen.codegen.generate import generate_code

            files = dict(generate_code(derived).files)
            _store_files(on_disk, files)
        _GENERATED[key] = files
        while len(_GENERATED) > GENERATED_KEPT:
            _GENERATED.popitem(last=False)
    return dict(_GENERATED[key])


def filter_factory(derived: DerivedModel | ModelOutline, implementation: str, work_dir: str | Path,
                   files: Mapping[str, str] | None = None) -> Callable[[np.ndarray, np.ndarray], KalmanFilter]:
    """A maker of fresh filters (x0, P0) -> filter for ``implementation``.

    ``c`` and ``python`` are the code ``modelgen generate`` writes for the
    model (default options; ``files`` if given, as :func:`generated_filter_files`
    made them), written into ``work_dir`` now and compiled or imported once;
    every filter made shares that code but has its own state.  The C is taken
    from the compile cache when it was compiled before
    (:func:`modelgen.codegen.build.compile_shared_library`).
    ``reference`` is the dense numpy filter.  For ``c`` the maker is a
    :class:`NativeFilterMaker`: called, it
    gives a :class:`GeneratedCFilter` for the Python loop; the streaming driver
    flies it in the compiled loop where the sensor allows.
    """
    if implementation not in IMPLEMENTATIONS:
        raise ModelError(f"simulation: unknown filter implementation {implementation!r} "
                         f"(choose from {', '.join(IMPLEMENTATIONS)})")
    if implementation == "reference":
        return lambda x0, P0: ReferenceFilter(derived, x0, P0)
    from modelgen.codegen.build import compile_shared_library, load_python_module  # siblings
    from modelgen.fileio.output import write_atomically
    from modelgen.codegen.layout import ModelSizes

    model = derived.model
    folder = Path(work_dir) / model.name
    write_atomically(folder, dict(files) if files is not None else generated_filter_files(derived))
    if implementation == "python":
        module = load_python_module(folder / f"{model.name}.py")
        return lambda x0, P0: GeneratedPythonFilter(module, x0, P0)
    library = compile_shared_library([folder / f"{model.name}.c"], folder / f"lib{model.name}.so", cache=True)
    return NativeFilterMaker(library, model.name, ModelSizes.of(derived), model.parameter_names)


def named_parameters(derived: DerivedModel, available: Mapping[str, float], validate: bool = True) -> dict[str, float]:
    """The model's parameters from a larger vocabulary; a missing one is refused by name."""
    chosen = {name: available[name] for name in derived.model.parameter_names if name in available}
    if validate:
        from modelgen.derivation.symbolic import parameter_vector  # sympy-based: here, where a derived model validates

        missing = [p for p in derived.model.parameters if p.name not in chosen and p.value is None]
        if missing:
            at = next((p.place() for p in missing if p.place()), "")  # the first declaration that gives no value
            raise ModelError((f"{at}: " if at else "")
                             + unsupplied_parameters_message(derived.model.name, [f"{p.name} ({p.symbol})" for p in missing],
                                                             sorted(available)))
        parameter_vector(derived.model, chosen)
    return chosen


def _collapse_numbered(names: list[str]) -> list[str]:
    """``pseudorange_sigma_1``, ``pseudorange_sigma_2``... shown once as ``pseudorange_sigma_<k>``."""
    import re

    return list(dict.fromkeys(re.sub(r"_\d+$", "_<k>", name) for name in names))


def unsupplied_parameters_message(model: str, missing: list[str], supplied: list[str]) -> str:
    """Why a model cannot fly, and the convention that would let it (README: 'Flying your own model')."""
    return (
        f"model {model!r} cannot fly this profile: the simulation supplies no value for parameter(s) "
        f"{', '.join(missing)}.  A model's parameters take, by name, the simulated quantity of the same name "
        f"({', '.join(_collapse_numbered(supplied))}); any other parameter needs a default value in the model file or a constant "
        f"in the profile's filter.parameters (for example `{missing[0].split(' ')[0]}: 0.0`)"
    )


class ModelMatrices:
    """F, G, Q, H, R of a derived model as a fast function of a parameter mapping.

    ``DerivedModel.numeric`` validates its input on every call; a filter cycle
    evaluates the matrices thousands of times with parameters already checked
    once (:func:`named_parameters`), so this compiles the same expressions once
    (sympy lambdify with common subexpressions) and only looks values up.
    """

    def __init__(self, derived: DerivedModel):
        import sympy as sp

        model = derived.model
        self.derived = derived
        self.names = model.parameter_names
        self.defaults = model.parameter_defaults()
        self.shapes = [derived.F.shape, derived.G.shape, derived.Q.shape, derived.H.shape, derived.R.shape]
        self._function = sp.lambdify(model.parameter_symbols, [derived.F, derived.G, derived.Q, derived.H, derived.R],
                                     modules=[np], cse=True)  # module object: no `from numpy import *` (DerivedModel._numeric)

    def __call__(self, values: Mapping[str, float]) -> dict[str, np.ndarray]:
        args = [values[name] if name in values else self.defaults[name] for name in self.names]
        out = {}
        for key, value, shape in zip("F G Q H R".split(), self._function(*args), self.shapes):
            out[key] = np.broadcast_to(np.asarray(value, dtype=float), shape).copy()
        return out
