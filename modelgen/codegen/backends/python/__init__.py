"""The Python backend: one numpy module per model, the readable double-precision twin of the C.

``printer`` prints sympy expressions with the math module and parameters
as named locals, ``context`` builds one CSE'd function per model matrix
and the vectorized prediction plan, ``templates/`` holds the module template.
"""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Backend
from modelgen.codegen.backends.python.context import python_context

HERE = Path(__file__).resolve().parent

BACKEND = Backend(
    name="python",
    context=python_context,
    templates=HERE / "templates",
    files=(("{p}.py", "python_module.py.j2"),),
)
