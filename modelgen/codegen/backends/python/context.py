"""The Python module template's context: one CSE'd function per model matrix, the vectorized prediction plan."""

from __future__ import annotations

import json

import numpy as np

from modelgen.codegen.backends.python.printer import PyPrinter, parameter_locals
from modelgen.codegen.description import FilterDescription, named
from modelgen.codegen.expressions import Block, eliminate_common_subexpressions, poles
from modelgen.codegen.kernels import python_filter_predict_kernel, python_predict_kernel, python_predict_plan
from modelgen.codegen.smoother import reset_inverse
from modelgen.derivation.discretization import DOUBLE_ROUNDOFF, nominal_scaling, series_range

BANNER = "# GENERATED FILE - DO NOT EDIT (modelgen)"

#: Up to this many nonzeros of F the generated discretize balances F in plain Python floats
#: (a loop over the entries) rather than numpy (about a dozen calls per sweep, whatever the
#: size).  Measured (bench/bench_python_module.py's machine, one core): ned_doppler18, 54
#: entries, 275 us in Python against 380-475 us in numpy; ned_doppler32_augmented, 87
#: entries, 505-590 us against 480-525 us.  Both add in the same order, so the norm is the
#: same to the bit either way.
PYTHON_BALANCING_ENTRIES = 64


def _print_block(block: Block, targets: list[str], printer) -> dict[str, list[tuple[str, str]]]:
    return {
        "temporaries": [(str(s), printer.doprint(e)) for s, e in block.temporaries],
        "outputs": [(t, printer.doprint(e)) for t, e in zip(targets, block.outputs)],
    }


def py_tuple(names: list[str]) -> str:
    """A Python tuple literal of strings (``("a",)`` for one)."""
    if not names:
        return "()"
    return "(" + ", ".join(json.dumps(x) for x in names) + ("," if len(names) == 1 else "") + ")"


def matrix_functions(description: FilterDescription) -> list[dict[str, object]]:
    """One generated function per model matrix (F, G, H, diag Q, diag R), each with its own CSE."""
    derived, structure, model = description.derived, description.structure, description.model
    n, nw, nm = derived.n_states, derived.n_noises, derived.n_measurements
    functions = []
    for name, doc, matrix, entries, shape in (
        ("system_matrix", "F = df/dx at the operating point p.", derived.F, structure.entries("F"), f"({n}, {n})"),
        ("noise_input_matrix", "G = df/dw at the operating point p.", derived.G, structure.entries("G"), f"({n}, {nw})"),
        ("measurement_matrix", "H = dh/dx at the operating point p.", derived.H, structure.entries("H"), f"({nm}, {n})"),
        ("noise_psd", "diag(Q): continuous noise power spectral densities.", derived.Q, [(k, k) for k in range(nw)], f"({nw},)"),
        ("measurement_variance", "diag(R): measurement noise variances.", derived.R, [(k, k) for k in range(nm)], f"({nm},)"),
    ):
        fn_block = eliminate_common_subexpressions([matrix[i, j] for i, j in entries])
        vector = shape.endswith(",)")
        fn_targets = [f"{i}" if vector else f"{i}, {j}" for i, j in entries]
        fn_poles = poles([matrix[i, j] for i, j in entries])
        locals_, printer = parameter_locals(model, fn_block, [p.argument for p in fn_poles])
        functions.append(
            {
                "name": name,
                "doc": doc,
                "shape": shape,
                "parameters": locals_,
                "poles": [
                    {"text": named(p.denominator, model), "value": printer.doprint(p.denominator), "argument": printer.doprint(p.argument)}
                    for p in fn_poles
                ],
                **_print_block(fn_block, fn_targets, printer),
            }
        )
    return functions


def index_expression(indices: list[int]) -> str:
    """A Python index for these rows: ``slice(a, b)`` for a contiguous run (a view, no gather), else a list."""
    if indices and indices == list(range(indices[0], indices[-1] + 1)):
        return f"slice({indices[0]}, {indices[-1] + 1})"
    return repr(indices)


