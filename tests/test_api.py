"""The Python API (modelgen.api, offered by ``import modelgen``): cheap to import, documented, the same jobs as the CLI."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import modelgen
import modelgen.api as api
import modelgen.jobs as jobs
from modelgen.derivation.symbolic import DerivedModel

from conftest import REPO

TINY = """model: tilt
title: Single-axis tilt loop
parameters:
  - {name: gravity, symbol: g, unit: m/s^2, value: 9.8}
  - {name: earth_radius, symbol: R, unit: m, value: 6371000.0}
  - {name: velocity_sigma, symbol: s_v, unit: m/s, value: 0.1}
states:
  - {name: tilt_error, symbol: phi, unit: rad}
  - {name: velocity_error, symbol: dv, unit: m/s}
dynamics:
  phi: -dv/R
  dv: g*phi
measurements:
  - {name: velocity_difference, symbol: z, unit: m/s, expression: dv, variance: "s_v**2"}
"""


def docs_page(name: str) -> str:
    """A page of the documentation site (docs/NAME)."""
    return (REPO / "docs" / name).read_text(encoding="utf-8")


def test_the_api_is_exactly_the_documented_eight_functions_with_docstrings():
    functions = ["load_model", "derive", "verify", "generate", "check", "observability", "covariance_analysis", "simulate"]
    assert api.__all__ == functions
    assert set(functions) <= set(modelgen.__all__) and set(functions) <= set(dir(modelgen))
    for name in functions:
        assert callable(getattr(modelgen, name)), name
        assert len((getattr(api, name).__doc__ or "").split()) >= 10, name
        assert f"`{name}(" in docs_page("python-api.md"), f"docs/python-api.md's table lists {name}"


def test_importing_modelgen_loads_no_heavy_library():
    code = "import sys, modelgen; print(sorted(m for m in ('sympy', 'numpy', 'casadi', 'jinja2', 'matplotlib') if m in sys.modules))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"


def test_derive_is_both_the_subpackage_and_the_function():
    import modelgen.derivation.symbolic as symbolic

    assert modelgen.derivation.symbolic is symbolic
    derived = modelgen.derive("ned_doppler18")
    assert isinstance(derived, DerivedModel) and derived.n_states == 18
    assert modelgen.derive(derived) is derived


def test_python_dash_m_modelgen_runs_the_command_line():
    run = subprocess.run([sys.executable, "-m", "modelgen", "--version"], capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout.startswith("modelgen, version ")


def test_the_documented_notebook_runs(tmp_path, monkeypatch):
    """docs/python-api.md's block, with the verify table of docs/verifying-a-paper.md saved as my_table.yaml, runs and
    finds the table's mistakes."""
    table = re.search(r"```yaml\n(model: enu_doppler18.*?)```", docs_page("verifying-a-paper.md"), re.S).group(1)
    code = re.search(r"```python\n(.*?)```", docs_page("python-api.md"), re.S).group(1)
    (tmp_path / "my_table.yaml").write_text(table, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(ast.parse(code), "docs/python-api.md", "exec"), namespace)
    assert [e.label for e in namespace["result"].unexplained] == ["F(2,4)", "F(5,1)", "F(6,5)"]
    assert Path("generated", "enu_doppler18", "enu_doppler18.c") in namespace["generated"].files
    assert (tmp_path / "generated" / "enu_doppler18" / "enu_doppler18.c").is_file()
    assert namespace["report"].rank <= 18


@pytest.mark.compile
def test_check_compiles_and_runs_a_model_against_the_reference(tmp_path):
    path = tmp_path / "tilt.yaml"
    path.write_text(TINY, encoding="utf-8")
    results = modelgen.check(path)
    assert {"python", "c"} <= {r.implementation for r in results}  # and "cpp" where a C++ compiler is there
    assert all(r.passed() for r in results)


