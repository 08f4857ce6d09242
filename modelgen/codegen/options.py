"""What the generated C may be asked to be: the code-generation options.

The options only change the C, except ``process_noise`` (and the Taylor
order and tolerance), which the generated Python module follows too; it is
always the double-precision numpy filter (the readable twin of the default C).

* ``scalar`` -- ``double`` or ``float`` (every array, constant and math call).
* ``form`` -- ``covariance`` (P is stored) or ``ud`` (P = U D U^T is stored:
  U unit upper triangular, D diagonal; Thornton's modified weighted
  Gram-Schmidt time update and Bierman's scalar measurement update keep D >= 0
  by construction, which is what makes single precision safe).
* ``storage`` -- ``full`` N x N array or ``packed`` upper triangle
  (N (N + 1) / 2 entries, row by row) for P, Q_d and the workspace copies.
* ``update`` -- ``vector``: all measurements at once with a small Cholesky
  solve of the innovation covariance; ``sequential``: one scalar measurement
  after another, no matrix inverse and no square root (valid because R is
  diagonal, which every model's measurement_variance makes it).
* ``covariance_update`` -- ``joseph`` (I-KH) P (I-KH)^T + K R K^T, first-order
  insensitive to errors in K, or ``standard`` P - K H P (cheaper).

* ``taylor_order`` -- the highest order of the Taylor series of discretize
  (the paper's 9 by default), and ``taylor_tolerance`` -- the relative
  accuracy of Phi against e^{F T} that discretize guarantees (default 1e-12):
  at run time it sums only the orders and doublings that bound needs
  (modelgen.derivation.discretization.taylor_plan); None sums every order up to
  ``taylor_order`` and doubles until the remainder is below the unit
  roundoff (the paper's fixed order).

* ``recompute_threshold`` -- None (default) or a relative change: discretize
  keeps the transition it computed last, and returns at once, while T is the
  same and no entry of F, G or q has moved by more than this fraction of its
  value then (the operating point has not changed); the transition struct
  holds the inputs it was computed from and must be zeroed before first use.

* ``process_noise`` -- ``taylor`` (default): Q_d = Gamma (Q/T) Gamma^T of the
  paper's eq. (9), Gamma from the Taylor series; ``van-loan``: Phi and the
  exact Q_d = int_0^T e^{F s} G Q G^T e^{F^T s} ds by Van Loan's block
  exponential (Van Loan 1978; modelgen.codegen.van_loan), in the C by a
  block Taylor series with scaling and squaring under the same accuracy
  rule, in the Python module by scipy.linalg.expm.  Covariance form only:
  the UD form's Thornton update takes Gamma and q, not Q_d (refused).

``storage``, ``update`` and ``covariance_update`` describe the covariance
form; the UD form always stores U packed and updates by Bierman, so they do
not apply to it (``describe`` says what the code really does).
"""

from __future__ import annotations

from dataclasses import dataclass

from modelgen.derivation.discretization import DEFAULT_TAYLOR_ORDER, DEFAULT_TOLERANCE
from modelgen.errors import ModelError

SCALARS = ("double", "float")
FORMS = ("covariance", "ud")
STORAGES = ("full", "packed")
UPDATES = ("vector", "sequential")
COVARIANCE_UPDATES = ("joseph", "standard")
PROCESS_NOISES = ("taylor", "van-loan")


@dataclass(frozen=True)
class CodegenOptions:
    """Choices that shape the generated code (see the module docstring)."""

    taylor_order: int = DEFAULT_TAYLOR_ORDER
    scalar: str = "double"
    form: str = "covariance"
    storage: str = "full"
    update: str = "vector"
    covariance_update: str = "joseph"
    taylor_tolerance: float | None = DEFAULT_TOLERANCE
    recompute_threshold: float | None = None
    process_noise: str = "taylor"

    def __post_init__(self) -> None:
        for field, allowed in (
            ("scalar", SCALARS),
            ("form", FORMS),
            ("storage", STORAGES),
            ("update", UPDATES),
            ("covariance_update", COVARIANCE_UPDATES),
            ("process_noise", PROCESS_NOISES),
        ):
            value = getattr(self, field)
            if value not in allowed:
                label = "scalar type" if field == "scalar" else field.replace("_", " ")
                raise ModelError(f"{label} must be one of {', '.join(map(repr, allowed))}, not {value!r}")
        if not isinstance(self.taylor_order, int) or not 1 <= self.taylor_order <= 30:
            raise ModelError(f"Taylor order must be between 1 and 30, not {self.taylor_order}")
        tolerance = self.taylor_tolerance
        if tolerance is not None and (isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0.0 < tolerance < 1.0):
            raise ModelError(f"Taylor tolerance must be a number between 0 and 1 (exclusive) or None, not {tolerance!r}")
        threshold = self.recompute_threshold
        if threshold is not None and (isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not 0.0 <= threshold < 1.0):
            raise ModelError(f"recompute threshold must be a number in [0, 1) or None, not {threshold!r}")
        if self.van_loan and self.ud:
            raise ModelError(
                "process noise 'van-loan' needs form 'covariance', not form 'ud': the UD time update "
                "(Thornton) takes Gamma and q, not the Q_d that Van Loan's method gives"
            )

    @property
    def van_loan(self) -> bool:
        """True when discretize computes Phi and the exact Q_d by Van Loan's block exponential."""
        return self.process_noise == "van-loan"

    @property
    def ud(self) -> bool:
        return self.form == "ud"

    @property
    def packed(self) -> bool:
        """True when P (or U) is stored as a packed triangle."""
        return self.ud or self.storage == "packed"

    @property
    def sequential(self) -> bool:
        return self.ud or self.update == "sequential"

    def describe(self) -> str:
        """One line saying what the generated filter does, for file headers and reports."""
        if self.ud:
            return (
                f"{self.scalar}, UD factorized (P = U D U^T, U packed): Thornton MWGS time update, "
                "Bierman sequential scalar measurement update"
            )
        update = (
            "vector measurement update (Cholesky solve)" if self.update == "vector" else "sequential scalar measurement updates"
        )
        form = "Joseph-form" if self.covariance_update == "joseph" else "standard-form"
        noise = ", Van Loan's exact Q_d" if self.van_loan else ""
        return f"{self.scalar}, covariance form, {self.storage} storage, {update}, {form} covariance update{noise}"

    def slug(self) -> str:
        """Short identifier of the combination (file and test names)."""
        if self.ud:
            return f"{self.scalar}-ud"
        noise = "-van-loan" if self.van_loan else ""
        return f"{self.scalar}-{self.storage}-{self.update}-{self.covariance_update}{noise}"


def all_combinations(scalar: str = "double") -> list[CodegenOptions]:
    """Every supported combination for one scalar type (8 covariance forms + UD)."""
    out = [
        CodegenOptions(scalar=scalar, storage=s, update=u, covariance_update=c)
        for s in STORAGES
        for u in UPDATES
        for c in COVARIANCE_UPDATES
    ]
    out.append(CodegenOptions(scalar=scalar, form="ud"))
    return out
