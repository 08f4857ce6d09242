"""Reading a paper's printed table of F, G, H entries (a YAML data file).

The table is data, not code: ``modelgen/data/paper_000_table.yaml`` holds the
core paper's entries exactly as printed, the reading used where the OCR is
garbled, the paper's units with their conversion factors, the human
annotations of known differences and the paper's own inconsistencies.  This
module validates that file, parses every expression in the paper's symbols
and resolves the printed cross-references ("F(2,1) = -F(1,2)").  It knows
nothing about any derived model; :mod:`modelgen.checks.paper_check` does the
comparison.

A user's own table (``modelgen verify MODEL --table FILE``) is read with the
model it describes (``load_paper_table(path, model)``): then only ``entries``
is required; ``shape`` and ``symbols`` default to the model's, the unit factor
to ``M = 180*3600/pi``, and every state, noise and measurement a table does
not list in ``state_units``/``noise_units``/``measurement_units`` keeps the
model's SI unit (factor 1).  The format is documented in README "Verifying
your own paper" and ``modelgen/data/verify_table.schema.json``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml, read_yaml_with_lines
from modelgen.model.declaration import ErrorModel
from modelgen.model.expression import check_defined, parse_expression
from modelgen.model.vectors import MAX_TREE_NODES, tree_size

MATRICES = ("F", "G", "H")
STATUSES = ("match", "differ", "paper_only", "derived_only")
CLASSIFICATIONS = (
    "ocr_damage",
    "paper_typo",
    "unit_inconsistency",
    "sign_convention",
    "omitted_in_paper",
    "model_difference",
)
#: What an annotation explains: the table comparison, or the cross-check of
#: table-omitted entries against the paper's eq. (1).
ANNOTATION_TARGETS = ("table", "equation_1")

_REFERENCE = re.compile(r"\b([FGH])\(\s*(\d+)\s*,\s*(\d+)\s*\)")
_TOP_KEYS = {
    "source",
    "model",
    "shape",
    "unit_factor",
    "symbols",
    "state_units",
    "noise_units",
    "measurement_units",
    "entries",
    "equation_1_entries",
    "annotations",
    "paper_inconsistencies",
}
#: The unit factor a user table gets when it declares none: arc-seconds per radian.
DEFAULT_UNIT_FACTOR = {"symbol": "M", "value": "180*3600/pi"}
_UNIT_KINDS = (("state_units", "state", "states"), ("noise_units", "noise", "noises"), ("measurement_units", "measurement", "measurements"))

Key = tuple[str, int, int]  # (matrix, row, col), 1-based as printed


@dataclass(frozen=True)
class PaperEntry:
    """One printed entry: where, what was printed, what the comparison uses.

    ``value`` is the resolved expression (references replaced, reading
    applied) in the paper's units, with the unit factor ``M`` still symbolic
    and the paper's symbols mapped to the model's parameter symbols.
    """

    matrix: str
    row: int
    col: int
    printed: str
    expression: str
    reading: str | None
    why: str | None
    value: sp.Expr

    @property
    def key(self) -> Key:
        return (self.matrix, self.row, self.col)

    @property
    def label(self) -> str:
        return f"{self.matrix}({self.row},{self.col})"


@dataclass(frozen=True)
class UnitFactor:
    """A quantity's unit in the paper and the factor s with x_paper = s * x_SI."""

    quantity: str  # symbol of the state, noise or measurement in the model
    paper_unit: str
    factor: sp.Expr  # in the unit symbol M
    reasoning: str


@dataclass(frozen=True)
class Annotation:
    """Human judgement of one known difference (lives in the data file)."""

    matrix: str
    row: int
    col: int
    status: str
    classification: str
    reason: str
    against: str = "table"

    @property
    def key(self) -> Key:
        return (self.matrix, self.row, self.col)

    @property
    def label(self) -> str:
        return f"{self.matrix}({self.row},{self.col})"


