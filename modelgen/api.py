"""The Python API: modelgen's jobs as functions for notebooks and scripts.

``import modelgen`` gives these functions (lazily: importing the package
loads none of sympy, CasADi or numpy until one is called).  Each is a thin
wrapper over :mod:`modelgen.jobs` or the subpackage that does the work, so
the command line and the API always do the same thing::

    import modelgen

    model = modelgen.load_model("enu_doppler18")         # a built-in name or a YAML file
    derived = modelgen.derive(model)                      # F, G, H, Q, R (sympy)
    result = modelgen.verify(model, table="my_table.yaml")  # a paper's table, with hints
    code = modelgen.generate(model, out="generated")      # Python + C99 into generated/<model>/
    checks = modelgen.check(model)                        # compile and run against the reference
    report = modelgen.observability(model)                # rank, unobservable directions
    modelgen.covariance_analysis(out="report/covariance")  # the paper's Table 2 and Figs 2-7
    modelgen.simulate(hours=0.5, runs=0, out="report/sim")  # fly a profile

Every function takes a model as a built-in name, a model file's path, a
loaded :class:`~modelgen.model.declaration.ErrorModel` or a derived
:class:`~modelgen.derivation.symbolic.DerivedModel`, and raises
:class:`modelgen.errors.ModelError` for bad input.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Callable, Union

import modelgen.jobs as jobs
from modelgen.derivation.symbolic import DerivedModel
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel

#: What every function accepts as a model.
ModelLike = Union[str, Path, ErrorModel, DerivedModel]

__all__ = [
    "load_model",
    "derive",
    "verify",
    "generate",
    "check",
    "observability",
    "covariance_analysis",
    "simulate",
]


def load_model(model: str | Path) -> ErrorModel:
    """Load a model file (YAML) or a built-in model by name, validated (file:line in every error)."""
    return jobs.load_model(model)


def derive(model: ModelLike) -> DerivedModel:
    """The model's F, G, H, Q, R as sympy matrices (``.F``, ``.G``, ``.H``, ``.Q``, ``.R``; ``.numeric(values)`` for numbers)."""
    if isinstance(model, DerivedModel):
        return model
    if isinstance(model, ErrorModel):
        return jobs.derive(model)
    return jobs.load_and_derive(model)


def verify(model: ModelLike, table: str | Path | None = None, complete: bool | None = None):
    """Compare the derived F, G, H with a paper's table: a :class:`~modelgen.checks.paper_check.VerificationResult`.

    ``table`` is your own table file (README "Verifying your own paper");
    without it, the built-in paper table written for the model (a ModelError
    if there is none).  Only the entries a table lists are compared unless
    ``complete`` (the default for the built-in table).  ``result.unexplained``
    lists the differences no annotation explains, each with ``hints``;
    ``result.to_markdown()`` and ``result.to_json()`` are the reports.
    """
    derived = derive(model)
    if complete is None:
        complete = table is None
    return jobs.verify(derived, table, complete=complete)


def generate(model: ModelLike, out: str | Path = "generated", force: bool = False, check: bool = False, **options: Any):
    """Generate the Python and C99 filter into ``out/<model>/``: a :class:`~modelgen.jobs.GenerationResult`.

    ``options`` are those of ``modelgen generate`` (``scalar="float"``,
    ``form="ud"``, ``storage="packed"``, ``update="sequential"``,
    ``taylor_order=9``...; see :class:`modelgen.codegen.options.CodegenOptions`).
    With ``check`` the code is compiled and run against the reference first
    and replaces the folder only if it passes (``result.written``).
    """
    return jobs.generate(derive(model), Path(out), jobs.CodegenOptions(**options), force=force, with_check=check)


def check(model: ModelLike, folder: str | Path | None = None, **options: Any) -> list:
    """Compile and run the generated C and Python beside the numpy reference filter.

    Checks the code in ``folder`` (as written by :func:`generate` with the same
    ``options``), or, without it, code generated into a temporary folder.
    Returns one :class:`~modelgen.checks.code_check.ConformanceResult` per
    build (``.passed()``, ``.max_scaled_P``, ``.tolerance``), run at the model's
    check scenario.
    """
    derived = derive(model)
    codegen_options = jobs.CodegenOptions(**options)
    if folder is not None:
        return jobs.check(derived, Path(folder), options=codegen_options)
    with tempfile.TemporaryDirectory(prefix="modelgen-api-") as root:
        return list(jobs.generate(derived, Path(root), codegen_options, with_check=True).checks)


def observability(
    model: ModelLike,
    parameters: dict[str, float] | None = None,
    step: float | None = None,
    steps: int | None = None,
    scenario: str | Path | None = None,
    weak_rtol: float = 1e-3,
):
    """Rank and unobservable directions of the model: an :class:`~modelgen.analysis.observability.ObservabilityReport`.

    The operating point is the scenario file ``scenario``, else the paper's
    level flight where it covers the model, else the model's check scenario;
    ``parameters`` (name or symbol -> value) override it.  ``str(report)``
    is not the text report; use :func:`modelgen.analysis.observability.format_report`.
    """
    assignments = tuple(f"{name}={value!r}" for name, value in (parameters or {}).items())
    return jobs.observability_analysis(derive(model), None if scenario is None else str(scenario), assignments, step, steps, weak_rtol)[1]


def covariance_analysis(
    out: str | Path = "report/covariance",
    sensitivity: bool = True,
    figures: bool = True,
    progress: Callable[[str], None] | None = None,
):
    """The core paper's covariance analysis (Table 2, Figs 2-7) written into ``out``; returns the report object."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    return jobs.covariance_analysis(folder, sensitivity, figures, progress)


def simulate(
    profile: str | Path = "profile_000",
    out: str | Path = "report/simulation",
    runs: int = 0,
    seed: int = 0,
    hours: float | None = None,
    imu_rate: float | None = None,
    implementation: str = "c",
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Fly a flight profile (trajectory, IMU, aiding sensor, strapdown, filter) and write summary.md into ``out``.

    ``implementation`` is the filter of the correction-mode runs: ``"c"``
    (the generated C, compiled now), ``"python"`` or ``"reference"``;
    ``runs`` Monte Carlo runs are flown too.  Returns the summary's path.
    """
    if runs < 0:
        raise ModelError(f"runs must be 0 or more, got {runs}")
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    scenario = jobs.flight_scenario(str(profile), hours=hours, imu_rate=imu_rate)
    return jobs.simulate_flight(scenario, folder, runs, seed, implementation, echo=progress or (lambda message: None))
