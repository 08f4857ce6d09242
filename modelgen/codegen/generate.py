"""Code generation: derived model -> Python module and C99 header/source.

The pipeline is expression (``expressions``), structure and kernels
(``structure``, ``kernels``), memory layout (``layout``), printer
(``printers``) and template (``templates/*.j2``), as in SymForce's and
CasADi's generators; ``options`` says which filter variant is wanted.  Besides
the code, the C folder gets a CMakeLists.txt, a Makefile and a README with a
usage example, so that it can be dropped into another build as it is.  This module
only assembles the template context and writes the files, atomically: the
output folder is built next to its destination and renamed into place, so a
failure never leaves a half-written ``generated/<model>/``.
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import dataclass, field
from typing import Callable
from importlib import resources
from pathlib import Path

import jinja2
import sympy as sp

from modelgen import __version__
from modelgen.codegen.contract import contract_markdown, contract_text
from modelgen.codegen.escape import FILTERS
from modelgen.codegen.expressions import Block, eliminate_common_subexpressions, poles
from modelgen.codegen.kernels import (
    KernelBlock,
    OperationCount,
    c_covariance_predict,
    c_state_predict,
    c_ud_weights,
    discretize_cost,
    doubling_cost,
    estimated_code_bytes,
    python_predict_cost,
    python_predict_plan,
    thornton_cost,
    update_cost,
)
from modelgen.codegen.layout import CLayout, ModelSizes, c_layout
from modelgen.codegen.options import CodegenOptions
from modelgen.codegen.printers import CPrinter, PyPrinter
from modelgen.codegen.structure import FilterStructure, filter_structure
from modelgen.derivation import DerivedModel
from modelgen.discretization import DOUBLE_ROUNDOFF, FLOAT_ROUNDOFF, series_range
from modelgen.errors import ModelError
from modelgen.output import write_atomically  # noqa: F401  (re-exported: the one atomic writer lives in modelgen.output)

__all__ = ["CodegenOptions", "GeneratedCode", "generate_code", "render_c_template", "write_atomically", "template_folder"]


@dataclass(frozen=True)
class GeneratedCode:
    """File name -> text, plus the operation counts written into the files."""

    model: str
    files: dict[str, str]
    costs: dict[str, OperationCount] = field(default_factory=dict)


def template_folder() -> Path:
    """Installed templates (wheel) or the repository's templates/ (editable)."""
    packaged = resources.files("modelgen") / "templates"
    if packaged.is_dir():
        return Path(str(packaged))
    return Path(__file__).resolve().parents[2] / "templates"


def _environment() -> jinja2.Environment:
    """The templates' environment, with one escaping filter per output language (``escape``)."""
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_folder())),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,  # HTML escaping: none of the output languages is HTML (see escape)
    )
    env.filters.update(FILTERS)
    return env


def _evaluation_outputs(derived: DerivedModel, structure: FilterStructure) -> tuple[list[str], list[sp.Expr]]:
    """Targets (``F[3]``) and expressions of every nonzero model-matrix entry."""
    targets: list[str] = []
    exprs: list[sp.Expr] = []
    for name, matrix in (("F", derived.F), ("G", derived.G), ("H", derived.H)):
        for k, (i, j) in enumerate(structure.entries(name)):
            targets.append(f"{name}[{k}]")
            exprs.append(matrix[i, j])
    for name, matrix in (("q", derived.Q), ("r", derived.R)):
        for k in range(matrix.shape[0]):
            targets.append(f"{name}[{k}]")
            exprs.append(matrix[k, k])
    return targets, exprs


def _print_block(block: Block, targets: list[str], printer) -> dict[str, list[tuple[str, str]]]:
    return {
        "temporaries": [(str(s), printer.doprint(e)) for s, e in block.temporaries],
        "outputs": [(t, printer.doprint(e)) for t, e in zip(targets, block.outputs)],
    }


def _c_number(value: float | None, scalar: str) -> str:
    text = repr(float(value or 0.0))
    if "e" not in text and "." not in text:
        text += ".0"
    return text + ("F" if scalar == "float" else "")


def _table(values: list[int]) -> str:
    return ", ".join(str(v) for v in values) if values else "0"


