"""The paper checked from first principles: its printed error equations against the derived error model.

``modelgen/data/paper_000_equations.yaml`` transcribes the core paper's
eqs. (1)-(6) term by term, as printed (OCR decisions recorded beside the
terms).  This module builds F, G, H (and Q from eq. (5)) from those terms and compares them entry
by entry with the error model that modelgen DERIVES from the navigation
equations under the paper's own assumptions (the twin model the file names,
``ned_doppler18_twin``: one spherical Earth radius, no vertical channel, the
paper's sensor models).  The table check (:mod:`modelgen.checks.paper_check`)
is a different, older comparison and is not changed by this one.

No difference is written in by hand: each is found by the comparison and
then classified by the rules below, applied in order to the computed
difference (the report names the rule that fired):

1. **convention** — the column belongs to a sensor error (a state whose own
   derived equation couples to no other state: a random constant or a
   first-order Markov process) and every entry of that column, in F and H,
   is the negated derived one: the paper defines that error with the
   opposite sign.  Covariances do not change.
2. **omitted term** — the paper lacks one or more terms of the derived entry
   entirely (no printed term has their form) and they are small at the
   scenario: their value is at most :data:`SMALL_FRACTION` of the derived
   entry's, or zero there (e.g. a V_d term in level flight).
3. **physics** (structure) — the paper's entry is the negated mirror entry
   (F(i,j) = -F(j,i)) of its own equations while the derived pair is not
   antisymmetric: the paper's derivation assumed a symmetry the
   linearization does not have (typically: it kept -(2 w_ie + w_en) x dv and
   left out the perturbation of the transport rate, d(w_en) x v).
4. **typo** — every differing term is printed, with the right form but a
   different numeric factor or sign: an isolated coefficient slip.
5. **physics** — anything else: a missing term that is not small, or a
   different functional form: the paper's equation describes different
   physics from the navigation equations it claims to linearize.

The scenario is the check scenario of the paper's model (the paper's level
flight at 30 N).  Public API (used by ``modelgen verify`` and ``modelgen run``)::

    result = paper_equations_check(twin_derived)            # twin: DerivedModel
    write_paper_equations_report(result, folder)            # paper_equations.md + .json
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import sympy as sp

from modelgen.checks.crosscheck import (
    layout,
    load_pairs,
    magnitude,
    scenario_values,
    hand_substitution,
)
from modelgen.checks.hints import constant_ratio, same
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.fileio.datafiles import data_path, read_yaml, read_yaml_with_lines
from modelgen.fileio.output import write_text_atomically
from modelgen.model.declaration import ErrorModel
from modelgen.model.expression import parse_expression
from modelgen.model.loading import load_model

#: The core paper's transcribed equations.
CORE_PAPER_EQUATIONS = "paper_000_equations.yaml"
CLASSIFICATIONS = ("typo", "convention", "omitted term", "physics")
#: A missing term counts as small (rule 2) up to this fraction of the derived entry at the scenario.
SMALL_FRACTION = 0.01
MATRICES = ("F", "G", "H", "Q")
#: Fields of every difference record in paper_equations.json.
#: Q is the driving noises' power spectral densities (eq. (5)), compared where the paper prints them.
RECORD_FIELDS = (
    "matrix", "row", "column", "row_quantity", "column_quantity", "equation", "printed", "paper", "derived",
    "difference", "magnitude", "classification", "rule",
)

_TOP_KEYS = {"source", "paper", "seed_file", "model", "twin", "assumptions", "combinations", "equations", "noise_densities", "measurements"}
_TERM_KEYS = {"of", "coefficient", "printed", "ocr"}


# -- the transcription ---------------------------------------------------------------
@dataclass(frozen=True)
class PrintedTerm:
    """One printed term: ``coefficient`` times the quantity ``of`` (a state, noise or combination symbol)."""

    of: str
    coefficient: sp.Expr
    printed: str
    ocr: str | None = None


@dataclass(frozen=True)
class PrintedEquation:
    """One printed equation: d(target)/dt (or a measurement ``target``) as a sum of terms."""

    equation: int
    target: str
    printed: str
    terms: tuple[PrintedTerm, ...]
    ocr: str | None = None


@dataclass(frozen=True)
class PaperEquations:
    """A paper's error equations as transcribed, with the model whose symbols they use and the twin to compare."""

    name: str
    source: str
    paper: str
    seed_file: str
    model: str
    twin: str
    assumptions: tuple[str, ...]
    combinations: Mapping[str, sp.Expr]
    dynamics: tuple[PrintedEquation, ...]
    measurements: tuple[PrintedEquation, ...]
    noise_densities: tuple[tuple[str, sp.Expr, int, str], ...] = ()  # (noise, psd, equation, printed)


