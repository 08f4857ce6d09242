"""Equation text to sympy, safely: a model file's expressions are data, never code.

sympy's parser evaluates its input as Python, so every equation a model file
gives is checked first (length, tokens, number literals, syntax-tree depth,
exponents) and its result afterwards (only declared symbols and the allowed
functions, defined and finite everywhere, a bounded size once multiplied
out).  :func:`parse_expression` is the one entry point; the checks are public
for the vector notation (:mod:`modelgen.model.vectors`), which parses its own
text with the same rules.
"""

from __future__ import annotations

import keyword
import re
from typing import Any, Mapping

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.file_fields import underflows_to_zero

# -- limits on what a model may contain (hostile-input bounds) --------------------
#: Longest expression text accepted, in characters.
MAX_EXPRESSION_LENGTH = 10_000
#: Deepest expression accepted, counted in levels of nesting: the terms of one
#: flat sum ``a + b + c`` (or factors of one flat product) share a level.
MAX_EXPRESSION_DEPTH = 100
#: Most syntax-tree levels accepted, the terms of a flat sum or product each
#: one level (Python's compiler, which sympy's parser calls, recurses through
#: them: about 3,000 exhaust it).
MAX_SYNTAX_DEPTH = 1000
#: Largest constant exponent accepted, in absolute value.
MAX_EXPONENT = 64
#: Longest number literal accepted, in characters.
MAX_NUMBER_LENGTH = 40
#: Most terms an expression may have once multiplied out (derivation expands).
MAX_EXPANDED_TERMS = 10_000
#: Largest finite double (DBL_MAX): a constant beyond it is infinite in C.
DOUBLE_MAX = 1.7976931348623157e308

#: Functions an equation may use; anything else is an unknown symbol.
ALLOWED_FUNCTIONS: dict[str, object] = {
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "sec": sp.sec,
    "asin": sp.asin,
    "acos": sp.acos,
    "atan": sp.atan,
    "atan2": sp.atan2,
    "sqrt": sp.sqrt,
    "exp": sp.exp,
    "log": sp.log,
    "Abs": sp.Abs,
    "pi": sp.pi,
}


