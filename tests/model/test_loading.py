"""Model files: every malformed file is refused naming the file, the line or key, and the problem.

The base file below is valid; each test changes one thing and checks the
message starts with ``<file>:<line>:`` (or names the file and the key where
there is no line) and says what is wrong.
"""

from __future__ import annotations

import re

import pytest

from modelgen.derivation.symbolic import derive
from modelgen.errors import ModelError
from modelgen.model.declaration import check_identifier
from modelgen.model.loading import builtin_models, load_model, load_model_text

BASE = """\
model: toy
parameters:
  - {name: rate, symbol: mu, value: 0.5}
  - {name: sigma, symbol: sig}
states:
  - {name: position_error, symbol: dx, unit: m}
  - {name: velocity_error, symbol: dv, unit: m/s}
noises:
  - {name: accel_noise, symbol: w, psd: "2*mu*sig**2"}
dynamics:
  dx: dv
  dv: -mu*dv + w
measurements:
  - {name: position_difference, expression: dx, variance: "0.01"}
"""
# line numbers in BASE (1-based)
LINE = {"model": 1, "rate": 3, "states": 5, "position_error": 6, "velocity_error": 7, "noise": 9, "dynamics": 10, "dx": 11, "dv": 12, "meas": 14}


def edit(old: str, new: str) -> str:
    assert old in BASE, old
    return BASE.replace(old, new, 1)


def refusal(text: str, *patterns: str) -> str:
    """The ModelError message for ``text`` loaded as model.yaml; each pattern must be in it."""
    with pytest.raises(ModelError) as info:
        load_model_text(text, "model.yaml")
    message = str(info.value)
    for pattern in patterns:
        assert re.search(pattern, message), f"{pattern!r} not in {message!r}"
    return message


def test_base_file_is_valid_and_derives():
    m = load_model_text(BASE, "model.yaml")
    d = derive(m)
    assert m.name == "toy" and d.F.shape == (2, 2) and d.H.shape == (1, 2)


def test_unknown_symbol_names_file_line_equation_and_symbol():
    refusal(edit("  dv: -mu*dv + w", "  dv: -mu*dv + w + drift"), rf"^model\.yaml:{LINE['dv']}: ", r"d\(dv\)/dt", "unknown symbol", "drift")


def test_unknown_symbol_in_a_measurement_names_its_line():
    refusal(edit("expression: dx,", "expression: dx + bias,"), rf"^model\.yaml:{LINE['meas']}: ", "measurement 'position_difference'", "bias")


def test_duplicate_name_names_the_second_declaration_line():
    refusal(edit("{name: velocity_error, symbol: dv, unit: m/s}", "{name: position_error, symbol: dv, unit: m/s}"), rf"^model\.yaml:{LINE['velocity_error']}: ", "declared twice", "position_error")


def test_duplicate_symbol_across_kinds_is_refused():
    refusal(edit("{name: rate, symbol: mu, value: 0.5}", "{name: rate, symbol: dx, value: 0.5}"), rf"^model\.yaml:{LINE['rate']}: ", "'dx' is declared twice")


def test_duplicate_key_in_a_mapping_is_refused_with_its_line():
    refusal(edit("  dv: -mu*dv + w\n", "  dv: -mu*dv + w\n  dx: dv\n"), rf"^model\.yaml:{LINE['dv'] + 1}: ", "appears twice", "dynamics.dx")


@pytest.mark.parametrize("bad", ["2dv", "d-v", "dv x", "vélocité"])
def test_invalid_c_identifier_is_refused_with_its_line(bad):
    refusal(edit("symbol: dv, unit", f"symbol: '{bad}', unit"), rf"^model\.yaml:{LINE['velocity_error']}: ", "not a valid C identifier")


@pytest.mark.parametrize("word", ["int", "return", "struct", "class"])
def test_keyword_is_refused_with_its_line(word):
    refusal(edit("{name: rate,", f"{{name: {word},"), rf"^model\.yaml:{LINE['rate']}: ", "keyword", word)