def _c_tables(structure: FilterStructure) -> dict[str, object]:
    n = structure.n_states
    f_entries = structure.entries("F")
    h_entries = structure.entries("H")
    row_start = [0]
    for i in range(n):
        row_start.append(row_start[-1] + sum(1 for r, _ in f_entries if r == i))
    h_row_start = [0]
    for a in range(structure.H.shape[0]):
        h_row_start.append(h_row_start[-1] + sum(1 for r, _ in h_entries if r == a))
    unit = set(structure.unit_rows)
    active = [(i, j) for i, j in structure.entries("Phi") if i not in unit]
    qd = [(i, j) for i, j in structure.entries("Qd") if i <= j]
    return {
        "F_row": _table([i for i, _ in f_entries]),
        "F_col": _table([j for _, j in f_entries]),
        "G_row": _table([i for i, _ in structure.entries("G")]),
        "G_col": _table([j for _, j in structure.entries("G")]),
        "H_row": _table([i for i, _ in h_entries]),
        "H_col": _table([j for _, j in h_entries]),
        "F_row_start": _table(row_start),
        "H_row_start": _table(h_row_start),
        "n_active": len(active),
        "active_row": _table([i for i, _ in active]),
        "active_col": _table([j for _, j in active]),
        "n_unit": len(unit),
        "unit_row": _table(sorted(unit)),
        "n_qd": len(qd),
        "qd_row": _table([i for i, _ in qd]),
        "qd_col": _table([j for _, j in qd]),
        "max_index": max([n, len(f_entries), len(active), len(qd)]),
    }


def _accessors(packed: bool) -> tuple[Callable[[str, str, str], str], Callable[[str, str, str], str]]:
    """C text for entry (i, j) of a symmetric matrix: (i <= j only, any i, j)."""
    if packed:
        return (lambda base, i, j: f"{base}[PACKED_UPPER({i}, {j})]", lambda base, i, j: f"{base}[PACKED_ANY({i}, {j})]")
    return (lambda base, i, j: f"{base}[{i}][{j}]", lambda base, i, j: f"{base}[{i}][{j}]")


def _c_parts(options: CodegenOptions, has_measurements: bool) -> list[str]:
    """Templates included by c_source.c.j2, chosen by the options."""
    parts = ["c_predict_ud.c.j2" if options.ud else "c_predict_covariance.c.j2"]
    if has_measurements:
        if options.ud:
            parts.append("c_update_bierman.c.j2")
        elif options.update == "sequential":
            parts.append("c_update_sequential.c.j2")
        else:
            parts.append("c_update_vector.c.j2")
    return parts


def _block_functions(blocks: list[KernelBlock], prefix: str) -> list[dict[str, object]]:
    """Static C functions for the unrolled kernel pieces, with the parameters each uses."""
    out = []
    for block in blocks:
        params = [
            f"const {prefix}_filter *f" if block.uses("f") else None,
            f"const {prefix}_transition *t" if block.uses("t") else None,
            f"{prefix}_filter_scratch *w",
        ]
        out.append(
            {
                "name": block.name,
                "signature": ", ".join(p for p in params if p),
                "arguments": ", ".join(a for a, p in zip(("f", "t", "w"), params) if p),
                "lines": list(block.lines),
                "checked": block.checked,
            }
        )
    return out


def _structs(layout: CLayout) -> list[dict[str, object]]:
    return [
        {"name": "matrices", "doc": "Structural nonzeros of F, G, H (row, column pairs in the tables below).", "fields": layout.matrices},
        {"name": "transition", "doc": "The transition over one step T (from discretize).", "fields": layout.transition},
        {"name": "filter", "doc": "The filter state: estimate and covariance (or its factors).", "fields": layout.filter},
        {"name": "discretize_scratch", "doc": "Scratch memory of discretize.", "fields": layout.discretize_scratch},
        {
            "name": "filter_scratch",
            "doc": "Scratch memory of predict, update and set_covariance.",
            "fields": layout.filter_scratch,
        },
    ]


def _struct_bytes(fields, scalar_size: int) -> int:
    total = 0
    for f in fields:
        count = 1
        for d in f.dims:
            count *= d.value
        total += count * scalar_size
    return total


def _all_struct_bytes(layout: CLayout, scalar_size: int) -> dict[str, int]:
    """Bytes of each struct, and of the workspace union (the larger scratch struct)."""
    sizes = {s["name"]: _struct_bytes(s["fields"], scalar_size) for s in _structs(layout)}
    sizes["workspace"] = max(sizes["discretize_scratch"], sizes["filter_scratch"])
    return sizes


