"""modelgen.export.formats: text, JSON, LaTeX and Octave exports carry exactly the derived F, G, H, Q, R."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

from modelgen.cli import main
from modelgen.derivation.symbolic import derive, parameter_vector
from modelgen.errors import ModelError
from modelgen.export.formats import matrix_entries, octave_function_name, octave_locals, to_json, to_latex, to_octave, to_text
from modelgen.model.declaration import ErrorModel, Measurement, Noise, Parameter, State

MATRICES = ("F", "G", "H", "Q", "R")
HOSTILE = "Tilt \\input{/etc/passwd} $x$ & 100% #1 ^_~ {group} %{ */ end"
HOSTILE_LINES = "first line\n%{\nblock comment?\n%}"


def numeric_from_entries(shapes, entries, values):
    """Matrices rebuilt from (matrix, row, column, sympy expression) at parameter values (by symbol)."""
    out = {m: np.zeros(shape) for m, shape in shapes.items()}
    for m, i, j, expr in entries:
        out[m][i - 1, j - 1] = float(sp.sympify(expr).xreplace(values).evalf(20))
    return out


def symbol_values(derived, values):
    """Each parameter symbol -> its value (defaults filled in), as sympy Floats."""
    numbers = parameter_vector(derived.model, values)
    return {p.sym: sp.Float(v, 20) for p, v in zip(derived.model.parameters, numbers)}


@pytest.fixture(scope="module")
def hostile_model():
    return derive(
        ErrorModel.build(
            name="tilt",
            title=HOSTILE,
            states=[State(name="tilt_error", symbol="phi", unit="rad"), State(name="velocity_error", symbol="dv", unit="m/s")],
            noises=[Noise(name="accel_noise", symbol="w_a", unit="m/s^2/sqrt(s)", psd="q_a")],
            parameters=[
                Parameter(name="gravity", symbol="g", unit="m/s^2", value=9.8, description=HOSTILE_LINES),
                Parameter(name="earth_radius", symbol="R", unit="m"),
                Parameter(name="accel_psd", symbol="q_a", unit="m^2/s^3"),
                Parameter(name="velocity_sigma", symbol="end", unit="m/s"),
            ],
            dynamics={"phi": "-dv/R", "dv": "g*phi + w_a"},
            measurements=[Measurement(name="velocity_difference", symbol="z", unit="m/s", expression="dv", variance="end**2")],
        )
    )


def test_text_lists_q_and_r_beside_f_g_h(enu_derived):
    text = to_text(enu_derived)
    assert text.splitlines()[0] == "model enu_doppler18: 18 states, 9 noises, 3 measurements"
    assert "Q(4,4) [gyro_markov_noise_x, gyro_markov_noise_x] = 2*mu_eps_x*sigma_eps_x**2" in text
    assert "R(3,3) [velocity_difference_up, velocity_difference_up] = sigma_eta_U**2" in text
    assert "F(1,9) [attitude_error_east, height_error] = v_N/(R_M + h)**2" in text
    assert len(text.splitlines()) == 1 + len(matrix_entries(enu_derived))


def test_json_entries_read_back_as_the_derived_matrices(enu_derived, enu_values):
    data = json.loads(to_json(enu_derived))
    symbols = {p["symbol"]: sp.Symbol(p["symbol"], real=True) for p in data["parameters"]}
    entries = [
        (m, e["row"], e["column"], sp.sympify(e["expression"], locals=symbols))
        for m in MATRICES
        for e in data["matrices"][m]["entries"]
    ]
    shapes = {m: tuple(data["matrices"][m]["shape"]) for m in MATRICES}
    rebuilt = numeric_from_entries(shapes, entries, symbol_values(enu_derived, enu_values))
    reference = enu_derived.numeric(enu_values)
    for m in MATRICES:
        np.testing.assert_allclose(rebuilt[m], reference[m], rtol=1e-13, atol=0, err_msg=m)
    assert data["matrices"]["G"]["rows"] == "states" and data["matrices"]["G"]["columns"] == "noises"
    assert [s["name"] for s in data["states"]] == enu_derived.model.state_names


def test_latex_is_one_table_row_per_entry_with_the_models_symbols(enu_derived):
    latex = to_latex(enu_derived)
    rows = [line for line in latex.splitlines() if re.match(r"^\$[FGHQR]\(\d+,\d+\)\$ & ", line)]
    assert len(rows) == len(matrix_entries(enu_derived))
    assert latex.count("\\begin{longtable}") == latex.count("\\end{longtable}") == 1
    assert ("$F(1,2)$ & attitude\\_\\allowbreak{}error\\_\\allowbreak{}east /\\newline "
            "attitude\\_\\allowbreak{}error\\_\\allowbreak{}north & $\\omega_{ie} \\sin{\\left(L \\right)}") in latex
    assert "\\left(R_{M} + h\\right)^{2}" in latex  # R_M + h kept together
    body = latex.split("\\begin{longtable}")[1]
    assert body.count("{") == body.count("}")


def test_latex_columns_add_up_to_less_than_the_text_width(enu_derived):
    """The quantity and value columns are fractions of \\linewidth; with the widest entry label and the gaps they fit."""
    from modelgen.export.formats import LATEX_QUANTITY_WIDTH, LATEX_VALUE_WIDTH

    spec = next(line for line in to_latex(enu_derived).splitlines() if line.startswith("\\begin{longtable}"))
    assert f"p{{{LATEX_QUANTITY_WIDTH}\\linewidth}}" in spec and f"p{{{LATEX_VALUE_WIDTH}\\linewidth}}" in spec
    # A4 article text width 345 pt: the entry column ("$R(12,12)$", 50 pt) and two gaps of 2 x 6 pt leave 271 pt
    assert (LATEX_QUANTITY_WIDTH + LATEX_VALUE_WIDTH) * 345 <= 345 - 50 - 24


@pytest.fixture(scope="module")
def builtin_latex_folder(tmp_path_factory, derived_builtin):
    """Every built-in model's LaTeX table, written once for both paper sizes: (folder, \\input lines).

    The models are the session's (tests/conftest.py: load_and_derive, once per worker).
    """
    from modelgen.model.loading import builtin_models

    folder = tmp_path_factory.mktemp("latex")
    inputs = []
    for name in builtin_models():
        (folder / f"{name}.tex").write_text(to_latex(derived_builtin(name)), encoding="utf-8")
        inputs.append(f"\\input{{{name}.tex}}\\clearpage")
    return folder, inputs


@pytest.mark.compile
@pytest.mark.parametrize("paper", ["a4paper", "letterpaper"])
def test_latex_export_of_every_builtin_model_fits_the_page(builtin_latex_folder, paper):
    """pdflatex sets every built-in model's table without an overfull line (it used to be 153 pt too wide)."""
    import shutil
    import subprocess

    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex is not installed (Debian: texlive-latex-base texlive-latex-recommended)")
    folder, inputs = builtin_latex_folder
    (folder / f"{paper}.tex").write_text(f"\\documentclass[{paper}]{{article}}\n\\usepackage{{longtable,array,amsmath}}\n"
                                         "\\begin{document}\n" + "\n".join(inputs) + "\n\\end{document}\n", encoding="utf-8")
    run = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", f"{paper}.tex"], cwd=folder,
                         capture_output=True, text=True, timeout=300)
    log = (folder / f"{paper}.log").read_text(encoding="utf-8", errors="replace")
    assert run.returncode == 0, log[-2000:]
    assert [line for line in log.splitlines() if line.startswith("Overfull \\hbox")] == []


