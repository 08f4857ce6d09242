"""F, G, H, Q, R of a derived model as text, JSON, LaTeX and an Octave function file.

Every format lists the structurally nonzero entries of the five matrices of
``dx/dt = F x + G w`` (w with power spectral density Q) and ``z = H x + v``
(v with covariance R), 1-based as in a paper, each entry printed by
:func:`modelgen.export.readable.readable`.  Rows and columns are named by the
model's quantities: F is states x states, G states x noises, H measurements x
states, Q noises x noises, R measurements x measurements.  Free text from the
model file (title, names, units) goes through the escapers of
:mod:`modelgen.codegen.escape`; symbols are identifiers the model loader has
already checked.  Every function is pure: the same model gives the same text.
"""

from __future__ import annotations

import json
import keyword
import re
from typing import Any

import sympy as sp

from modelgen.codegen.escape import latex_text, octave_comment, octave_string, one_line
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.export.readable import MATRIX_NAMES, nonzero_entries, readable
from modelgen.model.declaration import ErrorModel, Quantity

#: ``modelgen derive --format`` choices (casadi lives in :mod:`modelgen.export.casadi_file`).
TEXT_FORMATS = ("text", "json", "latex", "octave")
JSON_FORMAT_VERSION = 1

#: Octave keywords and the names the exported function uses itself: never a local variable name.
_OCTAVE_RESERVED = frozenset(
    """__FILE__ __LINE__ break case catch classdef continue do else elseif end end_try_catch
    end_unwind_protect endclassdef endenumeration endevents endfor endfunction endif endmethods
    endparfor endproperties endspecification endswitch endwhile enumeration events for function
    global if methods otherwise parfor persistent properties return switch try until
    unwind_protect unwind_protect_cleanup while p F G H Q R zeros isfield error pi e i j I J
    Inf NaN eps sin cos tan sec csc cot asin acos atan atan2 sinh cosh tanh exp log sqrt abs
    sign min max""".split()
)


def quantities(model: ErrorModel, matrix: str) -> tuple[tuple[Quantity, ...], tuple[Quantity, ...]]:
    """The quantities that name the rows and the columns of ``matrix`` (one of F, G, H, Q, R)."""
    states, noises, measurements = tuple(model.states), tuple(model.noises), tuple(model.measurements)
    return {
        "F": (states, states),
        "G": (states, noises),
        "H": (measurements, states),
        "Q": (noises, noises),
        "R": (measurements, measurements),
    }[matrix]


def matrix_entries(derived: DerivedModel) -> list[tuple[str, int, int, sp.Expr]]:
    """Every nonzero entry of F, G, H, Q, R in readable form: (matrix, row, column, entry), 1-based."""
    return [(name, i, j, readable(e)) for name in MATRIX_NAMES for i, j, e in nonzero_entries(getattr(derived, name))]


# -- text ---------------------------------------------------------------------
def to_text(derived: DerivedModel) -> str:
    """What ``modelgen derive`` prints: a header line, then one line per nonzero entry of F, G, H, Q, R."""
    model = derived.model
    lines = [f"model {model.name}: {derived.n_states} states, {derived.n_noises} noises, {derived.n_measurements} measurements"]
    for name, i, j, entry in matrix_entries(derived):
        rows, columns = quantities(model, name)
        lines.append(f"{name}({i},{j}) [{rows[i - 1].name}, {columns[j - 1].name}] = {sp.sstr(entry)}")
    return "\n".join(lines) + "\n"


# -- JSON ---------------------------------------------------------------------
def _quantity_record(q: Quantity) -> dict[str, Any]:
    record = {"name": q.name, "symbol": q.symbol, "unit": q.unit, "description": q.description}
    if getattr(q, "value", None) is not None:
        record["value"] = q.value
    return record