@dataclass(frozen=True)
class PaperTable:
    """The validated contents of a paper-table data file."""

    name: str  # file name, for reports (no absolute path: reports stay byte-identical)
    source: str
    model: str
    shape: Mapping[str, tuple[int, int]]
    unit_symbol: sp.Symbol
    unit_value: sp.Expr
    symbols: Mapping[str, str]  # paper symbol -> model parameter symbol
    state_units: tuple[UnitFactor, ...]
    noise_units: tuple[UnitFactor, ...]
    measurement_units: tuple[UnitFactor, ...]
    entries: tuple[PaperEntry, ...]
    equation_1_entries: tuple[PaperEntry, ...]
    annotations: tuple[Annotation, ...]
    inconsistencies: tuple[str, ...]


#: The core paper's table of F, G, H entries; its ``model:`` key names the paper's model.
CORE_PAPER_TABLE = "paper_000_table.yaml"


def _table_header(path: Path) -> dict[str, Any]:
    """The top-level mapping of a paper table file (empty if it is not YAML or not a mapping)."""
    try:
        return read_yaml(path, "paper-table file")
    except ModelError:
        return {}


def paper_table_model(path: str | Path) -> str:
    """The model a paper table was written for (its ``model:`` key): which model is the paper's is data."""
    model = _table_header(Path(path)).get("model")
    if not isinstance(model, str) or not model:
        raise ModelError(f"{Path(path).name}: a paper table needs 'model: <model name>'")
    return model


def paper_table_path(model_name: str) -> Path | None:
    """The paper table written for the model ``model_name``, if there is one."""
    for path in sorted(data_path().glob("paper_*_table.yaml")):
        if _table_header(path).get("model") == model_name:
            return path
    return None


def load_paper_table(path: str | Path, model: ErrorModel | None = None) -> PaperTable:
    """Read, validate and parse a paper-table data file (see module doc).

    Without ``model`` every key of the full format is required (the shipped
    paper tables); with it, a partial user table is completed from the model.
    """
    path = Path(path)
    where = path.name
    data, lines = read_yaml_with_lines(path, "paper-table file")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ModelError(f"{where}: unknown key {unknown[0]!r} (expected one of {sorted(_TOP_KEYS)})")
    if model is not None:
        data = _completed_from_model(data, model, where)
    for key in ("model", "shape", "unit_factor", "symbols", "state_units", "entries"):
        if key not in data:
            raise ModelError(f"{where}: missing required key {key!r}")

    shape = _shape(data["shape"], where)
    unit = _mapping(data["unit_factor"], f"{where}: unit_factor", {"symbol", "value"})
    unit_name = str(unit["symbol"])
    unit_symbol = sp.Symbol(unit_name, positive=True)
    symbols = _mapping(data["symbols"], f"{where}: symbols")
    namespace: dict[str, sp.Symbol] = {str(k): sp.Symbol(str(v), real=True) for k, v in symbols.items()}
    if unit_name in namespace:
        raise ModelError(f"{where}: unit factor symbol {unit_name!r} is also a paper symbol")
    namespace[unit_name] = unit_symbol
    unit_value = parse_expression(str(unit["value"]), {}, f"{where}: unit_factor.value")

    units = {
        kind: tuple(
            _unit_factor(item, f"{where}: {kind}[{i}]", field, {unit_name: unit_symbol})
            for i, item in enumerate(_list(data.get(kind) or [], f"{where}: {kind}"))
        )
        for kind, field in (("state_units", "state"), ("noise_units", "noise"), ("measurement_units", "measurement"))
    }
    _check_unit_counts(units, shape, where)

    entries = _entries(data["entries"], "entries", shape, namespace, where, lines)
    equation_1 = _entries(data.get("equation_1_entries") or [], "equation_1_entries", shape, namespace, where, lines)
    annotations = tuple(
        _annotation(item, f"{lines.get(f'annotations[{i}]', where)}: annotations[{i}]", shape)
        for i, item in enumerate(_list(data.get("annotations") or [], f"{where}: annotations"))
    )
    seen: set[tuple[str, Key, str]] = set()
    for a in annotations:
        ident = (a.against, a.key, a.status)
        if ident in seen:
            raise ModelError(f"{where}: annotation for {a.label} ({a.against}, {a.status}) appears twice")
        seen.add(ident)
    inconsistencies = tuple(str(s) for s in _list(data.get("paper_inconsistencies") or [], f"{where}: paper_inconsistencies"))
    return PaperTable(
        name=path.name,
        source=str(data.get("source", "")),
        model=str(data["model"]),
        shape=shape,
        unit_symbol=unit_symbol,
        unit_value=unit_value,
        symbols={str(k): str(v) for k, v in symbols.items()},
        state_units=units["state_units"],
        noise_units=units["noise_units"],
        measurement_units=units["measurement_units"],
        entries=entries,
        equation_1_entries=equation_1,
        annotations=annotations,
        inconsistencies=inconsistencies,
    )