def test_hostile_free_text_stays_inert_text_in_latex_and_octave(hostile_model):
    latex = to_latex(hostile_model)
    caption = next(line for line in latex.splitlines() if line.startswith("\\caption"))
    assert "\\input" not in caption and "\\textbackslash{}input\\{/etc/passwd\\}" in caption
    assert "\\$x\\$ \\& 100\\% \\#1" in caption
    octave = to_octave(hostile_model)
    for line in octave.splitlines():
        assert line.strip() not in ("%{", "%}", "#{", "#}")
    assert all(line.startswith(("function", "%", "  ", "end")) or line == "" for line in octave.splitlines())


def test_octave_locals_never_shadow_the_outputs_or_keywords(hostile_model):
    names = {s.name: v.name for s, v in octave_locals(hostile_model.model).items()}
    assert names["R"] == "R_" and names["end"] == "end_" and names["g"] == "g"


def octave_assignments(text):
    """(matrix, row, column, sympy expression) read back from the Octave file's assignment lines."""
    out = []
    for m, i, j, expr in re.findall(r"^  ([FGHQR])\((\d+), (\d+)\) = (.*);$", text, re.M):
        python = expr.replace(".^", "**").replace(".*", "*").replace("./", "/")
        out.append((m, int(i), int(j), python))
    return out