def _costs(structure: FilterStructure, options: CodegenOptions, evaluate_ops: int, nm: int) -> dict[str, OperationCount]:
    n = structure.n_states
    _, _, state_cost = c_state_predict(structure)
    if options.ud:
        _, weights_cost = c_ud_weights(structure)
        sweep = thornton_cost(structure)
        predict = OperationCount(
            state_cost.multiplications + weights_cost.multiplications + sweep.multiplications,
            state_cost.additions + weights_cost.additions + sweep.additions,
        )
    else:
        _, cov_cost = c_covariance_predict(structure, options.packed)
        predict = OperationCount(
            state_cost.multiplications + cov_cost.multiplications, state_cost.additions + cov_cost.additions
        )
    costs = {
        "matrices_evaluate": OperationCount(evaluate_ops, 0),
        "discretize": discretize_cost(structure, options.taylor_order),
        "discretize, each doubling (long steps)": doubling_cost(structure),
        "predict (C)": predict,
        "predict (Python)": python_predict_cost(structure),
        "predict (dense, for comparison)": OperationCount(2 * n**3 + n, 2 * n * n * (n - 1) + n * n),
    }
    if nm:
        costs["update"] = update_cost(structure, options)
    return costs


def _contexts(derived: DerivedModel, options: CodegenOptions) -> tuple[dict, dict, dict[str, OperationCount]]:
    """Template contexts for the C files and the Python module, and the kernel costs."""
    model = derived.model
    if derived.nonlinear:
        raise ModelError(
            f"model {model.name!r}: equations of {', '.join(derived.nonlinear)} are not linear in the "
            "error states and noises; a linear Kalman filter cannot be generated"
        )
    structure = filter_structure(
        derived.structure("F"), derived.structure("G"), derived.structure("H"), options.taylor_order
    )
    warn_if_large(model.name, structure)
    targets, exprs = _evaluation_outputs(derived, structure)
    block = eliminate_common_subexpressions(exprs)
    n, nw, nm = derived.n_states, derived.n_noises, derived.n_measurements
    sizes = ModelSizes.of(derived)
    prefix = model.name.upper()
    costs = _costs(structure, options, block.operation_count, nm)
    cost_lines = [
        f"{name}: {cost}" if name != "matrices_evaluate" else f"{name}: {cost.multiplications} operations after CSE"
        for name, cost in costs.items()
    ]

    parameters = [
        {
            "name": p.name,
            "symbol": p.symbol,
            "unit": p.unit,
            "description": p.description,
            "default": _c_number(p.value, options.scalar),
        }
        for p in model.parameters
    ]
    tables = _c_tables(structure)
    index_type = "unsigned char" if tables["max_index"] < 256 else "unsigned short"
    if tables["max_index"] >= 65536:
        raise ModelError(f"model {model.name!r} is too large for 16-bit index tables")

    common = {
        "model": model,
        "version": __version__,
        "n_states": n,
        "n_noises": nw,
        "n_measurements": nm,
        "taylor_order": options.taylor_order,
        "state_names": model.state_names,
        "cost_lines": cost_lines,
        "description": options.describe(),
        "banner_c": "/* GENERATED FILE - DO NOT EDIT (modelgen) */",
        "banner_python": "# GENERATED FILE - DO NOT EDIT (modelgen)",
        "banner_hash": "# GENERATED FILE - DO NOT EDIT (modelgen)",
        "contract_text": contract_text("  "),
        "contract_markdown": contract_markdown(),
    }

    packed = options.packed and not options.ud
    at_upper, at_any = _accessors(packed)
    state_lines, state_commit, _ = c_state_predict(structure)
    layout = c_layout(sizes, options, prefix)
    parts = _c_parts(options, bool(nm))
    one = "1.0F" if options.scalar == "float" else "1.0"
    epsilon = "FLT_EPSILON" if options.scalar == "float" else "DBL_EPSILON"
    scalar_size = 4 if options.scalar == "float" else 8
    c_printer = CPrinter(options.scalar, {p.sym: f"params->{p.name}" for p in model.parameters})
    c_context = {
        **common,
        "p": model.name,
        "P": prefix,
        "guard": f"MODELGEN_{prefix}_H",
        "scalar": options.scalar,
        "one": one,
        "zero": "0.0F" if options.scalar == "float" else "0.0",
        "sqrt": "sqrtf" if options.scalar == "float" else "sqrt",
        "fabs": "fabsf" if options.scalar == "float" else "fabs",
        "half": "0.5F" if options.scalar == "float" else "0.5",
        "epsilon": epsilon,
        "parameters": parameters,
        "nnz_f": sizes.nnz_f,
        "nnz_g": sizes.nnz_g,
        "nnz_h": sizes.nnz_h,
        "n_packed": sizes.packed,
        "n_upper": max(sizes.upper, 1),
        "n_upper_real": sizes.upper,
        "n_weights": n + nw,
        "dim_f": max(sizes.nnz_f, 1),
        "dim_w": max(nw, 1),
        "dim_m": max(nm, 1),
        "dim_g": max(sizes.nnz_g, 1),
        "dim_h": max(sizes.nnz_h, 1),
        "index_type": index_type,
        "tables": tables,
        "structs": _structs(layout),
        "form_macro": "FORM_UD" if options.ud else "FORM_COVARIANCE",
        "ud": options.ud,
        "sequential": options.sequential,
        "packed": packed,
        "joseph": options.covariance_update == "joseph",
        "at_upper": at_upper,
        "at_any": at_any,
        "pivot_tolerance": f"(16 * N * {epsilon})",
        "update_doc": (
            "Bierman, one scalar measurement after another"
            if options.ud
            else ("one scalar measurement after another" if options.update == "sequential" else "all at once, Cholesky solve")
            + (", Joseph form" if options.covariance_update == "joseph" else ", standard form")
        ),
        "part_templates": parts,
        "source_templates": ["c_source.c.j2", *parts, "c_udu_factor.c.j2"],
        "evaluate": _print_block(block, targets, c_printer),
        "poles": [
            {"text": _named(pole.denominator, model), "value": c_printer.doprint(pole.denominator), "argument": c_printer.doprint(pole.argument)}
            for pole in poles(exprs)
        ],
        "series_range": _c_number(series_range(options.taylor_order, FLOAT_ROUNDOFF if options.scalar == "float" else DOUBLE_ROUNDOFF), options.scalar),
        "predict_state": state_lines,
        "predict_state_check": [
            f"check += {ref} - {ref};"
            for ref in [line.split(" = ")[0] for line in state_lines] + [f"f->x[{i}]" for i in structure.unit_rows]
        ],
        "free_parameters": [p.name for p in model.parameters if p.value is None],
        "probe": next((i, j) for i, j in structure.entries("Phi") if i not in set(structure.unit_rows))
        if len(structure.unit_rows) < n
        else (0, 0),
        "predict_state_commit": state_commit,
        "predict_blocks": _block_functions(
            c_ud_weights(structure)[0] if options.ud else c_covariance_predict(structure, packed)[0], model.name
        ),
        "struct_bytes": _all_struct_bytes(layout, scalar_size),
        "predict_reads_transition": bool(state_lines)
        or any(block.uses("t") for block in (c_ud_weights(structure)[0] if options.ud else c_covariance_predict(structure, packed)[0])),
        "first_free_parameter": next((p.name for p in model.parameters if p.value is None), None),
        "example_value": _c_number(0.5, options.scalar),
        "example_variance": _c_number(1e-4, options.scalar),
        "example_step": _c_number(1.0, options.scalar),
        "example_z": ", ".join(_c_number(0.1 * (k + 1) * (-1) ** k, options.scalar) for k in range(max(nm, 1))),
    }

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
        locals_, printer = _python_parameter_locals(model, fn_block, [p.argument for p in fn_poles])
        functions.append(
            {
                "name": name,
                "doc": doc,
                "shape": shape,
                "parameters": locals_,
                "poles": [
                    {"text": _named(p.denominator, model), "value": printer.doprint(p.denominator), "argument": printer.doprint(p.argument)}
                    for p in fn_poles
                ],
                **_print_block(fn_block, fn_targets, printer),
            }
        )

    qd_entries = structure.entries("Qd")
    py_context = {
        **common,
        "functions": functions,
        "plan": python_predict_plan(structure),
        "series_range": repr(series_range(options.taylor_order, DOUBLE_ROUNDOFF)),
        "f_rows": repr([i for i, _ in structure.entries("F")]),
        "f_cols": repr([j for _, j in structure.entries("F")]),
        "qd_rows": [i for i, _ in qd_entries],
        "qd_cols": [j for _, j in qd_entries],
        "state_names_tuple": _py_tuple(model.state_names),
        "noise_names_tuple": _py_tuple(model.noise_names),
        "measurement_names_tuple": _py_tuple(model.measurement_names),
        "parameter_names_tuple": _py_tuple(model.parameter_names),
        "parameter_defaults_dict": "{"
        + ", ".join(f"{json.dumps(p.name)}: {float(p.value)!r}" for p in model.parameters if p.value is not None)
        + "}",
    }

    return c_context, py_context, costs


