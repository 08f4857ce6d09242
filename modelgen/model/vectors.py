"""3-vectors, 3x3 matrices and named definitions in model expressions.

A model file may declare a state, noise, parameter or measurement with
``shape: 3`` (a 3-vector) or ``shape: [3, 3]`` (a 3x3 matrix) and write its
equations with vector operations: ``cross``, ``dot``, ``skew``,
``transpose``, ``diag``, ``eye``, ``norm``, ``vector``, and matrix and
matrix-vector products with ``*``.  A ``definitions:`` list names
intermediate expressions, each usable by the ones after it.

Expressions are evaluated here by walking their Python syntax tree, never by
``eval``: the text first passes the same token and syntax whitelist as a
scalar equation (:func:`modelgen.model.declaration.parse_expression`), then
each node is one of a handful of operations on sympy scalars and
``sympy.Matrix`` values, with the shapes checked at every step so that a
mismatch is reported with the operation and both shapes.

After loading, a vector model is an ordinary scalar
:class:`~modelgen.model.declaration.ErrorModel`: every vector is expanded into
its components, named by :func:`component_names` (``dv`` -> ``dv_n, dv_e,
dv_d`` in NED).
"""

from __future__ import annotations

import ast
from typing import Any, Callable, Mapping, Sequence

import sympy as sp

from modelgen.errors import ModelError
from modelgen.model.declaration import check_identifier
from modelgen.model.expression import (
    ALLOWED_FUNCTIONS,
    MAX_EXPRESSION_LENGTH,
    check_defined,
    check_syntax,
    check_tokens,
    excerpt,
)

#: A value in a vector expression: a sympy scalar or a sympy Matrix.
Value = Any  # sp.Expr | sp.Matrix

#: Shapes a declaration may have: a scalar, a 3-vector (column) or a 3x3 matrix.
SUPPORTED_SHAPES = ((1, 1), (3, 1), (3, 3))
#: Most nodes an expression's tree may have once every definition it uses is written
#: out.  Definitions share subexpressions, so ``d1 = sin(d0) + cos(d0)``, ``d2 = sin(d1)
#: + cos(d1)``... doubles the tree with each line; sympy's later passes walk the tree,
#: not the shared graph, and would take hours.  The largest built-in equation has
#: under 300 nodes.
MAX_TREE_NODES = 20_000
#: Axis letters of a 3-vector's components, by the axes it is resolved in.
AXIS_SUFFIXES: dict[str, tuple[str, str, str]] = {
    "NED": ("n", "e", "d"),
    "ENU": ("e", "n", "u"),
    "body": ("x", "y", "z"),
}


# -- shapes ---------------------------------------------------------------------
def shape_of(value: Value) -> tuple[int, int]:
    """(rows, columns) of a value; a scalar is (1, 1)."""
    return tuple(value.shape) if isinstance(value, sp.MatrixBase) else (1, 1)  # type: ignore[return-value]


def shape_text(value_or_shape: Value | tuple[int, int]) -> str:
    """``scalar``, ``3x1`` or ``3x3``: how messages name a shape."""
    shape = value_or_shape if isinstance(value_or_shape, tuple) else shape_of(value_or_shape)
    return "scalar" if shape == (1, 1) else f"{shape[0]}x{shape[1]}"


def is_matrix(value: Value) -> bool:
    """Whether ``value`` is a Matrix (a vector or matrix) rather than a scalar."""
    return isinstance(value, sp.MatrixBase)


def _as_scalar_if_1x1(value: Value) -> Value:
    """A 1x1 Matrix (``transpose(a)*b``) as the scalar it is."""
    if isinstance(value, sp.MatrixBase) and value.shape == (1, 1):
        return value[0, 0]
    return value


def _is_3_vector(value: Value) -> bool:
    return isinstance(value, sp.MatrixBase) and value.shape == (3, 1)