def excerpt(text: str, limit: int = 80) -> str:
    """``text`` quoted, cut to ``limit`` characters so that a huge expression makes a short message."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} characters)"



#: Operators an equation may contain; anything else (attribute access, indexing,
#: strings, keywords) is refused before the text reaches sympy's eval-based parser.
_ALLOWED_OPERATORS = frozenset({"+", "-", "*", "/", "**", "(", ")", ","})
#: A number literal: decimal integer or float, with an optional exponent.  No
#: imaginary (``1j``), hexadecimal, octal, binary or underscored literals.
_DECIMAL_NUMBER = re.compile(r"^(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def check_tokens(text: str, where: str) -> None:
    """Allow only names, decimal numbers and arithmetic in equation text.

    sympy's ``parse_expr`` evaluates its input as Python, so ``x.subs(...)``
    or ``x.__class__`` in a model file would run.  A model file is data: only
    identifiers, numbers and ``+ - * / ** ( ) ,`` may appear.  A number must
    be decimal, at most :data:`MAX_NUMBER_LENGTH` characters long and within
    the range of a double.
    """
    import io
    import tokenize

    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, SyntaxError, IndentationError) as exc:
        raise ModelError(f"{where}: cannot parse {excerpt(text)} ({exc})") from None
    skip = {tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER, tokenize.INDENT, tokenize.DEDENT}
    for tok in tokens:
        if tok.type in skip:
            continue
        if tok.type == tokenize.NUMBER:
            _check_number(tok.string, text, where)
            continue
        if tok.type == tokenize.NAME and not keyword.iskeyword(tok.string):
            continue
        if tok.type == tokenize.OP and tok.string in _ALLOWED_OPERATORS:
            continue
        raise ModelError(
            f"{where}: {tok.string!r} is not allowed in {excerpt(text)} "
            "(an expression may use only declared names, numbers, + - * / ** ( ) and functions)"
        )


def _check_number(literal: str, text: str, where: str) -> None:
    """Refuse a number literal that is not decimal, is too long, or overflows a double."""
    if not _DECIMAL_NUMBER.match(literal):
        raise ModelError(f"{where}: {literal!r} in {excerpt(text)} is not a decimal number (no imaginary, hex or other literals)")
    if len(literal) > MAX_NUMBER_LENGTH:
        raise ModelError(
            f"{where}: the number {literal[:20]}... in {excerpt(text)} has {len(literal)} characters; "
            f"at most {MAX_NUMBER_LENGTH} are accepted"
        )
    if abs(float(literal)) > DOUBLE_MAX:
        raise ModelError(f"{where}: the number {literal} in {excerpt(text)} is beyond the range of a double")
    if underflows_to_zero(literal):
        raise ModelError(
            f"{where}: the number {literal} in {excerpt(text)} is nonzero but below the smallest double "
            "(about 4.9e-324): it would be read as 0"
        )


def check_syntax(text: str, namespace: Mapping[str, sp.Symbol], where: str) -> None:
    """Check an expression's shape before sympy sees it, so that nothing can hang.

    On the Python syntax tree: depth at most :data:`MAX_EXPRESSION_DEPTH`;
    every name declared (or an allowed function); exponents constant and at
    most :data:`MAX_EXPONENT` in absolute value, or symbolic, and never a
    power of a power (``10**10**10``).
    """
    import ast

    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError) as exc:
        raise ModelError(f"{where}: cannot parse {excerpt(text)} ({exc.msg if isinstance(exc, SyntaxError) else exc})") from None
    except (RecursionError, MemoryError):
        raise ModelError(f"{where}: {excerpt(text)} is nested too deeply to parse") from None
    unknown_symbols, unknown_functions = set(), set()
    stack = [(tree.body, 1, 1)]  # (node, nesting depth, syntax-tree depth)
    while stack:
        node, depth, syntax_depth = stack.pop()
        if depth > MAX_EXPRESSION_DEPTH:
            raise ModelError(f"{where}: {excerpt(text)} is nested more than {MAX_EXPRESSION_DEPTH} levels deep")
        if syntax_depth > MAX_SYNTAX_DEPTH:
            raise ModelError(
                f"{where}: {excerpt(text)} has a sum or product of more than {MAX_SYNTAX_DEPTH} terms "
                "(or nests sums of many terms more than that deep)"
            )
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id not in ALLOWED_FUNCTIONS and node.func.id not in namespace:
                unknown_functions.add(node.func.id)
            children = list(node.args) + [k.value for k in node.keywords]
        elif isinstance(node, ast.Name):
            if node.id not in namespace and node.id not in ALLOWED_FUNCTIONS:
                unknown_symbols.add(node.id)
            children = []
        else:
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
                _check_exponent(node.right, text, where)
            children = list(ast.iter_child_nodes(node))
        stack.extend((child, depth + (not _continues_chain(node, child)), syntax_depth + 1) for child in children)
    if unknown_symbols:
        raise ModelError(f"{where}: unknown symbol(s) {', '.join(sorted(unknown_symbols))} in {excerpt(text)}")
    if unknown_functions:
        raise ModelError(f"{where}: unknown function(s) {', '.join(sorted(unknown_functions))}")


def _continues_chain(node: Any, child: Any) -> bool:
    """``child`` is the left operand of ``node`` in one flat sum (``+ -``) or product (``* /``): the same level.

    Python parses ``a + b + c`` as ``(a + b) + c``: the chain's left
    operands nest, but the sum is flat; a right operand or a parenthesized
    sum inside a product is nesting.
    """
    import ast

    additive, multiplicative = (ast.Add, ast.Sub), (ast.Mult, ast.Div)
    if not (isinstance(node, ast.BinOp) and isinstance(child, ast.BinOp) and child is node.left):
        return False
    return any(isinstance(node.op, family) and isinstance(child.op, family) for family in (additive, multiplicative))


def _check_exponent(exponent: Any, text: str, where: str) -> None:
    """Refuse a power tower or a constant exponent beyond :data:`MAX_EXPONENT`."""
    import ast

    nodes = list(ast.walk(exponent))
    if any(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow) for n in nodes):
        raise ModelError(f"{where}: a power of a power (such as 10**10**10) is not accepted in {excerpt(text)}")
    if any(isinstance(n, ast.Name) for n in nodes):
        return  # a symbolic exponent: evaluated at run time, never expanded here
    value = _constant_value(exponent)
    if value is None or not abs(value) <= MAX_EXPONENT:
        raise ModelError(
            f"{where}: exponent {ast.unparse(exponent)[:40]} in {excerpt(text)} is not a number of at most "
            f"{MAX_EXPONENT} in absolute value"
        )


def _constant_value(node: Any) -> float | None:
    """The value of a constant exponent (numbers, + - * /), or None if it has none (e.g. 1/0)."""
    import ast
    import operator

    binary = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv}
    try:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            inner = _constant_value(node.operand)
            return None if inner is None else (inner if isinstance(node.op, ast.UAdd) else -inner)
        if isinstance(node, ast.BinOp) and type(node.op) in binary:
            left, right = _constant_value(node.left), _constant_value(node.right)
            if left is None or right is None:
                return None
            value = binary[type(node.op)](left, right)
            return value if value == value and abs(value) != float("inf") else None
    except (ArithmeticError, OverflowError):
        return None
    return None


#: Values sympy gives an undefined or infinite expression.
_NON_FINITE = (sp.nan, sp.zoo, sp.oo, -sp.oo)


def check_defined(expr: sp.Expr, text: str, where: str) -> None:
    """Refuse an expression that is undefined, infinite or complex anywhere.

    Refused: nan, zoo (complex infinity, e.g. ``x/0`` or ``log(0)``), oo, the
    imaginary unit (``sqrt(-4)``), any constant part whose value is not a
    finite real double (``asin(2)``, ``exp(1000)``), a denominator that is
    zero once simplified (``x/(sin(k)**2 + cos(k)**2 - 1)``), and an
    expression that would multiply out to more than :data:`MAX_EXPANDED_TERMS`
    terms.
    """
    def shown() -> str:  # printed only for a message: printing a large expression costs seconds
        return excerpt(str(text))

    if expr.has(*_NON_FINITE):
        raise ModelError(f"{where}: {shown()} is undefined or infinite (it evaluates to {excerpt(str(expr))})")
    if expr.has(sp.I):
        raise ModelError(f"{where}: {shown()} is complex (it evaluates to {excerpt(str(expr))})")
    terms = _expanded_terms(expr)
    if terms > MAX_EXPANDED_TERMS:
        raise ModelError(
            f"{where}: {shown()} multiplies out to more than {MAX_EXPANDED_TERMS} terms; write it in a smaller form"
        )
    power = _largest_power_of_a_sum(expr)
    if power > MAX_EXPONENT:
        raise ModelError(
            f"{where}: {shown()} raises a sum to the power {power} once the definitions or entries it refers to are written out "
            f"(at most {MAX_EXPONENT}: its expansion's coefficients grow with the power, past what sympy multiplies "
            "out in reasonable time)"
        )
    stack = [expr]
    while stack:
        e = stack.pop()
        if e.is_number:
            if not _finite_real(e):
                raise ModelError(f"{where}: {shown()} has a part, {excerpt(str(e))}, that is not a finite real number")
            continue
        if isinstance(e, sp.Pow) and e.exp.is_negative and _is_zero(e.base):
            raise ModelError(f"{where}: {shown()} divides by {excerpt(str(e.base))}, which is zero")
        stack.extend(e.args)


def _finite_real(e: sp.Expr) -> bool:
    """Whether a constant expression is a finite real number within the range of a double."""
    try:
        value = e.evalf(20)
        if value.has(*_NON_FINITE) or value.has(sp.I) or not value.is_real or not value.is_finite:
            return False
        return abs(float(value)) <= DOUBLE_MAX
    except (TypeError, ValueError, ArithmeticError, RecursionError):
        return False


def _is_zero(e: sp.Expr) -> bool:
    """Whether a denominator is identically zero (``sin(k)**2 + cos(k)**2 - 1``).

    sympy's assumptions decide most cases.  Otherwise the denominator is
    evaluated at a generic point: a clearly nonzero value proves it is not
    identically zero, without the cost of ``simplify`` (seconds per
    expression).  Only a denominator that vanishes there, and is small, is
    simplified to decide.
    """
    if e.is_zero:
        return True
    if e.is_zero is False:
        return False
    point = {s: sp.Rational(3 + 2 * k, 7 + 3 * k) for k, s in enumerate(sorted(e.free_symbols, key=str))}
    try:
        value = complex(e.subs(point).evalf(30))
        if value == value and abs(value) > 1e-20 and abs(value) != float("inf"):
            return False
    except (TypeError, ValueError, ArithmeticError, RecursionError):
        pass
    return sp.count_ops(e) <= 40 and sp.simplify(e) == 0


def _largest_power_of_a_sum(expr: sp.Expr) -> int:
    """The largest integer exponent |n| of a power whose base is a sum, anywhere in ``expr`` (0 if none).

    A literal exponent is bounded by :data:`MAX_EXPONENT` in the text; powers of definitions that are powers
    themselves (``a1 = (x + y)**64``, ``a2 = a1**64``) combine to (x + y)**4096, which has few terms but binomial
    coefficients of over a thousand digits: the term count does not see it.
    """
    return max((abs(int(e.exp)) for e in sp.preorder_traversal(expr)
                if isinstance(e, sp.Pow) and e.exp.is_Integer and isinstance(e.base, sp.Add)), default=0)


def _expanded_terms(expr: sp.Expr) -> int:
    """An upper bound on the terms of ``sp.expand(expr)`` or any of its parts (capped)."""
    from math import comb

    cap = MAX_EXPANDED_TERMS + 1
    terms: dict[sp.Basic, int] = {}
    worst = 1
    for e in sp.postorder_traversal(expr):
        if e in terms:
            continue
        if isinstance(e, sp.Add):
            n = sum(terms.get(a, 1) for a in e.args)
        elif isinstance(e, sp.Mul):
            n = 1
            for a in e.args:
                n = min(cap, n * terms.get(a, 1))
        elif isinstance(e, sp.Pow) and e.exp.is_Integer:
            base = terms.get(e.base, 1)
            k = min(abs(int(e.exp)), cap)
            n = 1 if base == 1 else min(cap, comb(base + k - 1, k))
        else:
            n = 1
        terms[e] = min(cap, n)
        worst = max(worst, terms[e])
    return worst


def parse_expression(text: str | sp.Expr | float | int, namespace: Mapping[str, sp.Symbol], where: str) -> sp.Expr:
    """Parse an equation, refusing any symbol not in ``namespace``.

    Names such as ``beta`` or ``gamma`` would be sympy functions under the
    default parser; here only declared symbols and :data:`ALLOWED_FUNCTIONS`
    exist, so every identifier means exactly what the model declared.  The
    text is checked (length, tokens, syntax tree) before sympy sees it, and
    the result is refused if it is undefined, infinite or complex anywhere
    (see :func:`check_defined`).
    """
    if isinstance(text, sp.Basic):
        expr = text
    elif isinstance(text, (int, float)) and not isinstance(text, bool):
        if isinstance(text, float) and not abs(text) <= DOUBLE_MAX:
            raise ModelError(f"{where}: {text!r} is not a finite number")
        expr = sp.nsimplify(text) if isinstance(text, int) else sp.Float(text)
    elif isinstance(text, str):
        from sympy.parsing.sympy_parser import parse_expr, standard_transformations

        if len(text) > MAX_EXPRESSION_LENGTH:
            raise ModelError(
                f"{where}: expression of {len(text)} characters; at most {MAX_EXPRESSION_LENGTH} are accepted"
            )
        check_tokens(text, where)
        check_syntax(text, namespace, where)
        local = dict(namespace)
        global_ns = {
            "Integer": sp.Integer,  # what parse_expr turns number literals into
            "Float": sp.Float,
            "Rational": sp.Rational,
            **ALLOWED_FUNCTIONS,
        }
        try:
            expr = parse_expr(text, local_dict=local, global_dict=global_ns, transformations=standard_transformations)
        except (SyntaxError, TypeError, NameError, AttributeError, ValueError) as exc:
            raise ModelError(f"{where}: cannot parse {excerpt(text)} ({exc})") from None
        except (RecursionError, MemoryError):
            raise ModelError(f"{where}: {excerpt(text)} is nested too deeply to parse") from None
    else:
        raise ModelError(f"{where}: expected an expression, got {type(text).__name__}")
    if not isinstance(expr, sp.Expr):
        raise ModelError(f"{where}: {excerpt(str(text))} is not a scalar expression")
    known = set(namespace.values())
    unknown = sorted(str(s) for s in expr.free_symbols if s not in known)
    if unknown:
        raise ModelError(f"{where}: unknown symbol(s) {', '.join(unknown)} in {excerpt(str(text))}")
    bad_functions = sorted(
        {type(f).__name__ for f in expr.atoms(sp.Function) if type(f).__name__ not in ALLOWED_FUNCTIONS}
    )
    if bad_functions:
        raise ModelError(f"{where}: unknown function(s) {', '.join(bad_functions)}")
    check_defined(expr, text, where)
    return expr