def test_octave_function_assigns_every_entry_and_reads_every_parameter(enu_derived, enu_values):
    text = to_octave(enu_derived)
    assert text.startswith("function [F, G, H, Q, R] = enu_doppler18_matrices(p)\n")
    assert text.rstrip().endswith("end")
    local = octave_locals(enu_derived.model)
    for p in enu_derived.model.parameters:
        assert f"{local[p.sym].name} = p.{p.name}" in text
    for m in MATRICES:
        rows, columns = getattr(enu_derived, m).shape
        assert f"  {m} = zeros({rows}, {columns});" in text
    assigned = octave_assignments(text)
    assert len(assigned) == len(matrix_entries(enu_derived))
    namespace = {v.name: v for v in local.values()}
    entries = [(m, i, j, sp.sympify(e, locals=namespace)) for m, i, j, e in assigned]
    values = {local[s]: v for s, v in symbol_values(enu_derived, enu_values).items()}
    shapes = {m: getattr(enu_derived, m).shape for m in MATRICES}
    rebuilt = numeric_from_entries(shapes, entries, values)
    reference = enu_derived.numeric(enu_values)
    for m in MATRICES:
        np.testing.assert_allclose(rebuilt[m], reference[m], rtol=1e-13, atol=0, err_msg=m)


def test_an_octave_function_name_that_is_no_identifier_is_refused(enu_derived):
    assert octave_function_name(enu_derived.model, "my_model") == "my_model"
    for bad in ("my-model", "1model", "end", "zeros", "x" * 64):
        with pytest.raises(ModelError, match="not a usable Octave function name"):
            octave_function_name(enu_derived.model, bad)


@pytest.mark.skipif(shutil.which("octave-cli") is None, reason="octave-cli is not installed: the function file is checked structurally above")
def test_octave_runs_the_function_file_and_agrees_with_sympy(enu_derived, enu_values, tmp_path):
    (tmp_path / "enu_matrices.m").write_text(to_octave(enu_derived, "enu_matrices"), encoding="utf-8")
    fields = "; ".join(f"p.{k} = {v!r}" for k, v in enu_values.items())
    script = f"{fields}; [F, G, H, Q, R] = enu_matrices(p); printf('%.17g\\n', F'(:));"
    run = subprocess.run(["octave-cli", "--eval", script], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    F = np.array([float(v) for v in run.stdout.split()]).reshape(enu_derived.F.shape)
    np.testing.assert_allclose(F, enu_derived.numeric(enu_values)["F"], rtol=1e-13)


def test_cli_derive_writes_each_format_to_a_file(tmp_path):
    runner = CliRunner()
    for fmt, name in (("json", "m.json"), ("latex", "m.tex"), ("octave", "ned_matrices.m"), ("text", "m.txt")):
        run = runner.invoke(main, ["derive", "ned_doppler18", "--format", fmt, "--out", str(tmp_path / name)])
        assert run.exit_code == 0, run.output
        assert (tmp_path / name).stat().st_size > 1000
    assert (tmp_path / "ned_matrices.m").read_text(encoding="utf-8").startswith("function [F, G, H, Q, R] = ned_matrices(p)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "m.tex", "m.txt", "ned_matrices.m"]  # no temporary files left


def test_cli_derive_refuses_casadi_without_out_and_a_bad_octave_file_name(tmp_path):
    runner = CliRunner()
    run = runner.invoke(main, ["derive", "--format", "casadi"])
    assert run.exit_code == 2 and "give --out FILE" in run.output
    run = runner.invoke(main, ["derive", "--format", "octave", "--out", str(tmp_path / "my-model.m")])
    assert run.exit_code == 2 and "'my-model' is not a usable Octave function name" in run.output
    assert not (tmp_path / "my-model.m").exists()