def paper_equations_path(model_name: str) -> Path | None:
    """The transcribed-equations file written for ``model_name`` (its ``model:`` key), if any."""
    for path in sorted(data_path().glob("paper_*_equations.yaml")):
        if read_yaml(path, "paper-equations file").get("model") == model_name:
            return path
    return None


def _require(data: Any, key: str, where: str) -> Any:
    if not isinstance(data, dict):
        raise ModelError(f"{where}: expected a mapping")
    if key not in data:
        raise ModelError(f"{where}: missing key {key!r}")
    return data[key]


def _list(value: Any, where: str) -> list:
    if not isinstance(value, list):
        raise ModelError(f"{where}: expected a list")
    return value


def _terms(items: Any, namespace: Mapping[str, sp.Symbol], key: str, place: Callable[[str], str]) -> tuple[PrintedTerm, ...]:
    """The printed terms of one equation (``key`` is its path in the file, ``place`` gives file:line and path)."""
    out = []
    for k, item in enumerate(_list(items, place(f"{key}.terms"))):
        where = place(f"{key}.terms[{k}]")
        if not isinstance(item, dict) or set(item) - _TERM_KEYS:
            raise ModelError(f"{where}: expected a mapping with keys {sorted(_TERM_KEYS)}")
        of = str(_require(item, "of", where))
        if of not in namespace:
            raise ModelError(f"{where}: {of!r} is not a state, noise or combination of the paper's model")
        coefficient = parse_expression(str(_require(item, "coefficient", where)), namespace, f"{where}.coefficient")
        out.append(PrintedTerm(of, coefficient, str(_require(item, "printed", where)), item.get("ocr")))
    return tuple(out)


