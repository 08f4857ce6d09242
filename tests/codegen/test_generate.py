"""Generated code compiles strictly, is deterministic, self-describing and cheap."""

import os
import re
import subprocess
import sys

import pytest

from modelgen.codegen.build import STRICT_FLAGS, compiler, load_python_module
from modelgen.codegen.generate import CodegenOptions, generate_code, write_atomically
from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Noise, Parameter, State


@pytest.fixture(scope="module")
def paper_code(paper_derived):
    return generate_code(paper_derived)


@pytest.mark.compile
@pytest.mark.parametrize("scalar", ["double", "float"])
def test_generated_c_compiles_as_strict_c99(paper_derived, tmp_path, scalar):
    code = generate_code(paper_derived, CodegenOptions(scalar=scalar))
    write_atomically(tmp_path / "out", code.files)
    result = subprocess.run(
        [compiler(), *STRICT_FLAGS, "-O2", "-c", str(tmp_path / "out" / "ned_doppler18.c"), "-o", str(tmp_path / "x.o")],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr


def test_generated_c_calls_no_allocator(paper_code):
    source = paper_code.files["ned_doppler18.c"] + paper_code.files["ned_doppler18.h"]
    calls = set(re.findall(r"\b([A-Za-z_][A-Za-z0-9_]*)\s*\(", source))
    assert "sqrt" in calls or "fabs" in calls  # the scan sees the calls the C makes
    for forbidden in ("malloc", "calloc", "realloc", "free", "alloca", "__builtin_alloca", "printf", "fprintf"):
        assert forbidden not in calls, forbidden


def test_every_file_says_it_is_generated_from_which_model_and_template(paper_code):
    assert set(paper_code.files) == {
        "ned_doppler18.py", "ned_doppler18.h", "ned_doppler18.c", "CMakeLists.txt", "Makefile", "README.md", "ned_doppler18.hpp",
        "modelgen_factor.h", "modelgen_ieee.h", "modelgen_lane_pair.h", "modelgen_scalar.h", "modelgen_taylor.h",
    }
    for name, text in paper_code.files.items():
        head = text[:1500]
        if name.startswith("modelgen_"):  # the fixed C runtime, the same for every model: copied, and says from where
            assert head.startswith("/* modelgen C runtime") and "modelgen/codegen/backends/c/runtime" in text[:3000], name
            continue
        assert "GENERATED FILE - DO NOT EDIT" in head, name
        assert "model 'ned_doppler18'" in head, name
        assert ".j2" in head, name
        if name.endswith((".c", ".h", ".py")):
            assert "predict (C):" in head and "flops" in head, name
    assert "predict (C):" in paper_code.files["README.md"]


def test_structured_prediction_costs_at_most_a_third_of_dense(paper_code):
    c, dense = paper_code.costs["predict (C)"], paper_code.costs["predict (dense, for comparison)"]
    assert c.total * 3 < dense.total


def test_generation_is_byte_identical_across_processes_and_hash_seeds(tmp_path):
    script = (
        "import sys; from modelgen.jobs import generate; from pathlib import Path; "
        "generate('ned_doppler18', Path(sys.argv[1]))"
    )
    outputs = []
    for seed in ("1", "12345"):
        out = tmp_path / f"run{seed}"
        env = {**os.environ, "PYTHONHASHSEED": seed}
        subprocess.run([sys.executable, "-c", script, str(out)], check=True, env=env)
        outputs.append({p.name: p.read_bytes() for p in sorted((out / "ned_doppler18").iterdir())})
    assert outputs[0] == outputs[1]


def test_generated_python_matrices_equal_derived_ones(paper_code, paper_derived, level_flight, tmp_path):
    import numpy as np

    write_atomically(tmp_path / "py", paper_code.files)
    gen = load_python_module(tmp_path / "py" / "ned_doppler18.py")
    p = gen.parameter_vector(level_flight)
    ref = paper_derived.numeric(level_flight)
    assert np.allclose(gen.system_matrix(p), ref["F"], rtol=1e-14, atol=0)
    assert np.array_equal(gen.noise_input_matrix(p), ref["G"])
    assert np.array_equal(gen.measurement_matrix(p), ref["H"])
    assert np.allclose(gen.noise_psd(p), np.diag(ref["Q"]), rtol=1e-14)


def test_nonlinear_model_is_refused_before_writing(tmp_path):
    with pytest.raises(ModelError, match="not linear"):  # refused as the model is built (modelgen.model.declaration)
        model = ErrorModel.build(
            "toy", [State("a"), State("b")], [Noise("w")], [Parameter("k")], {"a": "a*b", "b": "k*b + w"}
        )
        generate_code(derive(model))


def test_unknown_scalar_type_is_refused():
    with pytest.raises(ModelError, match="scalar type"):
        CodegenOptions(scalar="long double")


def test_failed_write_leaves_previous_output_intact(tmp_path):
    folder = tmp_path / "gen" / "m"
    write_atomically(folder, {"a.txt": "old"})

    class Exploding(dict):
        def items(self):
            yield "a.txt", "new"
            raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_atomically(folder, Exploding())
    assert (folder / "a.txt").read_text() == "old"
    assert sorted(p.name for p in folder.parent.iterdir()) == ["m"]


def test_generated_python_refuses_arguments_of_the_wrong_shape(paper_code, tmp_path):
    import numpy as np

    write_atomically(tmp_path / "shape", paper_code.files)
    gen = load_python_module(tmp_path / "shape" / "ned_doppler18.py")
    x, P = np.zeros(18), np.eye(18)
    with pytest.raises(ValueError, match=r"update: H has shape \(2, 17\), expected \(2, 18\)"):
        gen.update(x, P, np.zeros(2), np.zeros((2, 17)), np.ones(2))
    with pytest.raises(ValueError, match=r"predict: P has shape \(17, 17\)"):
        gen.predict(x, np.eye(17), np.eye(18), np.zeros((18, 18)))


@pytest.mark.compile
@pytest.mark.parametrize("form", ["covariance", "ud"])
def test_workspace_is_only_as_large_as_the_larger_scratch_and_the_readme_states_its_size(paper_derived, tmp_path, form):
    """discretize and the filter steps share the workspace (a union), so the caller
    keeps max(discretize scratch, filter scratch), and the README's byte count is
    what the compiler allocates."""
    code = generate_code(paper_derived, CodegenOptions(form=form))
    write_atomically(tmp_path / "out", code.files)
    probe = tmp_path / "sizes.c"
    probe.write_text(
        '#include <stdio.h>\n#include "ned_doppler18.h"\n'
        "int main(void) { printf(\"%lu %lu %lu\\n\", (unsigned long)sizeof(ned_doppler18_workspace),"
        " (unsigned long)sizeof(ned_doppler18_discretize_scratch), (unsigned long)sizeof(ned_doppler18_filter_scratch));"
        " return 0; }\n"
    )
    exe = tmp_path / "sizes"
    subprocess.run([compiler(), *STRICT_FLAGS, "-I", str(tmp_path / "out"), str(probe), "-o", str(exe)], check=True)
    workspace, discretize, filter_steps = map(int, subprocess.run([str(exe)], capture_output=True, text=True).stdout.split())
    assert workspace == max(discretize, filter_steps) < discretize + filter_steps
    assert f"ned_doppler18_workspace ({workspace} bytes)" in code.files["README.md"].replace("\n", " ")