class GeneratedSizeWarning(UserWarning):
    """The model's generated code will be unusually large (see :data:`LARGE_CODE_BYTES`)."""


#: Above this estimated size of the generated files a model gets a warning: 2 MB is about
#: 13 times the paper's 18-state model (160 kB), or roughly 110,000 unrolled flops in
#: predict; straight-line C of that size takes gcc -O2 minutes and hundreds of MB, and its
#: object code no longer fits the flash of a typical Cortex-M4 (1 MB).
LARGE_CODE_BYTES = 2_000_000


def warn_if_large(name: str, structure: FilterStructure) -> None:
    """``warnings.warn`` a :class:`GeneratedSizeWarning` with the expected size when above the threshold."""
    expected = estimated_code_bytes(structure)
    if expected > LARGE_CODE_BYTES:
        warnings.warn(
            f"model {name!r} is large: its generated code will be about {expected / 1e6:.1f} MB "
            f"({structure.n_states} states, {int(structure.Phi.sum())} structural nonzeros in Phi), "
            f"above the {LARGE_CODE_BYTES / 1e6:.0f} MB at which compiling it gets slow and it outgrows "
            "a microcontroller's flash; a reduced model (keep_states, markov_to_white) is smaller",
            GeneratedSizeWarning,
            stacklevel=3,
        )