def _completed_from_model(data: dict[str, Any], model: ErrorModel, where: str) -> dict[str, Any]:
    """A user table with every key the model can supply filled in (the file's own values win).

    ``model`` must match the model the table names; ``symbols`` maps each of the
    model's parameter symbols to itself, plus the table's own spellings; a
    quantity missing from a ``*_units`` list keeps its SI unit (factor 1);
    entries without ``printed`` show their expression.
    """
    named = data.get("model")
    if named is not None and named != model.name:
        raise ModelError(f"{where}: the table is written for model {named!r}, not {model.name!r}")
    n, k, m = len(model.states), len(model.noises), len(model.measurements)
    out = dict(data)
    out["model"] = model.name
    out.setdefault("shape", {"F": [n, n], "G": [n, k], "H": [m, n]})
    out.setdefault("unit_factor", dict(DEFAULT_UNIT_FACTOR))
    out.setdefault("source", f"the table {where}")
    own = _mapping(data.get("symbols") or {}, f"{where}: symbols")
    out["symbols"] = {**{p.symbol: p.symbol for p in model.parameters}, **own}
    for kind, field, plural in _UNIT_KINDS:
        listed: dict[str, dict] = {}
        for i, item in enumerate(_list(data.get(kind) or [], f"{where}: {kind}")):
            item = _mapping(item, f"{where}: {kind}[{i}]", {field, "factor"}, {"paper_unit", "reasoning"})
            listed[str(item[field])] = item
        quantities = getattr(model, plural)
        unknown = sorted(set(listed) - {q.symbol for q in quantities})
        if unknown:
            raise ModelError(f"{where}: {kind} names {unknown[0]!r}, which is not one of the {plural} of model {model.name!r}")
        out[kind] = [
            {
                field: q.symbol,
                "factor": listed[q.symbol]["factor"] if q.symbol in listed else 1,
                "paper_unit": listed.get(q.symbol, {}).get("paper_unit", q.unit),
                "reasoning": listed.get(q.symbol, {}).get("reasoning", "declared by the table" if q.symbol in listed else "the model's SI unit (default)"),
            }
            for q in quantities
        ]
    if "entries" in data:
        out["entries"] = [
            {**item, "printed": item.get("expression", "")} if isinstance(item, dict) and "printed" not in item else item
            for item in _list(data["entries"], f"{where}: entries")
        ]
    return out


# -- validation helpers -------------------------------------------------------
def _list(value: Any, where: str) -> list:
    if not isinstance(value, list):
        raise ModelError(f"{where}: must be a list")
    return value


def _mapping(value: Any, where: str, required: set[str] | None = None, optional: set[str] | None = None) -> dict:
    if not isinstance(value, dict):
        raise ModelError(f"{where}: must be a mapping")
    if required is not None:
        missing = sorted(required - set(value))
        if missing:
            raise ModelError(f"{where}: missing field {missing[0]!r}")
        extra = sorted(set(value) - required - (optional or set()))
        if extra:
            raise ModelError(f"{where}: unknown field {extra[0]!r}")
    return value