def to_json(derived: DerivedModel) -> str:
    """The matrices as JSON: quantities and parameters, then per matrix its shape and nonzero entries.

    Each entry's ``expression`` is a sympy string in the parameter symbols
    (``sympy.sympify`` reads it back with real symbols of those names); rows
    and columns are 1-based and name their quantity.
    """
    model = derived.model
    matrices: dict[str, Any] = {}
    kinds = {"F": ("states", "states"), "G": ("states", "noises"), "H": ("measurements", "states"), "Q": ("noises", "noises"), "R": ("measurements", "measurements")}
    for name in MATRIX_NAMES:
        rows, columns = quantities(model, name)
        matrices[name] = {
            "shape": list(getattr(derived, name).shape),
            "rows": kinds[name][0],
            "columns": kinds[name][1],
            "entries": [
                {"row": i, "column": j, "row_quantity": rows[i - 1].name, "column_quantity": columns[j - 1].name, "expression": sp.sstr(entry)}
                for m, i, j, entry in matrix_entries(derived)
                if m == name
            ],
        }
    data = {
        "format": "modelgen-matrices",
        "format_version": JSON_FORMAT_VERSION,
        "model": model.name,
        "title": getattr(model, "title", "") or "",
        "system": "dx/dt = F x + G w, E[w w'] = Q delta(t); z = H x + v, E[v v'] = R",
        "parameters": [_quantity_record(p) for p in model.parameters],
        "states": [_quantity_record(s) for s in model.states],
        "noises": [_quantity_record(w) for w in model.noises],
        "measurements": [_quantity_record(m) for m in model.measurements],
        "matrices": matrices,
    }
    return json.dumps(data, indent=2, ensure_ascii=False) + "\n"


# -- LaTeX --------------------------------------------------------------------
#: the quantity and value columns' widths as fractions of \linewidth; with the entry column (at most
#: "$R(12,12)$") and the column gaps the table is at most the text width (tests/export: pdflatex, A4 and letter)
LATEX_QUANTITY_WIDTH = 0.28
LATEX_VALUE_WIDTH = 0.50
#: a paragraph column set ragged right (array package), so long names and values break instead of overflowing
LATEX_TEXT_COLUMN = ">{\\raggedright\\arraybackslash}p"


#: an entry whose LaTeX is longer than this many characters may be wider than its column: it is printed in a
#: form TeX can break (see :func:`_latex_entry`)
LATEX_LONG_ENTRY = 90


def _latex_entry(entry: sp.Expr) -> str:
    """An entry as LaTeX math that fits its column: as sympy prints it, or, when long, with a long numerator
    split off its fraction (``\\frac{1}{R_{M} + h} (...)``) and ``\\bigl( \\bigr)`` for ``\\left( \\right)``, so that
    TeX may break the line after any + or - (it breaks no line inside a fraction or a ``\\left``-``\\right`` pair)."""
    text = sp.latex(entry)
    if len(text) <= LATEX_LONG_ENTRY:
        return text
    text = sp.latex(entry, long_frac_ratio=1.5)
    return text.replace("\\left(", "\\bigl(").replace("\\right)", "\\bigr)")


def _breakable(text: str) -> str:
    """Escaped LaTeX text that may break after each underscore (state names are long, spaceless words)."""
    return text.replace("\\_", "\\_\\allowbreak{}")


def to_latex(derived: DerivedModel) -> str:
    """A ``longtable`` of the nonzero entries, like a paper's table, in the model's symbols.

    The file is a fragment to ``\\input`` into a document that loads the
    ``longtable``, ``array`` and ``amsmath`` packages; entries are math (``sympy.latex``:
    ``omega_ie`` prints as ``\\omega_{ie}``), names and the title are text.
    """
    model = derived.model
    title = getattr(model, "title", "") or model.name
    lines = [
        f"% F, G, H, Q, R of model {one_line(model.name)}, written by modelgen derive --format latex.",
        "% Needs \\usepackage{longtable,array,amsmath}. dx/dt = F x + G w (PSD Q), z = H x + v (covariance R).",
        "% The columns are fixed fractions of \\linewidth (names break after an underscore, values after a",
        "% top-level + or -), so the table fits the text width of an A4 or letter page.",
        f"\\begin{{longtable}}{{@{{}}l{LATEX_TEXT_COLUMN}{{{LATEX_QUANTITY_WIDTH}\\linewidth}}"
        f"{LATEX_TEXT_COLUMN}{{{LATEX_VALUE_WIDTH}\\linewidth}}@{{}}}}",
        f"\\caption{{Nonzero entries of F, G, H, Q, R: {latex_text(title)}}}\\\\",
        "\\hline",
        "Entry & Row / column & Value \\\\",
        "\\hline",
        "\\endhead",
    ]
    for name, i, j, entry in matrix_entries(derived):
        rows, columns = quantities(model, name)
        where = f"{_breakable(latex_text(rows[i - 1].name))} /\\newline {_breakable(latex_text(columns[j - 1].name))}"
        lines.append(f"${name}({i},{j})$ & {where} & ${_latex_entry(entry)}$ \\\\")
    lines += ["\\hline", "\\end{longtable}", ""]
    return "\n".join(lines)