def generate_code(derived: DerivedModel, options: CodegenOptions | None = None) -> GeneratedCode:
    """Render the Python module, the C header/source and the C build files for ``derived``."""
    options = options or CodegenOptions()
    model = derived.model
    c_context, py_context, costs = _contexts(derived, options)
    env = _environment()
    files = {
        f"{model.name}.py": env.get_template("python_module.py.j2").render(py_context),
        f"{model.name}.h": env.get_template("c_header.h.j2").render(c_context),
        f"{model.name}.c": env.get_template("c_source.c.j2").render(c_context),
        "CMakeLists.txt": env.get_template("c_cmakelists.txt.j2").render(c_context),
        "Makefile": env.get_template("c_makefile.j2").render(c_context),
        "README.md": env.get_template("c_readme.md.j2").render(c_context),
    }
    return GeneratedCode(model=model.name, files=files, costs=costs)


def render_c_template(derived: DerivedModel, options: CodegenOptions, template: str, **extra: object) -> str:
    """Render another C template (test driver, firmware main) with the filter's context.

    Used for files that go with a generated filter but are not part of it,
    so that they always agree with its names, sizes and scalar type.
    """
    c_context, _, _ = _contexts(derived, options)
    return _environment().get_template(template).render({**c_context, **extra})


_PYTHON_TAKEN = re.compile(r"^(t\d+|p|out|np|math)$")


def _python_parameter_locals(model, block: Block, extra: list[sp.Expr] = ()) -> tuple[list[tuple[str, int]], PyPrinter]:
    """Parameters a generated Python function uses, unpacked into locals named as in the model.

    ``latitude = p[0]`` reads better than ``p[0]`` in every expression; a
    parameter whose name would clash with the function's own names (``p``,
    ``out``, ``np``, ``math``, temporaries ``t<k>``) stays ``p[k]``.
    """
    used = set().union(
        *(e.free_symbols for _, e in block.temporaries), *(e.free_symbols for e in block.outputs), *(e.free_symbols for e in extra)
    )
    renames, locals_ = {}, []
    for k, par in enumerate(model.parameters):
        if par.sym not in used:
            continue
        if _PYTHON_TAKEN.match(par.name):
            renames[par.sym] = f"p[{k}]"
        else:
            renames[par.sym] = par.name
            locals_.append((par.name, k))
    return locals_, PyPrinter(renames)


def _named(expr: sp.Expr, model) -> str:
    """``expr`` as text with parameters by name (``cos(latitude)``, not ``cos(phi)``), for messages."""
    return str(expr.subs({p.sym: sp.Symbol(p.name) for p in model.parameters}, simultaneous=True))


def _py_tuple(names: list[str]) -> str:
    if not names:
        return "()"
    return "(" + ", ".join(json.dumps(x) for x in names) + ("," if len(names) == 1 else "") + ")"