def _shape(value: Any, where: str) -> dict[str, tuple[int, int]]:
    shape = _mapping(value, f"{where}: shape", set(MATRICES))
    out = {}
    for m in MATRICES:
        dims = shape[m]
        if not (isinstance(dims, list) and len(dims) == 2 and all(isinstance(d, int) and d >= 0 for d in dims)):
            raise ModelError(f"{where}: shape.{m} must be [rows, columns], got {dims!r}")
        out[m] = (dims[0], dims[1])
    if out["F"][0] != out["F"][1] or out["G"][0] != out["F"][0] or out["H"][1] != out["F"][0]:
        raise ModelError(f"{where}: shapes F {out['F']}, G {out['G']}, H {out['H']} are not consistent")
    return out


def _unit_factor(item: Any, where: str, field: str, namespace: dict[str, sp.Symbol]) -> UnitFactor:
    item = _mapping(item, where, {field, "paper_unit", "factor", "reasoning"})
    factor = parse_expression(str(item["factor"]), namespace, f"{where} factor")
    if factor == 0:
        raise ModelError(f"{where}: factor must not be zero")
    return UnitFactor(str(item[field]), str(item["paper_unit"]), factor, str(item["reasoning"]))


def _check_unit_counts(units: dict[str, tuple[UnitFactor, ...]], shape: Mapping[str, tuple[int, int]], where: str) -> None:
    expected = {"state_units": shape["F"][0], "noise_units": shape["G"][1], "measurement_units": shape["H"][0]}
    for kind, n in expected.items():
        if len(units[kind]) != n:
            raise ModelError(f"{where}: {kind} lists {len(units[kind])} quantities, the table's shape needs {n}")
        names = [u.quantity for u in units[kind]]
        if len(set(names)) != len(names):
            raise ModelError(f"{where}: {kind} names a quantity twice")


def _check_index(matrix: Any, row: Any, col: Any, shape: Mapping[str, tuple[int, int]], where: str) -> Key:
    if matrix not in MATRICES:
        raise ModelError(f"{where}: matrix must be one of {', '.join(MATRICES)}, got {matrix!r}")
    rows, cols = shape[matrix]
    for label, value, limit in (("row", row, rows), ("col", col, cols)):
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= limit:
            raise ModelError(f"{where}: {label} {value!r} is outside 1..{limit} of the {rows}x{cols} {matrix}")
    return (matrix, row, col)


