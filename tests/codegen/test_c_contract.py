"""The generated C contract (issue 11, item 5): indices, state access, masked update with NIS, reset, hash.

A small consumer program that uses only the index macros and the contract's
functions is compiled strictly and run for every built-in model; the masked
update agrees with a full update over the used rows alone, in every option
family; every line of the C is at most 100 columns; every macro the C
defines carries the model's prefix.
"""

from __future__ import annotations

import re
import subprocess

import numpy as np
import pytest

from modelgen.codegen.backends.c.printer import LINE_WIDTH, wrap_line
from modelgen.codegen.build import STRICT_FLAGS, CompiledFilter, compile_shared_library, compiler
from modelgen.codegen.description import model_hash
from modelgen.codegen.generate import generate_code
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import all_combinations
from modelgen.model.loading import builtin_models

from generated_support import write_files


@pytest.fixture(scope="module")
def derived_models(derived_builtin):
    return {name: derived_builtin(name) for name in builtin_models()}  # derived once per session (tests/conftest.py)


def consumer_source(derived, h_first: float = 0.0) -> str:
    """C using only the index macros and the contract's functions (plus the structs they take)."""
    model = derived.model
    p, P = model.name, model.name.upper()
    first_state = f"{P}_STATE_{model.state_names[-1].upper()}"
    free = "\n".join(f"    params.{q.name} = 0.5;" for q in model.parameters if q.value is None)
    update = ""
    if derived.n_measurements:
        first = f"{P}_MEASUREMENT_{model.measurement_names[0].upper()}"
        update = f"""
    {{
        {p}_scalar z[{P}_N_MEASUREMENTS], innovation[{P}_N_MEASUREMENTS], nis = -1;
        unsigned char mask[{P}_N_MEASUREMENTS];
        for (i = 0; i < {P}_N_MEASUREMENTS; ++i) {{
            z[i] = NAN; /* a lost measurement: ignored by the mask */
            mask[i] = 0;
        }}
        z[{first}] = 0.25;
        mask[{first}] = 1;
        if ({p}_update_masked(&filter, z, mask, &m, innovation, &nis, &work) != {P}_OK) return 4;
        if (!(nis >= 0) || fabs(innovation[{first}] - (0.25 - 0.5 * {h_first!r})) > 1e-5) return 5;
        for (i = 0; i < {P}_N_MEASUREMENTS; ++i) {{
            if (i != {first} && innovation[i] != 0) return 6;
        }}
        printf("nis %.17g\\n", (double)nis);
    }}"""
    return f"""#include <math.h>
#include <stdio.h>
#include <string.h>
#include "{p}.h"

int main(void)
{{
    static {p}_params params;
    static {p}_matrices m;
    static {p}_transition t;
    static {p}_filter filter;
    static {p}_workspace work;
    static {p}_scalar P0[{P}_N_STATES * {P}_N_STATES], x[{P}_N_STATES];
    int i;
    {p}_default_params(&params);
{free}
    if ({p}_matrices_evaluate(&params, &m) != {P}_OK) return 1;
    if ({p}_discretize(&m, 1, &t, &work) != {P}_OK) return 1;
    for (i = 0; i < {P}_N_STATES; ++i) {{
        P0[i * {P}_N_STATES + i] = 1;
        x[i] = 0;
    }}
    x[{first_state}] = 0.5;
    if ({p}_set_covariance(&filter, P0, &work) != {P}_OK) return 2;
    if ({p}_set_state(&filter, x) != {P}_OK) return 2;
    x[0] = NAN;
    if ({p}_set_state(&filter, x) != {P}_ERR_NONFINITE) return 3;
    {p}_get_state(&filter, x);
    if (x[{first_state}] != 0.5 || x[0] != 0 || strcmp({p}_state_names[{first_state}], "{model.state_names[-1]}") != 0) return 3;
{update}
    if ({p}_predict(&filter, &t, &work) != {P}_OK) return 7;
    {p}_reset_error_state(&filter);
    {p}_get_state(&filter, x);
    for (i = 0; i < {P}_N_STATES; ++i) {{
        if (x[i] != 0) return 8;
    }}
    printf("%s %s %d\\n", {P}_MODEL_HASH, {P}_MODELGEN_VERSION, {P}_N_STATES);
    return 0;
}}
"""


def _h_of_first(derived, first_state: int) -> float:
    """H[first measurement, first_state] as a C literal (the consumer's x is 0.5 there, 0 elsewhere)."""
    return float(derived.H.subs({q.sym: (q.value if q.value is not None else 0.5) for q in derived.model.parameters})[0, first_state])


@pytest.mark.compile
@pytest.mark.parametrize("name", builtin_models())
def test_consumer_using_only_index_macros_and_contract_functions_compiles_and_runs(name, derived_models, tmp_path):
    derived = derived_models[name]
    model = derived.model
    folder = write_files(tmp_path, generate_code(derived).files)
    last = len(model.state_names) - 1
    source = consumer_source(derived, _h_of_first(derived, last) if derived.n_measurements else 0.0)
    (folder / "consumer.c").write_text(source)
    exe = folder / "consumer"
    subprocess.run(
        [compiler(), *STRICT_FLAGS, "-O1", "-o", str(exe), str(folder / "consumer.c"), str(folder / f"{name}.c"), "-lm"],
        check=True, capture_output=True, text=True,
    )
    run = subprocess.run([str(exe)], capture_output=True, text=True)
    assert run.returncode == 0, (run.returncode, run.stdout, run.stderr)
    last_line = run.stdout.strip().splitlines()[-1].split()
    assert last_line[0] == model_hash(model) and len(last_line[0]) == 16
    assert int(last_line[2]) == derived.n_states


