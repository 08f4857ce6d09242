"""Code generation: derived model -> Python module and C99 header/source.

The pipeline is expression (``expressions``), structure and kernels
(``structure``, ``kernels``), printer (``printers``) and template
(``templates/*.j2``), as in SymForce's and CasADi's generators.  This module
only assembles the template context and writes the files, atomically: the
output folder is built next to its destination and renamed into place, so a
failure never leaves a half-written ``generated/<model>/``.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import jinja2
import sympy as sp

from modelgen import __version__
from modelgen.codegen.expressions import Block, eliminate_common_subexpressions
from modelgen.codegen.kernels import (
    OperationCount,
    c_predict,
    discretize_cost,
    python_predict_cost,
    python_predict_plan,
    update_cost,
)
from modelgen.codegen.printers import CPrinter, PyPrinter
from modelgen.codegen.structure import FilterStructure, filter_structure
from modelgen.derivation import DerivedModel
from modelgen.discretization import DEFAULT_TAYLOR_ORDER
from modelgen.errors import ModelError


@dataclass(frozen=True)
class CodegenOptions:
    """Choices that shape the generated code."""

    taylor_order: int = DEFAULT_TAYLOR_ORDER
    scalar: str = "double"  # C scalar type: double or float

    def __post_init__(self) -> None:
        if self.scalar not in ("double", "float"):
            raise ModelError(f"scalar type must be 'double' or 'float', not {self.scalar!r}")
        if not 1 <= self.taylor_order <= 30:
            raise ModelError(f"Taylor order must be between 1 and 30, not {self.taylor_order}")


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
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(template_folder())),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


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
    row_start = [0]
    for i in range(n):
        row_start.append(row_start[-1] + sum(1 for r, _ in f_entries if r == i))
    unit = set(structure.unit_rows)
    active = [(i, j) for i, j in structure.entries("Phi") if i not in unit]
    qd = [(i, j) for i, j in structure.entries("Qd") if i <= j]
    return {
        "F_row": _table([i for i, _ in f_entries]),
        "F_col": _table([j for _, j in f_entries]),
        "G_row": _table([i for i, _ in structure.entries("G")]),
        "G_col": _table([j for _, j in structure.entries("G")]),
        "H_row": _table([i for i, _ in structure.entries("H")]),
        "H_col": _table([j for _, j in structure.entries("H")]),
        "F_row_start": _table(row_start),
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


def generate_code(derived: DerivedModel, options: CodegenOptions | None = None) -> GeneratedCode:
    """Render the Python module and the C header/source for ``derived``."""
    options = options or CodegenOptions()
    model = derived.model
    if derived.nonlinear:
        raise ModelError(
            f"model {model.name!r}: equations of {', '.join(derived.nonlinear)} are not linear in the "
            "error states and noises; a linear Kalman filter cannot be generated"
        )
    structure = filter_structure(
        derived.structure("F"), derived.structure("G"), derived.structure("H"), options.taylor_order
    )
    targets, exprs = _evaluation_outputs(derived, structure)
    block = eliminate_common_subexpressions(exprs)
    n, nw, nm = derived.n_states, derived.n_noises, derived.n_measurements

    predict_state, predict_covariance, c_predict_cost = c_predict(structure)
    costs = {
        "matrices_evaluate": OperationCount(block.operation_count, 0),
        "discretize": discretize_cost(structure, options.taylor_order),
        "predict (C)": c_predict_cost,
        "predict (Python)": python_predict_cost(structure),
        "predict (dense, for comparison)": OperationCount(2 * n**3 + n, 2 * n * n * (n - 1) + n * n),
    }
    if nm:
        costs["update"] = update_cost(structure)
    cost_lines = [
        f"{name}: {cost}" if name != "matrices_evaluate" else f"{name}: {cost.multiplications} operations after CSE"
        for name, cost in costs.items()
    ]

    parameters = [
        {
            "name": p.name,
            "symbol": p.symbol,
            "unit": p.unit,
            "description": p.description.replace("*/", "* /"),
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
        "banner_c": "/* GENERATED FILE - DO NOT EDIT (modelgen) */",
        "banner_python": "# GENERATED FILE - DO NOT EDIT (modelgen)",
    }

    c_printer = CPrinter(options.scalar, {p.sym: f"params->{p.name}" for p in model.parameters})
    c_context = {
        **common,
        "p": model.name,
        "P": model.name.upper(),
        "guard": f"MODELGEN_{model.name.upper()}_H",
        "scalar": options.scalar,
        "one": "1.0F" if options.scalar == "float" else "1.0",
        "zero": "0.0F" if options.scalar == "float" else "0.0",
        "sqrt": "sqrtf" if options.scalar == "float" else "sqrt",
        "parameters": parameters,
        "nnz_f": int(structure.F.sum()),
        "nnz_g": int(structure.G.sum()),
        "nnz_h": int(structure.H.sum()),
        "dim_w": max(nw, 1),
        "dim_m": max(nm, 1),
        "dim_g": max(int(structure.G.sum()), 1),
        "dim_h": max(int(structure.H.sum()), 1),
        "index_type": index_type,
        "tables": tables,
        "evaluate": _print_block(block, targets, c_printer),
        "predict_state": predict_state,
        "predict_covariance": predict_covariance,
    }

    py_printer = PyPrinter({p.sym: f"p[{k}]" for k, p in enumerate(model.parameters)})
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
        functions.append({"name": name, "doc": doc, "shape": shape, **_print_block(fn_block, fn_targets, py_printer)})

    qd_entries = structure.entries("Qd")
    py_context = {
        **common,
        "functions": functions,
        "plan": python_predict_plan(structure),
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

    env = _environment()
    files = {
        f"{model.name}.py": env.get_template("python_module.py.j2").render(py_context),
        f"{model.name}.h": env.get_template("c_header.h.j2").render(c_context),
        f"{model.name}.c": env.get_template("c_source.c.j2").render(c_context),
    }
    return GeneratedCode(model=model.name, files=files, costs=costs)


def _py_tuple(names: list[str]) -> str:
    if not names:
        return "()"
    return "(" + ", ".join(json.dumps(x) for x in names) + ("," if len(names) == 1 else "") + ")"


def write_atomically(folder: Path, files: dict[str, str]) -> Path:
    """Replace ``folder`` by exactly ``files``, never leaving it half-written."""
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        for name, text in sorted(files.items()):
            target = staging / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8", newline="\n")
        old = None
        if folder.exists():
            old = folder.with_name(f".{folder.name}.old")
            if old.exists():
                shutil.rmtree(old)
            os.replace(folder, old)
        os.replace(staging, folder)
        if old is not None:
            shutil.rmtree(old)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return folder