def _entries(
    raw: Any,
    kind: str,
    shape: Mapping[str, tuple[int, int]],
    namespace: Mapping[str, sp.Symbol],
    where: str,
    lines: Mapping[str, str] | None = None,
) -> tuple[PaperEntry, ...]:
    """Parse entries, then resolve the references between them; ``lines``: ``file:line`` by key path."""
    parsed: dict[Key, tuple[dict, sp.Expr, str]] = {}
    for i, item in enumerate(_list(raw, f"{where}: {kind}")):
        place = f"{(lines or {}).get(f'{kind}[{i}]', where)}: {kind}[{i}]"
        item = _mapping(item, place, {"matrix", "row", "col", "printed", "expression"}, {"reading", "why"})
        key = _check_index(item["matrix"], item["row"], item["col"], shape, place)
        label = f"{key[0]}({key[1]},{key[2]})"
        place = f"{place} ({label})"
        if key in parsed:
            raise ModelError(f"{place}: entry {label} appears twice")
        if ("reading" in item) != ("why" in item):
            raise ModelError(f"{place}: a 'reading' needs a 'why' and a 'why' needs a 'reading'")
        used = str(item["reading"] if "reading" in item else item["expression"])
        text, refs = _placeholders(used)
        try:
            expr = parse_expression(text, {**namespace, **refs}, f"{place} {'reading' if 'reading' in item else 'expression'}")
        except ModelError as exc:
            hint = "" if "reading" in item else " (if the print is garbled, add a 'reading' and say 'why')"
            raise ModelError(f"{exc}{hint}") from None
        parsed[key] = (item, expr, place)

    resolved: dict[Key, sp.Expr] = {}

    def resolve(key: Key, chain: tuple[Key, ...]) -> sp.Expr:
        if key in resolved:
            return resolved[key]
        item, expr, place = parsed[key]
        if key in chain:
            raise ModelError(f"{place}: circular reference {' -> '.join(f'{k[0]}({k[1]},{k[2]})' for k in (*chain, key))}")
        subs = {}
        for symbol in expr.free_symbols:
            ref = _reference_key(symbol.name)
            if ref is None:
                continue
            if ref not in parsed:
                raise ModelError(f"{place}: refers to {ref[0]}({ref[1]},{ref[2]}), which is not in {kind}")
            subs[symbol] = resolve(ref, (*chain, key))
        value = expr.xreplace(subs) if subs else expr
        # References share subexpressions: F(1,k) = F(1,k-1)*F(1,k-1) doubles the
        # tree with each entry, and the comparison walks the tree (hours at 18).
        if tree_size(value, MAX_TREE_NODES) > MAX_TREE_NODES:
            raise ModelError(
                f"{place}: grows to more than {MAX_TREE_NODES} operations once the entries it refers to are "
                "written out; write it in a smaller form"
            )
        if subs:  # the comparison expands it: bounded, defined and finite as a model's expressions are
            check_defined(value, f"{key[0]}({key[1]},{key[2]}) with the entries it refers to written out", place)
        resolved[key] = value
        return value

    out = []
    for key, (item, _, _) in parsed.items():
        out.append(
            PaperEntry(
                matrix=key[0],
                row=key[1],
                col=key[2],
                printed=str(item["printed"]),
                expression=str(item["expression"]),
                reading=str(item["reading"]) if "reading" in item else None,
                why=" ".join(str(item["why"]).split()) if "why" in item else None,
                value=resolve(key, ()),
            )
        )
    return tuple(out)


def _placeholders(text: str) -> tuple[str, dict[str, sp.Symbol]]:
    """Replace references such as F(1,2) by placeholder symbols."""
    refs: dict[str, sp.Symbol] = {}

    def swap(match: re.Match) -> str:
        name = f"ref_{match[1]}_{int(match[2])}_{int(match[3])}"
        refs[name] = sp.Symbol(name)
        return name

    return _REFERENCE.sub(swap, text), refs


def _reference_key(name: str) -> Key | None:
    parts = name.split("_")
    if len(parts) == 4 and parts[0] == "ref" and parts[1] in MATRICES:
        return (parts[1], int(parts[2]), int(parts[3]))
    return None


def _annotation(item: Any, where: str, shape: Mapping[str, tuple[int, int]]) -> Annotation:
    item = _mapping(item, where, {"matrix", "row", "col", "status", "classification", "reason"}, {"against"})
    key = _check_index(item["matrix"], item["row"], item["col"], shape, where)
    against = str(item.get("against", "table"))
    if against not in ANNOTATION_TARGETS:
        raise ModelError(f"{where}: against must be one of {', '.join(ANNOTATION_TARGETS)}, got {against!r}")
    status = str(item["status"])
    if status not in STATUSES or status == "match":
        raise ModelError(f"{where}: status must be one of differ, paper_only, derived_only, got {status!r}")
    classification = str(item["classification"])
    if classification not in CLASSIFICATIONS:
        raise ModelError(f"{where}: classification must be one of {', '.join(CLASSIFICATIONS)}, got {classification!r}")
    reason = " ".join(str(item["reason"]).split())
    if not reason:
        raise ModelError(f"{where}: reason is empty")
    return Annotation(*key, status=status, classification=classification, reason=reason, against=against)