@pytest.mark.parametrize("name", builtin_models())
def test_every_c_line_is_at_most_100_columns_and_every_macro_is_prefixed(name, derived_models):
    files = generate_code(derived_models[name]).files
    prefix = name.upper() + "_"
    for file in (f"{name}.h", f"{name}.c"):
        lines = files[file].splitlines()
        long = [(k + 1, len(line)) for k, line in enumerate(lines) if len(line) > LINE_WIDTH]
        assert not long, f"{file}: lines over {LINE_WIDTH} columns: {long[:5]}"
        macros = re.findall(r"^\s*#define +([A-Za-z_][A-Za-z0-9_]*)", files[file], re.M)
        bare = [m for m in macros if not m.startswith((prefix, "MODELGEN_"))]
        assert not bare, f"{file}: macros without the model's prefix: {bare}"


def test_kernel_calls_of_predict_are_indented_not_at_column_0(paper_derived):
    source = generate_code(paper_derived).files["ned_doppler18.c"]
    body = source[source.index("int ned_doppler18_predict(") :]
    body = body[: body.index("\n}\n")]
    calls = [line for line in body.splitlines() if re.search(r"(phi_times|propagate)_\w+\(", line)]
    assert calls and all(line.startswith("    ") for line in calls)


def test_wrapping_keeps_preprocessor_lines_and_moves_a_macro_comment_above():
    directive = "#define X_STATE_A 0 /* " + "word " * 30 + "*/"
    wrapped = wrap_line(directive)
    assert wrapped[-1] == "#define X_STATE_A 0" and all(len(line) <= LINE_WIDTH for line in wrapped)
    assert wrap_line("#include " + "a" * 120) == ["#include " + "a" * 120]


@pytest.mark.compile
@pytest.mark.parametrize("options", all_combinations("double"), ids=lambda o: o.slug())
def test_masked_update_equals_the_update_with_the_used_rows_and_reports_innovation_and_nis(options, paper_derived, tmp_path):
    """Both measurements of the paper's model; mask (1, 0): the second, NaN, is ignored."""
    python = {}
    files = generate_code(paper_derived, options).files
    folder = write_files(tmp_path, files)
    exec(compile(files["ned_doppler18.py"], "ned_doppler18.py", "exec"), python)
    library = compile_shared_library([folder / "ned_doppler18.c"], folder / "libned_doppler18.so", cache=True)
    model = paper_derived.model
    c = CompiledFilter(library, model.name, ModelSizes.of(paper_derived), model.parameter_names, options=options)
    values = {q.name: 0.6 if q.name == "latitude" else 20.0 for q in model.parameters if q.value is None}
    assert c.set_parameters(values) == 0
    p = python["parameter_vector"]({**python["PARAMETER_DEFAULTS"], **values})
    F, G, H, q, r = python["matrices_evaluate"](p)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(18, 18))
    P0 = A @ A.T * 1e-3 + np.eye(18) * 1e-2
    x0 = rng.normal(size=18) * 0.1
    assert c.set_state(x0, P0) == 0
    z = np.array([0.3, np.nan])
    status, innovation, nis = c.update_masked(z, [1, 0])
    assert status == 0
    x_ref, P_ref, innovation_ref, nis_ref = python["update_masked"](x0, P0, z, H, r, [True, False])
    np.testing.assert_allclose(c.x, x_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(c.P, P_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(innovation, innovation_ref, rtol=1e-12, atol=1e-15)
    assert innovation[1] == 0.0 and nis == pytest.approx(nis_ref, rel=1e-9)
    # every row used: the NIS of both, and the same state as the plain update
    assert c.set_state(x0, P0) == 0
    z = np.array([0.3, -0.2])
    status, innovation, nis = c.update_masked(z, None)
    x_all, _, _, nis_all = python["update_masked"](x0, P0, z, H, r)
    assert status == 0 and nis == pytest.approx(nis_all, rel=1e-9)
    np.testing.assert_allclose(c.x, x_all, rtol=1e-9, atol=1e-12)
    c.reset_error_state()
    assert not c.x.any()


@pytest.mark.parametrize(
    "options", [o for o in all_combinations("double") if o.slug() in ("double-full-vector-joseph", "double-full-sequential-standard", "double-ud")],
    ids=lambda o: o.slug(),
)
@pytest.mark.compile
def test_masked_update_refuses_a_nan_in_a_used_row_and_leaves_filter_and_outputs_unchanged(options, paper_derived, tmp_path):
    files = generate_code(paper_derived, options).files
    folder = write_files(tmp_path, files)
    library = compile_shared_library([folder / "ned_doppler18.c"], folder / "libned_doppler18.so", cache=True)
    model = paper_derived.model
    c = CompiledFilter(library, model.name, ModelSizes.of(paper_derived), model.parameter_names, options=options)
    assert c.set_parameters({q.name: 0.6 if q.name == "latitude" else 20.0 for q in model.parameters if q.value is None}) == 0
    assert c.set_state(np.full(18, 0.01), np.eye(18) * 1e-2) == 0
    x, P = c.x, c.P
    status, innovation, nis = c.update_masked(np.array([0.3, np.nan]), [0, 1])
    assert status == 1  # ERR_NONFINITE
    assert np.array_equal(c.x, x) and np.array_equal(c.P, P)
    assert not innovation.any() and np.isnan(nis)  # the outputs were not written
