"""The C printer: sympy expressions and the language-neutral kernels as C99 text.

Parameters are struct members (``params->latitude``); a kernel ``Ref`` is a
member of the filter (``f``), the transition (``t``) or the scratch (``w``)
reached through the pointer the generated function takes.
"""

from __future__ import annotations

from typing import Callable, Mapping

import sympy as sp
from sympy.codegen.ast import float32, float64, real
from sympy.printing.c import C99CodePrinter

from modelgen.codegen.backends.printing import RenamedSymbols, scalar_value, small_power
from modelgen.codegen.kernels import Assign, CheckedAssign, Ref, Statement, Term, lane_split

SCALAR_TYPES = {"double": float64, "float": float32}

#: The pointer through which a generated C function reaches each kernel owner.
POINTERS = {"filter": "f", "transition": "t", "scratch": "w", "matrices": "m"}


class CPrinter(RenamedSymbols, C99CodePrinter):
    """C99 printer with parameters renamed to struct members."""

    def __init__(self, scalar: str = "double", renames: Mapping[sp.Symbol, str] | None = None):
        super().__init__({"type_aliases": {real: SCALAR_TYPES[scalar]}})
        self.scalar = scalar
        self._init_renames(renames)

    def _print_Float(self, expr: sp.Float) -> str:
        """The literal in the scalar type: 0 for a value that underflows it (``scalar_value``), ModelError beyond its range."""
        if scalar_value(expr, self.scalar) == 0.0:
            return "0.0F" if self.scalar == "float" else "0.0"
        return super()._print_Float(expr)

    def _print_Pow(self, expr: sp.Pow) -> str:
        one = "1.0F" if self.scalar == "float" else "1.0"
        text = small_power(self, expr, one)
        return text if text is not None else super()._print_Pow(expr)


#: Kernel arrays the C stores as lane pairs, each entry twice, in another array: F h lives in term[0] during the
#: Horner chain (which uses term[1] and S only; term[0] is next written by the doublings and S G), entry e at
#: fh_pairs[2 e] and fh_pairs[2 e + 1], fh_pairs = term[0] or term[0] + 1, whichever is 16-byte aligned
#: (:data:`PAIRED_POINTER`), so that a loop reads it broadcast with one aligned load (:func:`c_pair`).
PAIRED = {("scratch", "fh"): ("term", 0)}
PAIRED_POINTER = "fh_pairs"


def paired(ref: Ref) -> bool:
    """Whether ``ref`` is an entry of an array stored as lane pairs (:data:`PAIRED`)."""
    return (ref.owner, ref.array) in PAIRED


def c_ref(ref: Ref, lane: int = 0) -> str:
    """``t->Phi[3][4]``: a kernel entry through its owner's pointer (a ``local`` scalar by its name; of a paired array, ``lane``)."""
    if ref.owner == "local":
        return ref.array
    if paired(ref):
        return f"{PAIRED_POINTER}[{2 * ref.index[0] + lane}]"
    return f"{POINTERS[ref.owner]}->{ref.array}" + "".join(f"[{i}]" for i in ref.index)


def c_paired_pointer(ref: Ref, scalar_type: str, written: bool) -> str:
    """The declaration of :data:`PAIRED_POINTER` for ``ref``'s array: the first 16-byte aligned entry of its storage."""
    array, row = PAIRED[(ref.owner, ref.array)]
    storage = f"{POINTERS[ref.owner]}->{array}[{row}]"
    return f"{'' if written else 'const '}{scalar_type} *{PAIRED_POINTER} = {storage} + lane_pair_offset({storage});"


def c_pair(ref: Ref) -> str:
    """An entry of a paired array broadcast into two lanes: its two stored copies, one aligned load."""
    assert paired(ref)
    return f"lane_pair_load_aligned(&{c_ref(ref)})"


def c_sum(terms: tuple[Term, ...]) -> str:
    """A sum of products, ``0`` when empty."""
    return " + ".join("*".join(c_ref(r) for r in term) for term in terms) if terms else "0"


def c_statement(statement: Statement, read_back: bool = False, value: str | None = None) -> str:
    """One kernel statement as one line of C (a checked one with ``read_back``: the stores only, summed later).

    ``value``: the C of its sum when printed otherwise (two lanes), else the sum of its terms.
    """
    value = c_sum(statement.terms) if value is None else value
    if isinstance(statement, Assign):
        if paired(statement.target):  # both copies, as one store of the value in two lanes (the compiler computes it once)
            return f"lane_pair_store(&{c_ref(statement.target)}, lane_pair_of({value}, {value}));"
        return f"{c_ref(statement.target)} = {value};"
    assert isinstance(statement, CheckedAssign)
    if read_back:
        first = c_ref(statement.targets[0])
        return f"{first} = {value};" + "".join(f" {c_ref(t)} = {first};" for t in statement.targets[1:])
    stores = " ".join(f"{c_ref(t)} = v;" for t in statement.targets)
    return f"v = {value}; {stores} check += v;"