# -- the vector functions --------------------------------------------------------
def cross(a: Value, b: Value) -> sp.Matrix:
    """a x b, the cross product of two 3-vectors (a 3-vector)."""
    if not (_is_3_vector(a) and _is_3_vector(b)):
        raise ModelError(f"cross() needs two 3-vectors, got {shape_text(a)} and {shape_text(b)}")
    return sp.Matrix(a).cross(sp.Matrix(b))


def dot(a: Value, b: Value) -> sp.Expr:
    """a . b = a^T b, the scalar product of two 3-vectors."""
    if not (_is_3_vector(a) and _is_3_vector(b)):
        raise ModelError(f"dot() needs two 3-vectors, got {shape_text(a)} and {shape_text(b)}")
    return sp.Matrix(a).dot(sp.Matrix(b))


def skew(a: Value) -> sp.Matrix:
    """[a x], the skew-symmetric matrix with [a x] b = a x b for every b."""
    if not _is_3_vector(a):
        raise ModelError(f"skew() needs a 3-vector, got {shape_text(a)}")
    return sp.Matrix([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def transpose(a: Value) -> sp.Matrix:
    """A^T of a matrix or vector (a vector becomes a 1x3 row; ``transpose(a)*b`` is a scalar)."""
    if not is_matrix(a):
        raise ModelError("transpose() needs a vector or matrix, got scalar")
    return sp.Matrix(a).T


def diag(*entries: Value) -> Value:
    """A diagonal matrix: ``diag(v)`` of a 3-vector, ``diag(a, b, c)`` of three scalars; the diagonal of a 3x3 matrix as a 3-vector."""
    if len(entries) == 3 and not any(is_matrix(e) for e in entries):
        return sp.diag(*entries)
    if len(entries) == 1 and _is_3_vector(entries[0]):
        return sp.diag(*list(entries[0]))
    if len(entries) == 1 and shape_of(entries[0]) == (3, 3):
        return sp.Matrix([entries[0][i, i] for i in range(3)])
    got = ", ".join(shape_text(e) for e in entries) or "no arguments"
    raise ModelError(f"diag() needs a 3-vector, three scalars or a 3x3 matrix, got {got}")


def eye(*size: Value) -> sp.Matrix:
    """The 3x3 identity: ``eye()`` or ``eye(3)`` (only 3x3 matrices are supported)."""
    if size and (len(size) != 1 or is_matrix(size[0]) or size[0] != 3):
        got = ", ".join(shape_text(s) if is_matrix(s) else str(s) for s in size)
        raise ModelError(f"eye() makes the 3x3 identity: write eye() or eye(3), got eye({got})")
    return sp.eye(3)


def norm(a: Value) -> sp.Expr:
    """|a| = sqrt(a . a), the Euclidean length of a 3-vector."""
    if not _is_3_vector(a):
        raise ModelError(f"norm() needs a 3-vector, got {shape_text(a)}")
    return sp.sqrt(sp.Matrix(a).dot(sp.Matrix(a)))


def vector(*entries: Value) -> sp.Matrix:
    """The 3-vector of three scalars, ``vector(v_n, v_e, v_d)``."""
    if len(entries) != 3 or any(is_matrix(e) for e in entries):
        got = ", ".join(shape_text(e) for e in entries) or "no arguments"
        raise ModelError(f"vector() needs three scalars, got {got}")
    return sp.Matrix(entries)


#: Functions of vectors and matrices an expression may call, by name.
VECTOR_FUNCTIONS: dict[str, Callable[..., Value]] = {
    "cross": cross,
    "dot": dot,
    "skew": skew,
    "transpose": transpose,
    "diag": diag,
    "eye": eye,
    "norm": norm,
    "vector": vector,
}


def library_functions() -> dict[str, Callable[..., Value]]:
    """Every function an expression may call besides the scalar ones: vector functions and the navigation library."""
    from modelgen.model.navlib import NAVLIB_FUNCTIONS

    return {**VECTOR_FUNCTIONS, **NAVLIB_FUNCTIONS}


def library_constants() -> dict[str, sp.Expr]:
    """Named constants an expression may use (the WGS-84 constants of the navigation library)."""
    from modelgen.model.navlib import NAVLIB_CONSTANTS

    return dict(NAVLIB_CONSTANTS)


# -- evaluating an expression ----------------------------------------------------
def parse_vector_expression(text: str | sp.Expr | float | int, namespace: Mapping[str, Value], where: str) -> Value:
    """Evaluate an expression whose names may stand for scalars, 3-vectors or 3x3 matrices.

    ``namespace`` maps names to sympy scalars or Matrices; a declared name
    shadows a library function or constant of the same name.  The text passes
    the same token and syntax whitelist as a scalar equation; then its syntax
    tree is evaluated node by node (numbers, names, ``+ - * / **``, unary
    minus, calls of :data:`VECTOR_FUNCTIONS`, the navigation library and the
    scalar functions).  A shape mismatch, a vector where a scalar is needed or
    a wrong call is a :class:`ModelError` naming ``where``, the operation and
    the shapes.  Every scalar (or element) of the result is checked to be
    defined and finite, as a scalar equation is.
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        text = repr(text)
    if isinstance(text, (sp.Basic, sp.MatrixBase)):  # already built: only the checks on the result apply
        known = set().union(*(v.free_symbols for v in namespace.values() if isinstance(v, (sp.Basic, sp.MatrixBase))))
        unknown = sorted(str(x) for x in text.free_symbols - known)
        if unknown:
            raise ModelError(f"{where}: unknown symbol(s) {', '.join(unknown)} in {excerpt(str(text))}")
        return _checked_result(_as_scalar_if_1x1(text), str(text), where)
    if not isinstance(text, str):
        raise ModelError(f"{where}: expected an expression, got {type(text).__name__}")
    if len(text) > MAX_EXPRESSION_LENGTH:
        raise ModelError(f"{where}: expression of {len(text)} characters; at most {MAX_EXPRESSION_LENGTH} are accepted")
    functions = {**library_functions(), **{k: v for k, v in ALLOWED_FUNCTIONS.items() if k != "pi"}}
    values: dict[str, Value] = {"pi": sp.pi, **library_constants()}
    for name, value in namespace.items():
        functions.pop(name, None)  # a declared name shadows a library name
        values[name] = value
    check_tokens(text, where)
    try:
        check_syntax(text, {**values, **functions}, where)
    except ModelError as exc:
        if "unknown function" not in str(exc):
            raise
        raise ModelError(f"{exc} (the functions are: {', '.join(sorted(functions))})") from None
    source = text.strip()
    tree = ast.parse(source, mode="eval")
    evaluator = _Evaluator(source, values, functions, where)
    return _checked_result(_as_scalar_if_1x1(evaluator.evaluate(tree.body)), text, where)


def _checked_result(result: Value, text: str, where: str) -> Value:
    """``result`` once each element is an expression, of bounded size, defined and finite (else ModelError)."""
    for element in (list(result) if is_matrix(result) else [result]):
        if not isinstance(element, sp.Expr):
            raise ModelError(f"{where}: {excerpt(text)} is not an expression")
        if tree_size(element, MAX_TREE_NODES) > MAX_TREE_NODES:
            raise ModelError(
                f"{where}: {excerpt(text)} grows to more than {MAX_TREE_NODES} operations once the definitions "
                "it uses are written out; write it in a smaller form"
            )
        check_defined(element, text, where)
    return result


def tree_size(expr: sp.Basic, cap: int) -> int:
    """Nodes of ``expr``'s tree (shared subexpressions counted each time they occur), at most ``cap + 1``.

    Computed on the shared graph, bottom-up and memoized, so it costs time in
    proportion to the distinct subexpressions even when the tree is
    exponentially larger (see :data:`MAX_TREE_NODES`).
    """
    sizes: dict[int, int] = {}
    stack: list[tuple[sp.Basic, bool]] = [(expr, False)]
    while stack:
        node, children_done = stack.pop()
        if id(node) in sizes:
            continue
        if not children_done:
            stack.append((node, True))
            stack.extend((arg, False) for arg in node.args if id(arg) not in sizes)
            continue
        sizes[id(node)] = min(cap + 1, 1 + sum(sizes[id(arg)] for arg in node.args))
    return sizes[id(expr)]


class _Evaluator:
    """Evaluates a whitelisted syntax tree on sympy scalars and Matrices (see :func:`parse_vector_expression`)."""

    def __init__(self, source: str, values: Mapping[str, Value], functions: Mapping[str, Callable], where: str):
        self.source, self.values, self.functions, self.where = source, values, functions, where

    def fail(self, node: ast.AST, problem: str) -> ModelError:
        """A ModelError for ``node``: where, the problem, and the part of the text it is about."""
        part = ast.get_source_segment(self.source, node) or self.source
        shown = f" in {excerpt(part)}" if part != self.source else f" in {excerpt(self.source)}"
        return ModelError(f"{self.where}: {problem}{shown}")

    def evaluate(self, node: ast.AST) -> Value:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            literal = ast.get_source_segment(self.source, node) or repr(node.value)
            return sp.Integer(node.value) if isinstance(node.value, int) else sp.Float(literal)
        if isinstance(node, ast.Name):
            if node.id in self.values:
                return self.values[node.id]
            if node.id in self.functions:
                raise self.fail(node, f"{node.id!r} is a function: call it, as {node.id}(...)")
            raise self.fail(node, f"unknown symbol {node.id!r}")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            operand = self.evaluate(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp):
            return self.binary(node)
        if isinstance(node, ast.Call):
            return self.call(node)
        raise self.fail(node, f"{type(node).__name__} is not allowed (only names, numbers, + - * / ** and calls)")

    def binary(self, node: ast.BinOp) -> Value:
        left, right = self.evaluate(node.left), self.evaluate(node.right)
        shapes = f"{shape_text(left)} and {shape_text(right)}"
        op = node.op
        if isinstance(op, (ast.Add, ast.Sub)):
            if shape_of(left) != shape_of(right):
                verb = "add" if isinstance(op, ast.Add) else "subtract"
                raise self.fail(node, f"cannot {verb} a {shape_text(left)} and a {shape_text(right)} (shapes differ)")
            result = left + right if isinstance(op, ast.Add) else left - right
        elif isinstance(op, ast.Mult):
            if is_matrix(left) and is_matrix(right) and left.shape[1] != right.shape[0]:
                raise self.fail(node, f"cannot multiply a {shape_text(left)} by a {shape_text(right)} (inner sizes differ)")
            result = left * right
        elif isinstance(op, ast.Div):
            if is_matrix(right):
                raise self.fail(node, f"cannot divide by a {shape_text(right)} (only by a scalar); got {shapes}")
            result = left / right
        elif isinstance(op, ast.Pow):
            if is_matrix(left) or is_matrix(right):
                raise self.fail(node, f"** needs scalars, got {shapes} (write matrix products with *)")
            result = left**right
        else:
            raise self.fail(node, f"operator {type(op).__name__} is not allowed")
        return _as_scalar_if_1x1(result)

    def call(self, node: ast.Call) -> Value:
        if not isinstance(node.func, ast.Name):
            raise self.fail(node, "only a named function may be called")
        name = node.func.id
        if name in self.values:
            raise self.fail(node, f"{name!r} is a {shape_text(self.values[name])} value, not a function")
        function = self.functions.get(name)
        if function is None:
            raise self.fail(node, f"unknown function {name!r}")
        if node.keywords:
            raise self.fail(node, f"{name}() takes its arguments by position only")
        arguments = [self.evaluate(a) for a in node.args]
        if name in ALLOWED_FUNCTIONS:
            return self.call_scalar_function(node, name, function, arguments)
        try:
            return _as_scalar_if_1x1(function(*arguments))
        except ModelError as exc:
            raise self.fail(node, str(exc)) from None
        except TypeError as exc:
            raise self.fail(node, f"wrong arguments for {name}() ({exc})") from None

    def call_scalar_function(self, node: ast.Call, name: str, function: Callable, arguments: list[Value]) -> Value:
        """sin, cos, sqrt...: scalars only, with their own number of arguments."""
        bad = [shape_text(a) for a in arguments if is_matrix(a)]
        if bad:
            raise self.fail(node, f"{name}() needs scalar arguments, got {', '.join(shape_text(a) for a in arguments)}")
        try:
            return function(*arguments)
        except (TypeError, ValueError) as exc:
            raise self.fail(node, f"wrong arguments for {name}() ({exc})") from None


# -- component names -------------------------------------------------------------
def normalize_shape(shape: Any, where: str) -> tuple[int, int]:
    """A ``shape:`` field as (rows, columns): absent/1 -> scalar, 3 -> 3-vector, [3, 3] -> 3x3 matrix."""
    if shape is None or (shape == 1 and not isinstance(shape, bool)):
        return (1, 1)
    if isinstance(shape, int) and not isinstance(shape, bool) and shape == 3:
        return (3, 1)
    if isinstance(shape, list) and [type(s) for s in shape] == [int, int] and shape == [3, 3]:
        return (3, 3)
    raise ModelError(
        f"{where}: shape {shape!r} is not supported; use 3 (a 3-vector) or [3, 3] (a 3x3 matrix), "
        "or leave 'shape' out for a scalar"
    )


def axis_suffixes(frame: str, axes: str | None, where: str) -> tuple[str, str, str]:
    """The component suffixes of a 3-vector: its ``axes`` (body, NED, ENU), or else the model's ``frame``."""
    if axes is not None:
        key = {"body": "body", "ned": "NED", "enu": "ENU", "nav": frame.upper() if frame else ""}.get(str(axes).lower())
        if key not in AXIS_SUFFIXES:
            raise ModelError(
                f"{where}: axes {axes!r} is not supported; use body (_x, _y, _z), NED (_n, _e, _d), "
                "ENU (_e, _n, _u), or nav (the model's frame)"
            )
        return AXIS_SUFFIXES[key]
    key = (frame or "").strip().upper()
    if key not in ("NED", "ENU"):
        raise ModelError(
            f"{where}: a 3-vector needs 'axes' (body, NED or ENU) when the model's frame is "
            f"{frame!r} (the frame gives the axes only when it is NED or ENU)"
        )
    return AXIS_SUFFIXES[key]


def component_names(name: str, shape: Any, frame: str, axes: str | None = None, where: str = "") -> list[str]:
    """The names of a declaration's scalar components, in storage order.

    A 3-vector ``dv`` in NED -> ``dv_n, dv_e, dv_d``; in ENU -> ``dv_e, dv_n,
    dv_u``; with ``axes: body`` -> ``dv_x, dv_y, dv_z``.  A 3x3 matrix ``C``
    -> ``C_11, C_12, ..., C_33`` (row-major).  A scalar keeps its name.
    """
    place = where or f"{name!r}"
    rows, columns = shape if isinstance(shape, tuple) else normalize_shape(shape, place)
    if (rows, columns) == (1, 1):
        return [name]
    if (rows, columns) == (3, 1):
        return [f"{name}_{suffix}" for suffix in axis_suffixes(frame, axes, place)]
    return [f"{name}_{i}{j}" for i in range(1, rows + 1) for j in range(1, columns + 1)]


# -- definitions -----------------------------------------------------------------
def _names_in(text: str) -> set[str]:
    """The identifiers an expression text mentions (empty if it does not parse: the evaluation reports that)."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return set()
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


def _definition_cycle(order: Sequence[str], uses: Mapping[str, set[str]]) -> list[str] | None:
    """A cycle among definitions (``[a, b, a]``), or None if they form none."""
    state: dict[str, int] = {}  # 1 = on the current path, 2 = done

    def visit(name: str, path: list[str]) -> list[str] | None:
        state[name] = 1
        for used in sorted(uses.get(name, ())):
            if state.get(used) == 1:
                return path[path.index(used):] + [used]
            if used not in state:
                found = visit(used, path + [used])
                if found:
                    return found
        state[name] = 2
        return None

    for name in order:
        if name not in state:
            found = visit(name, [name])
            if found:
                return found
    return None


def evaluate_definitions(
    entries: Sequence[Mapping[str, Any]], namespace: Mapping[str, Value], locate: Callable[[str], str]
) -> dict[str, Value]:
    """Evaluate a ``definitions:`` list in order; each may use the declared names and earlier definitions.

    ``entries`` are mappings ``{name, value}`` (optionally ``unit`` and
    ``description``); ``namespace`` holds the declared names (states, noises,
    parameters, as scalars or Matrices); ``locate("definitions[2]")`` gives
    the place of an entry (``model.yaml:14``).  Refused, each naming the
    definitions and lines involved: an entry that is not ``{name, value}``, a
    name defined twice, a name that is already declared, a cycle between
    definitions, and a definition used before the line that defines it.
    Returns name -> value (scalar or Matrix), in the file's order.
    """
    if not isinstance(entries, (list, tuple)):
        raise ModelError(f"{locate('definitions')}: 'definitions' must be a list of entries {{name, value}}")
    first_line: dict[str, int] = {}
    texts: dict[str, str] = {}
    for i, entry in enumerate(entries):
        place = locate(f"definitions[{i}]")
        if not isinstance(entry, Mapping) or "name" not in entry or "value" not in entry:
            raise ModelError(f"{place}: definitions[{i}] must be a mapping with a 'name' and a 'value'")
        extra = sorted(set(entry) - {"name", "value", "unit", "description"})
        if extra:
            raise ModelError(f"{place}: definitions[{i}] has unknown field {extra[0]!r} (allowed: description, name, unit, value)")
        name = entry["name"]
        check_identifier(name, f"{place}: definition name")
        if name in namespace:
            raise ModelError(f"{place}: definition {name!r} has the name of a declared state, noise, parameter or component")
        if name in VECTOR_FUNCTIONS:
            raise ModelError(f"{place}: definition {name!r} has the name of a vector function")
        if name in first_line:
            raise ModelError(
                f"{place}: {name!r} is defined twice (at {locate(f'definitions[{first_line[name]}]')} and here)"
            )
        value = entry["value"]
        if isinstance(value, (list, dict)) or value is None or isinstance(value, bool):
            raise ModelError(f"{place}: definition {name!r} value must be one expression (text or number)")
        first_line[name] = i
        texts[name] = value if isinstance(value, str) else repr(value)
    uses = {name: _names_in(text) & set(first_line) for name, text in texts.items()}
    cycle = _definition_cycle(list(texts), uses)
    if cycle:
        place = locate(f"definitions[{first_line[cycle[0]]}]")
        raise ModelError(f"{place}: definitions form a cycle: {' -> '.join(cycle)}")
    for name, used in uses.items():
        later = sorted((first_line[u], u) for u in used if first_line[u] > first_line[name])
        if later:
            _, other = later[0]
            raise ModelError(
                f"{locate(f'definitions[{first_line[name]}]')}: definition {name!r} uses {other!r} before it is defined "
                f"(it is defined at {locate(f'definitions[{first_line[other]}]')}); definitions are evaluated in order"
            )
    defined: dict[str, Value] = {}
    for name, text in texts.items():
        i = first_line[name]
        where = f"{locate(f'definitions[{i}].value')}: definition {name!r}"
        defined[name] = parse_vector_expression(text, {**namespace, **defined}, where)
    return defined