def load_paper_equations(path: str | Path, model: ErrorModel) -> PaperEquations:
    """Read and validate a transcribed-equations file against the model whose symbols it uses (errors name file:line)."""
    path = Path(path)
    data, lines = read_yaml_with_lines(path, "paper-equations file")

    def place(key: str) -> str:
        """``file:line: key`` of a key path such as ``equations[3].terms[1]``."""
        return f"{lines.get(key, path.name)}: {key}"

    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ModelError(f"{place(unknown[0])}: unknown key (expected one of {sorted(_TOP_KEYS)})")
    if _require(data, "model", path.name) != model.name:
        raise ModelError(f"{place('model')}: written for model {data['model']!r}, not {model.name!r}")
    namespace: dict[str, sp.Symbol] = {q.symbol: q.sym for q in (*model.parameters, *model.states, *model.noises)}
    combinations: dict[str, sp.Expr] = {}
    for k, item in enumerate(_list(data.get("combinations") or [], place("combinations"))):
        where = place(f"combinations[{k}]")
        symbol = str(_require(item, "symbol", where))
        if symbol in namespace:
            raise ModelError(f"{where}: {symbol!r} is already a symbol of model {model.name}")
        combinations[symbol] = parse_expression(str(_require(item, "expression", where)), namespace, f"{where}.expression")
    namespace.update({name: sp.Symbol(name, real=True) for name in combinations})

    def equations_of(section: str, target_key: str, targets: set[str], kind: str) -> list[PrintedEquation]:
        out = []
        for k, item in enumerate(_list(data.get(section) or [], place(section))):
            where = place(f"{section}[{k}]")
            target = str(_require(item, target_key, where))
            if target not in targets:
                raise ModelError(f"{where}: {target!r} is not a {kind} of model {model.name}")
            out.append(PrintedEquation(
                int(_require(item, "equation", where)), target, str(_require(item, "printed", where)),
                _terms(_require(item, "terms", where), namespace, f"{section}[{k}]", place), item.get("ocr"),
            ))
        return out

    _require(data, "equations", path.name)
    dynamics = equations_of("equations", "state", {s.symbol for s in model.states}, "state")
    written = [e.target for e in dynamics]
    missing = [s for s in (s.symbol for s in model.states) if s not in written]
    twice = sorted({t for t in written if written.count(t) > 1})
    if missing or twice:
        raise ModelError(f"{place('equations')}: every state needs exactly one equation (missing: {', '.join(missing) or '-'}; twice: {', '.join(twice) or '-'})")
    measurements = equations_of("measurements", "measurement", {m.symbol for m in model.measurements}, "measurement")
    noises = {w.symbol for w in model.noises}
    densities = []
    for k, item in enumerate(_list(data.get("noise_densities") or [], place("noise_densities"))):
        where = place(f"noise_densities[{k}]")
        noise = str(_require(item, "noise", where))
        if noise not in noises:
            raise ModelError(f"{where}: {noise!r} is not a noise of model {model.name}")
        psd = parse_expression(str(_require(item, "psd", where)), namespace, f"{where}.psd")
        densities.append((noise, psd, int(_require(item, "equation", where)), str(_require(item, "printed", where))))
    return PaperEquations(
        name=path.name, source=str(data.get("source", "")), paper=str(data.get("paper", "")),
        seed_file=str(data.get("seed_file", "")), model=model.name, twin=str(_require(data, "twin", path.name)),
        assumptions=tuple(str(a) for a in data.get("assumptions") or []), combinations=combinations,
        dynamics=tuple(dynamics), measurements=tuple(measurements), noise_densities=tuple(densities),
    )


def paper_matrices(equations: PaperEquations, model: ErrorModel) -> dict[str, sp.Matrix]:
    """F, G, H built from the printed terms (combinations expanded), in the model's state order, and Q from the
    printed noise densities (zero where the paper prints none)."""
    combos = {sp.Symbol(k, real=True): v for k, v in equations.combinations.items()}
    symbol = {q.symbol: q.sym for q in (*model.states, *model.noises)}

    def right_hand_side(e: PrintedEquation) -> sp.Expr:
        return sp.Add(*(t.coefficient * symbol.get(t.of, sp.Symbol(t.of, real=True)) for t in e.terms)).xreplace(combos)

    by_state = {e.target: right_hand_side(e) for e in equations.dynamics}
    f = sp.Matrix([by_state[s.symbol] for s in model.states])
    x = sp.Matrix(model.state_symbols)
    w = sp.Matrix(model.noise_symbols) if model.noises else sp.zeros(0, 1)
    by_measurement = {e.target: right_hand_side(e) for e in equations.measurements}
    h = sp.Matrix([by_measurement.get(m.symbol, sp.S.Zero) for m in model.measurements])
    psd = {noise: value for noise, value, _, _ in equations.noise_densities}
    return {
        "F": f.jacobian(x),
        "G": f.jacobian(w) if model.noises else sp.zeros(len(x), 0),
        "H": h.jacobian(x) if model.measurements else sp.zeros(0, len(x)),
        "Q": sp.diag(*[psd.get(n.symbol, sp.S.Zero) for n in model.noises]) if model.noises else sp.zeros(0, 0),
    }