def test_invalid_model_name_names_the_line_of_the_model_key():
    refusal(edit("model: toy", "model: 2toy"), rf"^model\.yaml:{LINE['model']}: ", "model name", "not a valid C identifier")


@pytest.mark.parametrize("value", ["fast", "yes", "2001-01-01", "[1, 2]", ".nan", ""])
def test_non_numeric_parameter_value_is_refused_with_its_line(value):
    refusal(edit("value: 0.5}", f"value: {value}}}"), rf"^model\.yaml:{LINE['rate']}: ", "parameter 'rate'", "not (a number|finite)")


def test_numeric_strings_are_numbers():
    m = load_model_text(edit("value: 0.5}", "value: '1e-3'}"), "model.yaml")
    assert m.parameter_defaults()["rate"] == pytest.approx(1e-3)


@pytest.mark.parametrize("psd, problem", [("high", "unknown symbol"), ("true", "not numeric"), ("-1", "negative"), ("[1, 2]", "dimension mismatch"), ("''", "empty")])
def test_bad_noise_statistic_is_refused_with_its_line(psd, problem):
    refusal(edit('psd: "2*mu*sig**2"', f"psd: {psd}"), rf"^model\.yaml:{LINE['noise']}: ", problem)


@pytest.mark.parametrize("variance, problem", [("small", "unknown symbol"), ("-0.01", "negative"), ("{a: 1}", "dimension mismatch")])
def test_bad_measurement_variance_is_refused_with_its_line(variance, problem):
    refusal(edit('variance: "0.01"', f"variance: {variance}"), rf"^model\.yaml:{LINE['meas']}: ", problem)


def test_equation_for_an_undeclared_state_names_its_line():
    refusal(edit("  dv: -mu*dv + w\n", "  dv: -mu*dv + w\n  dz: dv\n"), rf"^model\.yaml:{LINE['dv'] + 1}: ", "'dz', which is not a declared state")


def test_missing_equation_names_the_dynamics_line_and_the_state():
    refusal(edit("  dx: dv\n", ""), rf"^model\.yaml:{LINE['dynamics']}: ", "no equation for state", "position_error")


@pytest.mark.parametrize("rhs, problem", [("", "empty"), ("[dv, dx]", "dimension mismatch"), ("dv +", "cannot parse"), ("dv.subs(dv, 1)", "not allowed"), ("foo(dv)", "unknown function")])
def test_malformed_equation_is_refused_with_its_line(rhs, problem):
    refusal(edit("  dx: dv\n", f"  dx: {rhs}\n"), rf"^model\.yaml:{LINE['dx']}: ", problem)


@pytest.mark.parametrize(
    "text, line",
    [
        (edit("  dx: dv\n", "  dx: [dv\n"), LINE["dv"]),  # unclosed flow sequence, noticed on the next line
        (edit("states:\n", "states:\n  - {name: a\n"), LINE["states"] + 2),
        (edit("  dv: -mu*dv + w", " dv: -mu*dv + w"), LINE["dv"]),  # bad indentation
    ],
)
def test_malformed_yaml_names_the_file_and_line(text, line):
    refusal(text, rf"^model\.yaml:{line}: not valid YAML")


def test_unsafe_yaml_tag_is_refused_not_constructed():
    refusal(edit("value: 0.5}", "value: !!python/name:os.getcwd ''}"), rf"^model\.yaml:{LINE['rate']}: ", "parameters\\[0\\]\\.value", "constructor")


def test_unknown_top_level_key_names_line_and_key():
    refusal(BASE + "stats: {a: 1}\n", r"^model\.yaml:15: ", "unknown key 'stats'")


def test_unknown_field_of_an_entry_names_line_field_and_allowed_fields():
    refusal(edit('psd: "2*mu*sig**2"}', 'psd: "2*mu*sig**2", sigma: 3}'), rf"^model\.yaml:{LINE['noise']}: ", "unknown field 'sigma'", "allowed")


def test_missing_required_key_names_the_file_and_key():
    refusal(BASE.replace("model: toy\n", ""), r"^model\.yaml: ", "missing required key 'model'")


