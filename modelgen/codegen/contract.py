"""The contract of the generated filter: what each function refuses, in C and in Python alike.

One table, rendered into the generated Python module's docstring and the
generated README.md, and tested by tests/codegen/test_contract.py, which
feeds the same bad inputs to the Python and to every C option family.  C
returns a status and leaves the filter exactly as it was; Python raises
ValueError naming the function and the argument and returns nothing.
tol = 16 N eps (N states, eps of the C scalar type; double in Python).
"""

from __future__ import annotations

import textwrap

#: (C function / Python function, what is refused, C status)
CONTRACT: tuple[tuple[str, str, str], ...] = (
    ("matrices_evaluate / system_matrix ...", "a non-finite parameter or matrix entry; a singular operating point (the cos of a tan or sec, or another trigonometric denominator, zero within 4 eps max(1, abs(argument)): latitude +-90 deg)", "ERR_NONFINITE"),
    ("discretize", "T NaN or infinite (Python: or not a real number: a bool, a string, a complex); F, G or q non-finite; e^(F T) not representable (more than 64 doublings, or overflow)", "ERR_NONFINITE"),
    ("discretize", "T <= 0; a negative noise PSD q", "ERR_NOT_POSITIVE"),
    ("discretize (Taylor's Q_d)", "a T so short that q / T, the weights of the paper's Gamma (Q/T) Gamma^T, overflows: max(q) / T not finite (Van Loan's Q_d has no such weights)", "ERR_NONFINITE"),
    ("set_covariance / predict, update (P argument)", "a NaN or infinite entry of P", "ERR_NONFINITE"),
    ("set_covariance / predict, update (P argument)", "P_ii < 0; abs(P_ij - P_ji) > tol sqrt(P_ii P_jj); abs(P_ij) > sqrt(P_ii P_jj) (1 + tol), so a zero variance carries no correlation; P not positive semidefinite within tol", "ERR_NOT_POSITIVE"),
    ("set_state (C only)", "a NaN or infinite entry of x", "ERR_NONFINITE"),
    ("set_transition_matrix (C only)", "a NaN or infinite entry of Phi, anywhere (tested first)", "ERR_NONFINITE"),
    ("set_transition_matrix (C only)", "a nonzero entry outside the structural pattern of Phi (Phi_row, Phi_col); a row of a random constant that is not exactly e_i", "ERR_STRUCTURE"),
    ("predict", "non-finite x, Phi or Q_d, or a non-finite result", "ERR_NONFINITE"),
    ("predict", "a negative variance Q_d(i, i), as a P with one (UD form: a negative weight qw of Q_d = Gamma diag(qw) Gamma^T)", "ERR_NOT_POSITIVE"),
    ("update", "non-finite x, z, H or r, or a non-finite result, the normalized innovation squared nu^T S^-1 nu included (a z so far from H x that it overflows, e.g. z = 1e308)", "ERR_NONFINITE"),
    ("update", "r < 0 (UD form: r <= 0); an innovation variance that is not positive", "ERR_NOT_POSITIVE"),
    ("update_masked", "as update, over the used measurements only: an unused one's z, H row and r are not read (NaN allowed)", "as update"),
)


def contract_text(indent: str = "") -> list[str]:
    """The table as plain-text lines (for a docstring or a comment)."""
    lines = []
    for function, refused, status in CONTRACT:
        text = f"{function}: {refused} -> C {status}, Python ValueError"
        lines += textwrap.wrap(text, width=88, initial_indent=indent + "- ", subsequent_indent=indent + "  ")
    return lines


def contract_markdown() -> list[str]:
    """The table as Markdown rows, header first (no cell holds a ``|``)."""
    rows = ["| function (C / Python) | refused | C status |", "| --- | --- | --- |"]
    rows += [f"| {function} | {refused} | `{status}` |" for function, refused, status in CONTRACT]
    return rows