def printed_terms(equations: PaperEquations, noises: set[str]) -> dict[tuple[str, str, str], tuple[int, str]]:
    """(matrix, row symbol, column symbol) -> (equation number, the printed text of the term(s) there)."""
    out: dict[tuple[str, str, str], tuple[int, list[str]]] = {}
    for matrix, group in (("F", equations.dynamics), ("H", equations.measurements)):
        for e in group:
            for t in e.terms:
                columns = [str(s) for s in equations.combinations[t.of].free_symbols] if t.of in equations.combinations else [t.of]
                for column in columns:
                    kind = "G" if matrix == "F" and column in noises else matrix
                    out.setdefault((kind, e.target, column), (e.equation, []))[1].append(t.printed)
    for noise, _, equation, printed in equations.noise_densities:
        out[("Q", noise, noise)] = (equation, [printed])
    return {k: (n, " ".join(texts)) for k, (n, texts) in out.items()}


# -- the classification rules ------------------------------------------------------------
def additive_terms(expr: sp.Expr) -> tuple[sp.Expr, ...]:
    """The terms of a sum after distributing products (the unit in which a paper prints an entry)."""
    return sp.Add.make_args(sp.expand_mul(expr)) if expr != 0 else ()


@dataclass(frozen=True)
class TermComparison:
    """How two entries' terms line up: terms only the derived has, only the paper has, and term pairs with another factor."""

    missing: tuple[sp.Expr, ...]
    extra: tuple[sp.Expr, ...]
    refactored: tuple[tuple[sp.Expr, sp.Expr], ...]  # (paper term, derived term), same form, another number


def compare_terms(paper: sp.Expr, derived: sp.Expr) -> TermComparison:
    """Match each derived term with an equal paper term, else with one of the same form times a number."""
    left = list(additive_terms(paper))
    missing, refactored = [], []
    for term in additive_terms(derived):
        equal = next((p for p in left if same(p, term)), None)
        if equal is not None:
            left.remove(equal)
            continue
        scaled = next((p for p in left if constant_ratio(p, term) is not None), None)
        if scaled is not None:
            left.remove(scaled)
            refactored.append((scaled, term))
        else:
            missing.append(term)
    return TermComparison(tuple(missing), tuple(left), tuple(refactored))


def sensor_error_states(F: sp.Matrix) -> set[int]:
    """States whose derived equation couples to no other state (random constants, first-order Markov processes)."""
    return {i for i in range(F.shape[0]) if all(F[i, j] == 0 for j in range(F.shape[1]) if j != i)}


def column_sign_flipped(j: int, paper: Mapping[str, sp.Matrix], derived: Mapping[str, sp.Matrix]) -> bool:
    """Every nonzero entry of state column ``j`` (in F and H) is the negated derived one, and there is at least one."""
    found = False
    for m in ("F", "H"):
        P, D = paper[m], derived[m]
        for i in range(P.shape[0]):
            if m == "F" and i == j:
                continue  # the diagonal is invariant under a sign change of the state
            if P[i, j] == 0 and D[i, j] == 0:
                continue
            if not same(P[i, j], -D[i, j]) or D[i, j] == 0:
                return False
            found = True
    return found


