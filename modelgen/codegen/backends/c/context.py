"""The C templates' context: the description's kernels, tables and sizes printed as C."""

from __future__ import annotations

from modelgen.codegen.backends.c.literals import c_number, scalar_bytes, scalar_spellings
from modelgen.codegen.backends.c.printer import POINTERS, CPrinter, accessors, c_declarator, c_ref, c_statement
from modelgen.codegen.description import FilterDescription, named
from modelgen.codegen.kernels import KernelBlock
from modelgen.codegen.layout import CLayout, c_layout
from modelgen.codegen.structure import FilterStructure
from modelgen.derive.discretization import DOUBLE_ROUNDOFF, FLOAT_ROUNDOFF, series_range
from modelgen.errors import ModelError

BANNER = "/* GENERATED FILE - DO NOT EDIT (modelgen) */"
HASH_BANNER = "# GENERATED FILE - DO NOT EDIT (modelgen)"


def _table(values: list[int]) -> str:
    """An initializer list (``0`` for an empty table: C has no empty arrays)."""
    return ", ".join(str(v) for v in values) if values else "0"


def index_tables(structure: FilterStructure) -> dict[str, object]:
    """Row/column tables of the sparse matrices, CSR row starts, active and unit rows of Phi, Q_d pairs."""
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


def block_functions(blocks: list[KernelBlock], prefix: str) -> list[dict[str, object]]:
    """Static C functions for the unrolled kernel pieces, with the parameters each uses."""
    types = {"filter": f"const {prefix}_filter", "transition": f"const {prefix}_transition", "scratch": f"{prefix}_filter_scratch"}  # noqa: E501
    out = []
    for block in blocks:
        owners = [o for o in ("filter", "transition") if block.uses(o)] + ["scratch"]
        out.append(
            {
                "name": block.name,
                "signature": ", ".join(f"{types[o]} *restrict {POINTERS[o]}" for o in owners),
                "arguments": ", ".join(POINTERS[o] for o in owners),
                "lines": [c_statement(s) for s in block.statements],
                "checked": block.checked,
            }
        )
    return out


def _struct_list(layout: CLayout) -> list[dict[str, object]]:
    """The header's structs, in order, with their doc comments and layout fields."""
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


def structs(layout: CLayout) -> list[dict[str, object]]:
    """The header's structs with each member printed as a C declarator."""
    return [
        {**s, "fields": [{"declarator": c_declarator(f), "comment": f.comment} for f in s["fields"]]}
        for s in _struct_list(layout)
    ]


def _struct_bytes(fields, scalar_size: int) -> int:
    total = 0
    for f in fields:
        count = 1
        for d in f.dims:
            count *= d.value
        total += count * scalar_size
    return total


def struct_bytes(layout: CLayout, scalar_size: int) -> dict[str, int]:
    """Bytes of each struct, and of the workspace union (the larger scratch struct)."""
    sizes = {s["name"]: _struct_bytes(s["fields"], scalar_size) for s in _struct_list(layout)}
    sizes["workspace"] = max(sizes["discretize_scratch"], sizes["filter_scratch"])
    return sizes


def source_parts(description: FilterDescription) -> list[str]:
    """Templates included by c_source.c.j2, chosen by the options."""
    options = description.options
    parts = ["c_predict_ud.c.j2" if options.ud else "c_predict_covariance.c.j2"]
    if description.derived.n_measurements:
        if options.ud:
            parts.append("c_update_bierman.c.j2")
        elif options.update == "sequential":
            parts.append("c_update_sequential.c.j2")
        else:
            parts.append("c_update_vector.c.j2")
    return parts


def _update_doc(description: FilterDescription) -> str:
    options = description.options
    if options.ud:
        return "Bierman, one scalar measurement after another"
    kind = "one scalar measurement after another" if options.update == "sequential" else "all at once, Cholesky solve"
    return kind + (", Joseph form" if options.covariance_update == "joseph" else ", standard form")