def test_entry_without_name_and_wrong_section_types_are_refused():
    refusal(edit("{name: accel_noise, symbol: w,", "{symbol: w,"), rf"^model\.yaml:{LINE['noise']}: ", "must be a mapping with a 'name'")
    refusal("model: toy\nstates: {a: 1}\ndynamics: {}\n", r"^model\.yaml:2: ", "'states' must be a list")
    refusal("model: toy\nstates:\n  - {name: a}\ndynamics: [a]\n", r"^model\.yaml:4: ", "'dynamics' must map")
    refusal("- just\n- a list\n", r"^model\.yaml: ", "must be a mapping")


def test_measurement_without_expression_is_refused():
    refusal(edit("{name: position_difference, expression: dx, ", "{name: position_difference, "), rf"^model\.yaml:{LINE['meas']}: ", "no 'expression'")


def test_missing_file_names_the_path_and_the_builtin_models(tmp_path):
    with pytest.raises(ModelError, match=r"no_such\.yaml: no such model file.*ned_doppler18"):
        load_model(tmp_path / "no_such.yaml")


def test_model_file_on_disk_loads_by_path_with_its_path_in_errors(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(edit("  dx: dv\n", "  dx: dq\n"), encoding="utf-8")
    with pytest.raises(ModelError, match=rf"^{re.escape(str(path))}:{LINE['dx']}: "):
        load_model(path)


def test_the_library_has_the_models_of_all_four_source_documents():
    assert {"ned_doppler18", "ned_inertial16", "enu_doppler18", "ins_gps15", "gps_pseudorange11"} <= set(builtin_models())


@pytest.mark.parametrize("name", builtin_models())
def test_every_builtin_model_loads_derives_linearly_and_has_c_identifiers(name, derived_builtin):
    derived = derived_builtin(name)  # load_model and derive, once per session (tests/conftest.py)
    model = derived.model
    assert derived.nonlinear == ()
    assert derived.F.shape == (len(model.states), len(model.states))
    for q in (*model.states, *model.noises, *model.parameters, *model.measurements):
        check_identifier(q.name, name)
        check_identifier(q.symbol, name)


SOURCE_DOCUMENT_MODELS = ("ned_doppler18", "ned_inertial16", "enu_doppler18", "ins_gps15", "gps_pseudorange11")


@pytest.mark.parametrize("name", SOURCE_DOCUMENT_MODELS)
def test_source_document_models_describe_every_state_and_give_every_statistic(name):
    model = load_model(name)
    assert model.source and model.frame in ("NED", "ENU")
    for s in model.states:
        assert s.unit and s.description, s.name
    for w in model.noises:
        assert w.psd != "1", w.name  # the default PSD would be a silent assumption
    for m in model.measurements:
        assert m.variance != "1", m.name


# -- issue 10: hostile files are refused with the file name, never a traceback or a hang ----------


def test_binary_file_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(ModelError, match=r"m\.yaml:1: contains a NUL byte"):
        load_model(path)


def test_utf16_file_is_refused_asking_for_utf8(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(BASE, encoding="utf-16")
    with pytest.raises(ModelError, match=r"m\.yaml: is encoded as UTF-16.*UTF-8"):
        load_model(path)


def test_invalid_utf8_is_refused_naming_the_line_and_byte(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_bytes(BASE.replace("title", "x").encode().replace(b"unit: m/s}", b"unit: m/s\xe9}"))
    with pytest.raises(ModelError, match=rf"m\.yaml:{LINE['velocity_error']}: is not UTF-8 text \(byte 0xe9"):
        load_model(path)


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_bytes(b"\xef\xbb\xbf" + BASE.encode())
    assert load_model(path).name == "toy"


def test_directory_given_as_a_model_is_refused(tmp_path):
    (tmp_path / "m.yaml").mkdir()
    with pytest.raises(ModelError, match=r"m\.yaml: is a directory, not a model file"):
        load_model(tmp_path / "m.yaml")


def test_file_over_one_megabyte_is_refused_before_it_is_parsed(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(BASE + "# padding\n" * 110_000)
    with pytest.raises(ModelError, match=r"m\.yaml: \d+ bytes; a model file may have at most 1000000"):
        load_model(path)


def test_unreadable_file_is_refused_naming_it(tmp_path):
    import os

    path = tmp_path / "m.yaml"
    path.write_text(BASE)
    path.chmod(0)
    try:
        if os.access(path, os.R_OK):  # root reads anything
            pytest.skip("running as root: permissions do not apply")
        with pytest.raises(ModelError, match=r"m\.yaml: cannot read the model file \(Permission denied\)"):
            load_model(path)
    finally:
        path.chmod(0o644)


def test_yaml_alias_bomb_is_refused_without_expanding_it():
    bomb = "model: toy\nnotes: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"n{i}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
        for i in range(9)
    )
    refusal(bomb, r"^model\.yaml:3: ", r"aliases \(\*a\)")


def test_any_alias_is_refused_naming_its_line():
    refusal(edit("  dx: dv\n  dv: -mu*dv + w", "  dx: &rhs dv\n  dv: *rhs"), rf"^model\.yaml:{LINE['dv']}: ", r"\*rhs", "aliases")


def test_recursive_alias_and_deep_nesting_are_refused():
    refusal("model: toy\nstates: &s [*s]\n", "model.yaml")
    refusal("model: toy\nnotes: " + "[" * 5000 + "]" * 5000 + "\n", "model.yaml", "not valid")


def test_control_character_from_a_yaml_escape_is_refused_with_its_line():
    refusal(edit("model: toy\n", 'model: toy\ntitle: "run \\e[2J \\x00 this"\n'), r"^model\.yaml:2: ", "title", "U\\+001B")
    refusal(edit("unit: m/s}", 'unit: m/s, description: "a\\u202eb"}'), rf"^model\.yaml:{LINE['velocity_error']}: ", "description", "U\\+202E")


def test_raw_control_character_in_the_file_is_refused_with_its_line():
    refusal(edit("model: toy\n", "model: toy\ntitle: a\x1bb\n"), r"^model\.yaml:2: not valid YAML \(character U\+001B")


def test_free_text_must_be_text():
    refusal(edit("model: toy\n", "model: toy\ntitle: [a, b]\n"), r"^model\.yaml:2: 'title' must be text")


def test_nonlinear_measurement_is_refused_like_nonlinear_dynamics():
    refusal(edit("expression: dx,", "expression: dv**2 + dv,"), rf"^model\.yaml:{LINE['meas']}: ", "measurement 'position_difference'", "not linear")
    refusal(edit("  dv: -mu*dv + w", "  dv: -mu*dv*dx + w"), rf"^model\.yaml:{LINE['dv']}: ", r"d\(dv\)/dt", "not linear")


@pytest.mark.parametrize(
    "rhs, problem",
    [("0/0*dv", "undefined"), ("dv/(1-1)", "undefined"), ("log(0)*dv", "undefined"), ("sqrt(-2)*dv", "complex"), ("10**10**10*dv", "power of a power"), ("Float(1, 100000000)*dv", "unknown function")],
)
def test_undefined_or_pathological_equation_names_its_line(rhs, problem):
    refusal(edit("  dv: -mu*dv + w", f"  dv: {rhs}"), rf"^model\.yaml:{LINE['dv']}: ", r"d\(dv\)/dt", problem)


def test_negative_psd_expression_names_its_line():
    refusal(edit('psd: "2*mu*sig**2"', 'psd: "-2*sig**2"'), rf"^model\.yaml:{LINE['noise']}: ", "negative")


@pytest.mark.parametrize("name, collision", [("N", "generated C"), ("NAN", "C standard library"), ("linux", "POSIX"), ("errno", "C standard library")])
def test_colliding_parameter_name_names_its_line(name, collision):
    refusal(edit("{name: rate,", f"{{name: {name},"), rf"^model\.yaml:{LINE['rate']}: ", "collides with", collision)


def test_model_named_like_a_header_names_its_line():
    refusal(edit("model: toy", "model: math"), rf"^model\.yaml:{LINE['model']}: ", "collides with", "math")


def write_transform(path, model, base):
    path.write_text(f"model: {model}\nbase: {base}\ntransforms:\n  - keep_states: {{states: [dx, dv]}}\n")


def test_transform_whose_base_is_itself_is_refused(tmp_path):
    write_transform(tmp_path / "a.yaml", "a", "a.yaml")
    with pytest.raises(ModelError, match=r"a\.yaml: the chain of base models loops back on itself \(.*a\.yaml -> .*a\.yaml\)"):
        load_model(tmp_path / "a.yaml")


def test_transform_cycle_through_two_files_is_refused(tmp_path):
    write_transform(tmp_path / "a.yaml", "a", "b.yaml")
    write_transform(tmp_path / "b.yaml", "b", "a.yaml")
    with pytest.raises(ModelError, match=r"loops back on itself \(.*a\.yaml -> .*b\.yaml -> .*a\.yaml\)"):
        load_model(tmp_path / "a.yaml")


def test_transform_of_a_file_twice_in_a_chain_without_a_cycle_loads(tmp_path):
    (tmp_path / "base.yaml").write_text(BASE)
    write_transform(tmp_path / "a.yaml", "a", "base.yaml")
    write_transform(tmp_path / "b.yaml", "b", "a.yaml")
    assert load_model(tmp_path / "b.yaml").state_names == ["position_error", "velocity_error"]


def test_transform_free_text_is_checked():
    with pytest.raises(ModelError, match=r"file\.yaml:2: model 'small', title.*U\+001B"):
        load_model_text('model: small\ntitle: "a\\eb"\nbase: ned_doppler18\n', "file.yaml")
    with pytest.raises(ModelError, match=r"collides with"):
        load_model_text("model: stdio\nbase: ned_doppler18\n", "file.yaml")


def test_a_folder_named_like_a_built_in_model_does_not_shadow_it(tmp_path, monkeypatch):
    """Issue 28: a ./ned_doppler18 folder (``generate ned_doppler18 --out .`` makes one) hid the built-in model."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ned_doppler18").mkdir()
    assert len(load_model("ned_doppler18").states) == 18


def test_loaded_items_carry_the_lines_of_their_entries_and_fields():
    """Each state, noise, parameter and measurement keeps file:line of its entry and of its psd / variance /
    expression / value / equation, so that a refusal made after loading can name it (block style: each field on a
    line of its own); equality and the model hash ignore them."""
    from modelgen.codegen.description import model_hash

    text = edit('  - {name: position_difference, expression: dx, variance: "0.01"}\n',
                '  - name: position_difference\n    expression: dx\n    variance: "0.01"\n')
    m = load_model_text(text, "model.yaml")
    assert m.parameters[0].place() == m.parameters[0].place("value") == f"model.yaml:{LINE['rate']}"
    assert m.states[1].place() == f"model.yaml:{LINE['velocity_error']}"
    assert m.states[1].place("dynamics") == f"model.yaml:{LINE['dv']}"
    assert m.noises[0].place("psd") == f"model.yaml:{LINE['noise']}"
    measurement = m.measurements[0]
    assert (measurement.place(), measurement.place("expression"), measurement.place("variance")) == (
        f"model.yaml:{LINE['meas']}", f"model.yaml:{LINE['meas'] + 1}", f"model.yaml:{LINE['meas'] + 2}")
    elsewhere = load_model_text(text, "other/place.yaml")
    assert elsewhere.measurements == m.measurements and model_hash(elsewhere) == model_hash(m)


def test_items_of_vector_navigation_and_transformed_models_carry_their_lines(tmp_path):
    """The vector loader's and the navigation derivation's line maps reach the items too; a transform keeps the
    lines of the items it takes from its base (they are in the base file)."""
    nav = load_model("gps_pseudorange11_twin")
    assert re.fullmatch(r".*gps_pseudorange11_twin\.yaml:\d+", nav.measurements[3].place("variance"))
    (tmp_path / "base.yaml").write_text(BASE)
    write_transform(tmp_path / "small.yaml", "small", "base.yaml")
    small = load_model(tmp_path / "small.yaml")
    assert small.noises[0].place("psd") == f"{tmp_path / 'base.yaml'}:{LINE['noise']}"