def classify(
    matrix: str, i: int, j: int, paper: Mapping[str, sp.Matrix], derived: Mapping[str, sp.Matrix],
    values: Mapping[sp.Symbol, float], sensor_errors: set[int],
) -> tuple[str, str]:
    """The classification of a differing entry and the rule that gave it (module doc, rules 1-5)."""
    P, D = paper[matrix][i, j], derived[matrix][i, j]
    if matrix in ("F", "H") and (matrix, i) != ("F", j) and j in sensor_errors and column_sign_flipped(j, paper, derived):
        return "convention", "rule 1: the whole column of a sensor error is negated (sign of its definition)"
    terms = compare_terms(P, D)
    if terms.missing and not terms.extra and not terms.refactored:
        lost = sp.Add(*terms.missing)
        size, whole = magnitude(lost, values), magnitude(D, values)
        if size is not None and whole is not None and (size == 0 or size <= SMALL_FRACTION * whole):
            return "omitted term", (
                f"rule 2: the paper prints no term {sp.sstr(lost)}, {size:.3g} at the scenario "
                f"({'zero there' if size == 0 else f'at most {SMALL_FRACTION:g} of the entry'})"
            )
    if matrix == "F" and i != j:
        mirror_paper, mirror_derived = paper["F"][j, i], derived["F"][j, i]
        if P != 0 and same(P, -mirror_paper) and not same(D, -mirror_derived):
            return "physics", (
                f"rule 3: the paper's entry is minus its mirror F({j + 1},{i + 1}) (antisymmetric), the "
                "linearization's pair is not: the paper's derivation assumed a symmetry the navigation equations lack"
            )
    if terms.refactored and not terms.missing and not terms.extra:
        slips = ", ".join(f"{sp.sstr(p)} printed for {sp.sstr(d)}" for p, d in terms.refactored)
        return "typo", f"rule 4: every term has the derived form but another factor ({slips})"
    parts = []
    if terms.missing:
        parts.append(f"missing {sp.sstr(sp.Add(*terms.missing))}")
    if terms.extra:
        parts.append(f"extra {sp.sstr(sp.Add(*terms.extra))}")
    if terms.refactored:
        parts.append("other factors on " + ", ".join(sp.sstr(d) for _, d in terms.refactored))
    return "physics", "rule 5: " + "; ".join(parts or ["a different functional form"])


# -- the comparison ---------------------------------------------------------------------
@dataclass(frozen=True)
class EquationDifference:
    """One entry where the printed equations and the derived model differ (1-based indices)."""

    matrix: str
    row: int
    column: int
    row_quantity: str
    column_quantity: str
    equation: int | None
    printed: str | None
    paper: str
    derived: str
    difference: str
    magnitude: float | None
    classification: str
    rule: str

    @property
    def label(self) -> str:
        return f"{self.matrix}({self.row},{self.column})"

    def record(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in RECORD_FIELDS}


@dataclass(frozen=True)
class PaperEquationsResult:
    """The first-principles check: how many entries were compared, and each difference classified."""

    paper: str
    source: str
    equations_file: str
    model: str
    twin: str
    assumptions: tuple[str, ...]
    scenario: str
    compared: int
    differences: tuple[EquationDifference, ...]

    def classification_counts(self) -> dict[str, int]:
        return {c: sum(d.classification == c for d in self.differences) for c in CLASSIFICATIONS}

    def summary(self) -> dict[str, Any]:
        return {
            "paper": self.paper, "source": self.source, "equations_file": self.equations_file, "model": self.model,
            "twin": self.twin, "scenario": self.scenario, "compared": self.compared,
            "differences": len(self.differences), "classifications": self.classification_counts(),
        }

    def to_json(self) -> str:
        data = {
            "summary": self.summary(), "assumptions": list(self.assumptions), "record_fields": list(RECORD_FIELDS),
            "rules": RULES, "differences": [d.record() for d in self.differences],
        }
        return json.dumps(data, indent=2, sort_keys=True, ensure_ascii=False) + "\n"

    def to_markdown(self) -> str:
        return _markdown(self)


#: The rules as the reports print them (module doc, in order).
RULES = [
    "convention: the whole column of a sensor error (a random constant or Markov state) is negated",
    f"omitted term: the paper lacks the derived term(s) entirely and they are at most {SMALL_FRACTION:g} of the entry (or zero) at the scenario",
    "physics: the paper's entry is minus its mirror entry while the linearization's pair is not antisymmetric",
    "typo: every term is printed in the derived form with another numeric factor or sign",
    "physics: any other difference (a missing term that is not small, a different form)",
]