# -- Octave -------------------------------------------------------------------
_IDENTIFIER = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def octave_function_name(model: ErrorModel, requested: str | None = None) -> str:
    """The exported function's name: ``requested`` (a file's stem) or ``<model>_matrices``; refused if not an Octave identifier."""
    name = requested or f"{model.name}_matrices"
    if not _IDENTIFIER.match(name) or name in _OCTAVE_RESERVED or keyword.iskeyword(name) or len(name) > 63:
        raise ModelError(f"{name!r} is not a usable Octave function name (letters, digits, _; starting with a letter; at most 63)")
    return name


def octave_locals(model: ErrorModel) -> dict[sp.Symbol, sp.Symbol]:
    """Each parameter symbol -> the local variable name it gets in Octave (a reserved or taken name gets a trailing _)."""
    taken: set[str] = set(_OCTAVE_RESERVED)
    out = {}
    for p in model.parameters:
        name = p.symbol
        while name in taken:
            name += "_"
        taken.add(name)
        out[p.sym] = sp.Symbol(name, real=True)
    return out


def to_octave(derived: DerivedModel, function_name: str | None = None) -> str:
    """An Octave/MATLAB function file: ``[F, G, H, Q, R] = NAME(p)`` with ``p`` a struct of parameter values.

    The struct's fields are the parameters' spelled-out names (``p.latitude``);
    a parameter with a default value may be left out; a missing one without
    default is an error naming it.  The file must be saved as ``NAME.m``.
    """
    model = derived.model
    name = octave_function_name(model, function_name)
    local = octave_locals(model)
    title = getattr(model, "title", "") or model.name
    lines = [
        f"function [F, G, H, Q, R] = {name}(p)",
        f"% {name.upper()}  F, G, H, Q, R of model {octave_comment(model.name)}: {octave_comment(title)}",
        "%   dx/dt = F x + G w (w with power spectral density Q); z = H x + v (v with covariance R).",
        f"%   States ({len(model.states)}): " + octave_comment(", ".join(s.name for s in model.states)),
        f"%   Noises ({len(model.noises)}): " + octave_comment(", ".join(w.name for w in model.noises)),
        f"%   Measurements ({len(model.measurements)}): " + octave_comment(", ".join(m.name for m in model.measurements)),
        "%   p: struct of parameter values, one field per parameter (SI units):",
    ]
    for q in model.parameters:
        default = f", default {q.value!r}" if q.value is not None else ""
        lines.append(f"%     p.{q.name} ({octave_comment(q.symbol)}, {octave_comment(q.unit)}{default}): {octave_comment(q.description)}")
    lines += ["%   Written by modelgen derive --format octave.", ""]
    for q in model.parameters:
        var = local[q.sym].name
        if q.value is not None:
            lines.append(f"  if isfield(p, '{q.name}'), {var} = p.{q.name}; else, {var} = {float(q.value)!r}; end")
        else:
            message = octave_string(f"{name}: parameter {q.name} ({q.symbol}) is missing")
            lines.append(f"  if ~isfield(p, '{q.name}'), error({message}); end")
            lines.append(f"  {var} = p.{q.name};")
    for matrix in MATRIX_NAMES:
        rows, columns = getattr(derived, matrix).shape
        lines += ["", f"  {matrix} = zeros({rows}, {columns});"]
        for m, i, j, entry in matrix_entries(derived):
            if m == matrix:
                lines.append(f"  {matrix}({i}, {j}) = {sp.octave_code(entry.xreplace(local))};")
    lines += ["end", ""]
    return "\n".join(lines)


def to_format(derived: DerivedModel, fmt: str, name: str | None = None) -> str:
    """``derived`` in one of :data:`TEXT_FORMATS` (``name``: the Octave function name)."""
    if fmt == "text":
        return to_text(derived)
    if fmt == "json":
        return to_json(derived)
    if fmt == "latex":
        return to_latex(derived)
    if fmt == "octave":
        return to_octave(derived, name)
    raise ModelError(f"unknown export format {fmt!r} (choose one of {', '.join(TEXT_FORMATS)}, casadi)")