def test_verify_without_a_table_is_the_papers_check():
    result = modelgen.verify("ned_doppler18")
    assert result.table == "paper_000_table.yaml" and not result.unexplained


@pytest.mark.parametrize(
    ("call", "job", "expected"),
    [
        (lambda out: modelgen.covariance_analysis(out=out, sensitivity=False, figures=False), "covariance_analysis", lambda out: ((Path(out), False, False, None), {})),
        (
            lambda out: modelgen.simulate("profile_001", out=out, runs=3, seed=7, implementation="reference"),
            "simulate_flight",
            None,
        ),
    ],
    ids=["covariance_analysis", "simulate"],
)
def test_the_long_jobs_get_their_arguments_through(call, job, expected, tmp_path, monkeypatch):
    """covariance_analysis and simulate (minutes of work, tested by their commands) pass their arguments to the jobs."""
    seen = {}
    monkeypatch.setattr(jobs, job, lambda *args, **kwargs: seen.update(args=args, kwargs=kwargs) or "done")
    out = tmp_path / "out"
    assert call(out) == "done" and out.is_dir()
    if expected is not None:
        assert (seen["args"], seen["kwargs"]) == expected(out)
    else:
        scenario, folder, runs, seed, implementation = seen["args"]
        assert (folder, runs, seed, implementation) == (out, 3, 7, "reference")
        assert scenario == jobs.flight_scenario("profile_001")


def test_results_have_short_reprs_and_notebook_markdown(tmp_path):
    """A notebook shows a line or a short table for each result, not 26,545 characters of matrices."""
    model = modelgen.load_model("enu_doppler18")
    derived = modelgen.derive(model)
    assert repr(model) == (f"<ErrorModel 'enu_doppler18': 18 states, 9 noises, {len(model.parameters)} parameters, "
                           "3 measurements>")
    assert repr(derived).startswith("<DerivedModel 'enu_doppler18': 18 states, ") and len(repr(derived)) < 200
    assert f"`{derived!r}`" in docs_page("python-api.md")  # the page shows the repr as it is
    markdown = derived._repr_markdown_()
    assert "| F | 18 x 18 |" in markdown and f"| F | 18 x 18 | {derived.nonzeros('F')} |" in markdown
    assert derived.nonzeros("F") == sum(1 for entry in derived.F if entry != 0) > 0

    result = modelgen.verify(derived, table=REPO / "tests" / "checks" / "data" / "enu_doppler18_user_table.yaml")
    assert repr(result) == ("<VerificationResult 'enu_doppler18' against enu_doppler18_user_table.yaml: 9 entries, "
                            "5 match, 4 differ, 0 paper_only, 0 derived_only; 3 unexplained>")
    shown = result._repr_markdown_()
    assert "## Differences" in shown and "## Every entry" not in shown and len(shown) < len(result.to_markdown())

    generated = modelgen.generate(derived, out=tmp_path)
    names = sorted(generated.code.files)
    assert generated.files == tuple(tmp_path / "enu_doppler18" / name for name in names)
    assert all(path.is_file() for path in generated.files) and generated.written
    assert repr(generated) == f"<GenerationResult 'enu_doppler18': {len(names)} files in {tmp_path / 'enu_doppler18'}>"
    assert all(f"| `{name}` |" in generated._repr_markdown_() for name in names)


def test_a_generation_kept_back_by_a_failing_check_lists_no_files(tmp_path, monkeypatch):
    from modelgen.checks.code_check import ConformanceResult

    failing = ConformanceResult("c", 1, 1.0, 1.0, 1.0, True, True, tolerance=1e-12)
    monkeypatch.setattr(jobs, "check", lambda *args, **kwargs: [failing])
    result = jobs.generate(jobs.load_and_derive("ned_doppler13_reduced"), tmp_path, with_check=True)
    assert result.files == () and not result.written and not (tmp_path / "ned_doppler13_reduced").exists()
    assert "nothing written" in repr(result) and "c FAILED" in repr(result)