def compare_equations(
    equations: PaperEquations, model: ErrorModel, derived: Mapping[str, sp.Matrix], scenario: tuple[dict, str] | None = None,
    rename: Mapping[sp.Symbol, sp.Symbol] | None = None,
) -> PaperEquationsResult:
    """Compare the printed equations' F, G, H with ``derived`` (``model``'s state order).

    ``rename`` takes the paper's (``model``'s) parameter symbols to those of
    ``derived`` (a twin's), ``scenario`` gives values and a label for the
    magnitudes (default: ``model``'s check scenario).
    """
    paper = {m: value.xreplace(rename or {}) for m, value in paper_matrices(equations, model).items()}
    values, label = scenario or scenario_values(model)
    sensor_errors = sensor_error_states(derived["F"])
    where = printed_terms(equations, {w.symbol for w in model.noises})
    names = {
        "F": ([s.symbol for s in model.states],) * 2,
        "G": ([s.symbol for s in model.states], [w.symbol for w in model.noises]),
        "H": ([m.symbol for m in model.measurements], [s.symbol for s in model.states]),
        "Q": ([w.symbol for w in model.noises],) * 2,
    }
    compared, differences = 0, []
    for m in MATRICES:
        P, D = paper[m], derived[m]
        if P.shape != D.shape:
            raise ModelError(f"{equations.name}: the printed {m} is {P.shape}, the derived one {D.shape}")
        for i in range(P.shape[0]):
            for j in range(P.shape[1]):
                if P[i, j] == 0 and D[i, j] == 0:
                    continue
                compared += 1
                if same(P[i, j], D[i, j]):
                    continue
                classification, rule = classify(m, i, j, paper, derived, values, sensor_errors)
                row, column = names[m][0][i], names[m][1][j]
                equation, printed = where.get((m, row, column), (None, None))
                difference = sp.simplify(D[i, j] - P[i, j])
                differences.append(EquationDifference(
                    matrix=m, row=i + 1, column=j + 1, row_quantity=row, column_quantity=column, equation=equation,
                    printed=printed, paper=sp.sstr(P[i, j]), derived=sp.sstr(D[i, j]), difference=sp.sstr(difference),
                    magnitude=magnitude(difference, values), classification=classification, rule=rule,
                ))
    return PaperEquationsResult(
        paper=equations.paper, source=equations.source, equations_file=equations.name, model=model.name,
        twin=equations.twin, assumptions=equations.assumptions, scenario=label, compared=compared,
        differences=tuple(differences),
    )


def twin_in_model_order(twin: DerivedModel, model: ErrorModel) -> tuple[dict[str, sp.Matrix], dict[sp.Symbol, sp.Symbol]]:
    """The twin's F, G, H (and Q) in ``model``'s order, and the renaming of ``model``'s parameters to the twin's.

    The comparison is made in the twin's symbols (several per-axis parameters
    of the paper may be one of the twin's).  States the paper does not model
    (the pair's ``unmodelled``, e.g. the vertical channel) are left out, as the
    paper's assumptions say.
    """
    pair = next((p for p in load_pairs() if p.twin == twin.model.name), None)
    if pair is None:
        raise ModelError(f"twin {twin.model.name!r} has no pair in modelgen/data/crosscheck.yaml (its parameter mapping)")
    where = layout(pair, model, twin.model)
    out = {}
    for m in MATRICES:
        rows, columns = where.index(m)
        T = getattr(twin, m)
        out[m] = sp.Matrix(len(rows), len(columns), lambda i, j: T[rows[i], columns[j]])
    return out, hand_substitution(pair, model, twin.model)