def _balance_factors(structure, scaling: tuple[int, ...] | None) -> str | None:
    """d_j / d_i per nonzero of F (storage order) for ||F||_D with D = 2^scaling fixed at generation time; None: balance at run time."""
    if scaling is None:
        return None
    return repr([2.0 ** (scaling[j] - scaling[i]) for i, j in structure.entries("F")])


#: Above this many states the compiled kernel (numba) proves P positive definite with LAPACK's
#: dpotrf (numba's np.linalg.cholesky) rather than its own loop.  Measured (one core, bench
#: machine): 18 states loop 0.57 us against 0.82 us; 32 states 1.90 against 1.85; 100 states
#: 55 against 20.
COMPILED_LAPACK_CHOLESKY_STATES = 40


def compiled_predict_plan(structure) -> dict[str, str]:
    """The compiled predict kernel's constants: the general rows of Phi (anything but a lone diagonal entry), their CSR pattern, the diagonal rows."""
    n = structure.n_states
    general = [i for i in range(n) if [int(j) for j in np.flatnonzero(structure.Phi[i])] != [i]]
    columns = [[int(j) for j in np.flatnonzero(structure.Phi[i])] for i in general]
    starts = [0]
    for row in columns:
        starts.append(starts[-1] + len(row))
    return {
        "general": repr(general),
        "diagonal": repr([i for i in range(n) if i not in set(general)]),
        "starts": repr(starts),
        "columns": repr([j for row in columns for j in row]),
        "phi_rows": repr([int(i) for i, _ in zip(*np.nonzero(structure.Phi))]),
        "phi_cols": repr([int(j) for _, j in zip(*np.nonzero(structure.Phi))]),
        "lapack_cholesky": n > COMPILED_LAPACK_CHOLESKY_STATES,
    }


def smoother_context(description: FilterDescription) -> dict[str, object]:
    """The backward pass's constants: the model's non-identity reset block and its inverse, printed (None: G = I)."""
    reset = reset_inverse(description.derived)
    if reset is None:
        return {"reset": None}
    printer = PyPrinter()
    size = len(reset.states)
    return {"reset": {
        "states": repr(reset.states),
        "index": repr(list(reset.states)),
        "locals": [(str(symbol), index) for symbol, index in zip(reset.symbols, reset.states)],
        "entries": [(reset.states[a], reset.states[b], printer.doprint(reset.matrix[a, b]))
                    for a in range(size) for b in range(size)],
    }}


def python_context(description: FilterDescription) -> dict[str, object]:
    """Everything python_module.py.j2 reads (always the double-precision numpy filter)."""
    structure, model, options = description.structure, description.model, description.options
    return {
        **description.shared_context(),
        "banner_python": BANNER,
        "functions": matrix_functions(description),
        "plan": python_predict_plan(structure),
        "predict_kernel": python_predict_kernel(structure),
        "filter_predict_kernel": python_filter_predict_kernel(structure),
        "compiled": compiled_predict_plan(structure),
        "general_rows": index_expression(python_predict_plan(structure)["general"]),
        "van_loan": options.van_loan,
        "smoother": smoother_context(description),
        "balance_in_python": int(structure.F.sum()) <= PYTHON_BALANCING_ENTRIES,
        "balance_factors": _balance_factors(structure, nominal_scaling(description.derived)),
        "balance_start": repr(list(nominal_scaling(description.derived) or ())),
        "series_range": repr(series_range(options.taylor_order, DOUBLE_ROUNDOFF)),
        "taylor_tolerance": repr(options.taylor_tolerance)
        if options.taylor_tolerance is not None and options.taylor_tolerance > DOUBLE_ROUNDOFF
        else None,
        "f_rows": repr([i for i, _ in structure.entries("F")]),
        "f_cols": repr([j for _, j in structure.entries("F")]),
        "state_names_tuple": py_tuple(model.state_names),
        "noise_names_tuple": py_tuple(model.noise_names),
        "measurement_names_tuple": py_tuple(model.measurement_names),
        "parameter_names_tuple": py_tuple(model.parameter_names),
        "parameter_defaults_dict": "{"
        + ", ".join(f"{json.dumps(p.name)}: {float(p.value)!r}" for p in model.parameters if p.value is not None)
        + "}",
    }
