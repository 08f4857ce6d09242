"""The Python backend: one numpy module per model, the readable double-precision twin of the C.

``printer`` prints sympy expressions with the math module and parameters
as named locals, ``context`` builds one CSE'd function per model matrix
and the vectorized prediction plan, ``templates/`` holds the module template.
"""

from __future__ import annotations

from pathlib import Path

from modelgen.codegen.backends.base import Backend
from modelgen.codegen.backends.python.context import python_context
from modelgen.codegen.backends.python.run import python_run
from modelgen.codegen.description import FilterDescription
from modelgen.codegen.kernels import OperationCount, python_predict_cost

HERE = Path(__file__).resolve().parent

def python_costs(description: FilterDescription) -> dict[str, OperationCount]:
    """The Python's vectorized prediction (dense within each row class of Phi)."""
    return {"predict (Python)": python_predict_cost(description.structure)}


BACKEND = Backend(
    name="python",
    context=python_context,
    templates=HERE / "templates",
    runner=python_run,
    counter=python_costs,
    files=(("{p}.py", "python_module.py.j2"),),
)