def paper_equations_check(twin: DerivedModel, path: str | Path | None = None) -> PaperEquationsResult:
    """The first-principles check of the paper whose transcribed equations name ``twin`` (module doc)."""
    if path is None:
        path = next((p for p in sorted(data_path().glob("paper_*_equations.yaml"))
                     if read_yaml(p, "paper-equations file").get("twin") == twin.model.name), None)
        if path is None:
            raise ModelError(f"no transcribed paper equations in modelgen/data/ name the twin {twin.model.name!r}")
    header = read_yaml(path, "paper-equations file")
    model = load_model(str(_require(header, "model", Path(path).name)))
    equations = load_paper_equations(path, model)
    derived, rename = twin_in_model_order(twin, model)
    return compare_equations(equations, model, derived, scenario_values(twin.model), rename)


# -- the report ----------------------------------------------------------------------------
def _cell(text: Any) -> str:
    if text is None or text == "":
        return "—"
    return " ".join(str(text).split()).replace("|", "\\|")


def _markdown(r: PaperEquationsResult) -> str:
    counts = r.classification_counts()
    lines = [
        f"# The paper from first principles: eqs. (1)-(6) against `{r.twin}`",
        "",
        f"{r.paper}, {r.source}, transcribed term by term in `{r.equations_file}`, compared entry by entry with "
        f"the error model derived from the navigation equations under the paper's own assumptions (`{r.twin}`).",
        "",
        "The paper's assumptions:",
        "",
        *[f"- {a}" for a in r.assumptions],
        "",
        f"{r.compared} entries compared (nonzero on either side); **{len(r.differences)} differ**: "
        + ", ".join(f"{counts[c]} {c}" for c in CLASSIFICATIONS) + f". Magnitudes at {r.scenario}.",
        "",
        "Every difference is found by the comparison and classified by the first rule that applies:",
        "",
        *[f"{k}. {rule}" for k, rule in enumerate(RULES, 1)],
        "",
    ]
    if r.differences:
        lines += [
            "| entry | row | column | eq. | printed | paper | derived | derived - paper | magnitude | classification | rule |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for d in r.differences:
            size = "—" if d.magnitude is None else f"{d.magnitude:.3g}"
            lines.append(
                f"| {d.label} | {d.row_quantity} | {d.column_quantity} | {d.equation or '—'} | `{_cell(d.printed)}` "
                f"| `{_cell(d.paper)}` | `{_cell(d.derived)}` | `{_cell(d.difference)}` | {size} | {d.classification} | {_cell(d.rule)} |"
            )
    else:
        lines.append("No difference.")
    lines += ["", "`paper_equations.json` holds the summary, the rules and one record per difference with fields "
              + ", ".join(f"`{f}`" for f in RECORD_FIELDS) + ".", ""]
    return "\n".join(lines)


def write_paper_equations_report(result: PaperEquationsResult, folder: str | Path) -> tuple[Path, Path]:
    """Write ``paper_equations.md`` and ``paper_equations.json`` into ``folder`` atomically; returns both paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    markdown, data = folder / "paper_equations.md", folder / "paper_equations.json"
    write_text_atomically(markdown, result.to_markdown())
    write_text_atomically(data, result.to_json())
    return markdown, data


def differences_summary(result: PaperEquationsResult) -> Sequence[str]:
    """The differences for the command line and the run's report: one line per difference, or per group of
    differences with the same classification and rule (a negated column is one finding, not eighteen)."""
    groups: dict[tuple[str, str], list[EquationDifference]] = {}
    for d in result.differences:
        groups.setdefault((d.classification, d.rule), []).append(d)
    lines = []
    for (classification, rule), members in groups.items():
        if len(members) == 1:
            d = members[0]
            lines.append(
                f"{d.label} ({d.row_quantity}, {d.column_quantity}), eq. ({d.equation or '?'}): {classification} - "
                f"paper {d.paper}, derived {d.derived}; {rule}"
            )
        else:
            columns = sorted({d.column_quantity for d in members}, key=lambda c: min(d.column for d in members if d.column_quantity == c))
            lines.append(
                f"{len(members)} entries ({', '.join(d.label for d in members)}; columns {', '.join(columns)}): "
                f"{classification} - {rule}"
            )
    return lines