def _follows(first: Ref, second: Ref) -> bool:
    """Whether ``second`` is the entry right after ``first`` in memory (same array and row, next index)."""
    return (
        first.owner == second.owner != "local"
        and not paired(first)  # entry e + 1 of a paired array is not next to entry e's first copy
        and first.array == second.array
        and first.index[:-1] == second.index[:-1]
        and second.index[-1] == first.index[-1] + 1
    )


def _lane_operand(first: Ref, second: Ref) -> str:
    """Two factors as one lane pair: one load when they are consecutive entries."""
    if _follows(first, second):
        return f"lane_pair_load(&{c_ref(first)})"
    return f"lane_pair_of({c_ref(first)}, {c_ref(second)})"


def c_lines(statement: Statement, read_back: bool = False, two_lanes: bool = False) -> list[str]:
    """A kernel statement as C; with ``two_lanes``, its sum of products in two lanes (``kernels.lane_split``).

    A pair of terms is one two-lane product (SSE2 vector code, or the same
    operations on two scalars); the lanes are then added, then the other
    terms.  gcc -O2 does not find these vector products itself in
    straight-line code of several dot products (bench/bench_cycle.py).  The
    block declares ``lane_pair acc``.
    """
    pairs, rest = lane_split(statement.terms) if two_lanes else ((), statement.terms)
    if not pairs:
        return [c_statement(statement, read_back)]
    (a, b), *others = pairs
    lines = [f"acc = lane_pair_product({_lane_operand(a[0], b[0])}, {_lane_operand(a[1], b[1])});"]
    lines += [f"acc = lane_pair_add_product(acc, {_lane_operand(a[0], b[0])}, {_lane_operand(a[1], b[1])});" for a, b in others]
    value = " + ".join(["lane_pair_sum(acc)", *("*".join(c_ref(r) for r in term) for term in rest)])
    return lines + [c_statement(statement, read_back, value)]


def c_declarator(field) -> str:
    """``P[NED_DOPPLER18_N_STATES][NED_DOPPLER18_N_STATES]``: a struct member with its dimensions."""
    return field.name + "".join(f"[{d.text}]" for d in field.dims)


def accessors(packed: bool, prefix: str) -> tuple[Callable[[str, str, str], str], Callable[[str, str, str], str]]:
    """C text for entry (i, j) of a symmetric matrix: (i <= j only, any i, j), for the loop templates."""
    if packed:
        return (
            lambda base, i, j: f"{base}[{prefix}_PACKED_UPPER({i}, {j})]",
            lambda base, i, j: f"{base}[{prefix}_PACKED_ANY({i}, {j})]",
        )
    return (lambda base, i, j: f"{base}[{i}][{j}]", lambda base, i, j: f"{base}[{i}][{j}]")


#: Longest line of the generated C (tests/codegen/test_c_contract.py checks it).
LINE_WIDTH = 100


def wrap_line(line: str, width: int = LINE_WIDTH) -> list[str]:
    """``line`` broken at spaces into lines of at most ``width`` columns where C allows it.

    A space may become a line break anywhere in C code and inside a block
    comment; preprocessor lines, string literals and ``//`` comments are left
    whole.  Continuations are indented 8 more columns (``*   `` inside a
    comment block whose lines start with ``*``).
    """
    if len(line) <= width:
        return [line]
    body = line.lstrip(" ")
    indent = line[: len(line) - len(body)]
    if body.startswith("#define") and " /* " in body and body.endswith("*/") and '"' not in body:
        directive, comment = body.split(" /* ", 1)  # the comment goes on the lines above the macro
        return wrap_line(indent + "/* " + comment, width) + [indent + directive.rstrip(" ")]
    if body.startswith("#") or '"' in body or "//" in body:
        return [line]
    continuation = indent + ("*   " if body.startswith("* ") else " " * 8)
    room = width - len(continuation)
    words = [piece for word in body.split(" ") for piece in _split_product(word, room)]
    if len(words) > 1 and words[-1] == "*/":  # a comment's end stays with its last word
        words[-2:] = [words[-2] + " */"]
    lines, current = [], indent + words[0]
    for word in words[1:]:
        if len(current) + 1 + len(word) > width and current.strip() not in ("", "*"):
            lines.append(current.rstrip(" "))
            current = continuation + word
        else:
            current += " " + word
    lines.append(current)
    return lines


def _split_product(word: str, room: int) -> list[str]:
    """A product longer than ``room`` split after its ``*`` (a break is then a space, which C allows)."""
    if len(word) <= room or "*" not in word or "/*" in word or "*/" in word:
        return [word]
    pieces, current = [], ""
    for factor in word.split("*"):
        candidate = f"{current}*{factor}" if current else factor
        if current and len(candidate) + 1 > room:
            pieces.append(current + "*")
            current = factor
        else:
            current = candidate
    return pieces + [current]


def wrap_c(text: str, width: int = LINE_WIDTH) -> str:
    """Every line of a C file wrapped by :func:`wrap_line`."""
    return "\n".join(out for line in text.split("\n") for out in wrap_line(line, width))