def c_context(description: FilterDescription) -> dict[str, object]:
    """Everything the C templates (product and harness) read."""
    model, options, structure, sizes = description.model, description.options, description.structure, description.sizes
    n, nw, nm = sizes.n, sizes.nw, sizes.nm
    prefix = model.name.upper()
    tables = index_tables(structure)
    if tables["max_index"] >= 65536:
        raise ModelError(f"model {model.name!r} is too large for 16-bit index tables")
    index_type = "unsigned char" if tables["max_index"] < 256 else "unsigned short"
    spell = scalar_spellings(options.scalar)
    packed = description.packed
    at_upper, at_any = accessors(packed, prefix)
    layout = c_layout(sizes, options, prefix)
    printer = CPrinter(options.scalar, {p.sym: f"params->{p.name}" for p in model.parameters})
    targets, _, block = description.evaluation
    state_lines, state_commit, _ = description.state_predict
    blocks = description.predict_blocks[0]
    parts = source_parts(description)
    roundoff = FLOAT_ROUNDOFF if options.scalar == "float" else DOUBLE_ROUNDOFF
    return {
        **description.shared_context(),
        **spell,
        "banner_c": BANNER,
        "banner_hash": HASH_BANNER,
        "p": model.name,
        "P": prefix,
        "guard": f"MODELGEN_{prefix}_H",
        "scalar": options.scalar,
        "parameters": [
            {
                "name": p.name,
                "symbol": p.symbol,
                "unit": p.unit,
                "description": p.description,
                "default": c_number(p.value, options.scalar),
            }
            for p in model.parameters
        ],
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
        "structs": structs(layout),
        "form_macro": "FORM_UD" if options.ud else "FORM_COVARIANCE",
        "ud": options.ud,
        "sequential": options.sequential,
        "packed": packed,
        "joseph": options.covariance_update == "joseph",
        "at_upper": at_upper,
        "at_any": at_any,
        "pivot_tolerance": f"(16 * {prefix}_N_STATES * {spell['epsilon']})",
        "update_doc": _update_doc(description),
        "part_templates": parts,
        "source_templates": ["c_source.c.j2", *parts, "c_udu_factor.c.j2"],
        "evaluate": {
            "temporaries": [(str(s), printer.doprint(e)) for s, e in block.temporaries],
            "outputs": [(f"{t.matrix}[{t.k}]", printer.doprint(e)) for t, e in zip(targets, block.outputs)],
        },
        "poles": [
            {"text": named(pole.denominator, model), "value": printer.doprint(pole.denominator), "argument": printer.doprint(pole.argument)}
            for pole in description.poles
        ],
        "series_range": c_number(series_range(options.taylor_order, roundoff), options.scalar),
        "predict_state": [c_statement(s) for s in state_lines],
        "predict_state_check": [
            f"check += {ref} - {ref};"
            for ref in [c_ref(s.target) for s in state_lines] + [f"f->x[{i}]" for i in structure.unit_rows]
        ],
        "free_parameters": [p.name for p in model.parameters if p.value is None],
        "probe": next((i, j) for i, j in structure.entries("Phi") if i not in set(structure.unit_rows))
        if len(structure.unit_rows) < n
        else (0, 0),
        "predict_state_commit": [c_statement(s) for s in state_commit],
        "predict_blocks": block_functions(blocks, model.name),
        "struct_bytes": struct_bytes(layout, scalar_bytes(options.scalar)),
        "predict_reads_transition": bool(state_lines) or any(b.uses("transition") for b in blocks),
        "first_free_parameter": next((p.name for p in model.parameters if p.value is None), None),
        "example_value": c_number(0.5, options.scalar),
        "example_variance": c_number(1e-4, options.scalar),
        "example_step": c_number(1.0, options.scalar),
        "example_z": ", ".join(c_number(0.1 * (k + 1) * (-1) ** k, options.scalar) for k in range(max(nm, 1))),
    }
