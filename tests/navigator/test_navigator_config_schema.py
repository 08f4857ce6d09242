"""The replay configuration's JSON schema: valid, enforced by the loader, in step with it, and documented key by key."""

from __future__ import annotations

import copy
import re
from dataclasses import replace
from pathlib import Path

import jsonschema
import pytest
import yaml

from modelgen.errors import ModelError
from modelgen.navigator.config import builtin_config_path, load_config
from modelgen.navigator.config_schema import (key_sets, key_table_markdown, keys, load_schema, with_key_table)

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / "docs" / "replay-configuration.md"


def builtin_data() -> dict:
    data = yaml.safe_load(builtin_config_path().read_text(encoding="utf-8"))
    drives = builtin_config_path().parent
    data["imu"]["file"] = str(drives / data["imu"]["file"])
    data["gnss"]["file"] = str(drives / data["gnss"]["file"])
    return data


def write(folder: Path, data: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "nav.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _get(data: dict, dotted: str):
    node = data
    for part in dotted.split("."):
        node = node[part]
    return node


def _set(data: dict, dotted: str, value) -> None:
    *head, last = dotted.split(".")
    node = data
    for part in head:
        node = node.setdefault(part, {})
    node[last] = value


def _drop(data: dict, dotted: str) -> None:
    *head, last = dotted.split(".")
    node = data
    for part in head:
        node = node[part]
    del node[last]


def _comparable(config):
    return replace(config, path="")


def _navigator_keys():
    """(path, node) of every key that is the navigator's own (not a log format's, not inside a list)."""
    return [(p, n) for p, n in keys() if "(" not in p]


def _required(path: str) -> bool:
    parent, _, key = path.rpartition(".")
    node = load_schema()
    for part in parent.split(".") if parent else []:
        node = node.get("properties", node.get("x-keys", {}))[part]
    if "$ref" in node:  # outages: a schedule (all four keys) or windows
        branches = load_schema()["$defs"][node["$ref"].rpartition("/")[2]]["oneOf"]
        return any(key in b["properties"] and key in b["required"] for b in branches)
    return key in node.get("required", [])


def test_the_schema_is_valid_draft_2020_12_and_accepts_every_shipped_configuration():
    schema = load_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    shipped = [builtin_config_path(), REPO / "tests" / "navigator" / "data" / "excerpt.yaml"]
    for path in shipped:
        assert list(validator.iter_errors(yaml.safe_load(path.read_text(encoding="utf-8")))) == [], path


def test_the_schema_accepts_the_navigation_model_keys_of_the_parameters_section_and_scale_factor_sigmas():
    properties = load_schema()["properties"]
    assert properties["parameters"]["type"] == "object" and "description" in properties["parameters"]
    for key in ("gyro_scale_factor_sigma_ppm", "accel_scale_factor_sigma_ppm"):
        node = properties["initial"]["properties"][key]
        assert node["x-unit"] == "ppm" and key not in properties["initial"]["required"]


def test_the_loader_refuses_what_only_the_schema_checks_naming_file_and_line(tmp_path):
    data = builtin_data()
    data["description"] = ["a", "list"]
    path = write(tmp_path, data)
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if text.startswith("description"))
    with pytest.raises(ModelError, match=rf"nav\.yaml:{line}: description: \['a', 'list'\] is not of type 'string'"):
        load_config(path)
    data = builtin_data()
    data["navigator"] = ""
    with pytest.raises(ModelError, match=r"nav\.yaml:\d+: navigator: '' should be non-empty"):
        load_config(write(tmp_path / "empty", data))


def test_unknown_keys_are_refused_in_every_section_the_schema_closes(tmp_path):
    for section in ("", "imu", "gnss", "noise.gyro_white", "initial", "alignment", "filter", "zupt", "nhc", "outages",
                    "evaluation", "output"):
        data = builtin_data()
        data.setdefault("output", {})
        node = _get(data, section) if section else data
        node["no_such_key"] = 1
        with pytest.raises(ModelError, match=r"nav\.yaml:\d+: unknown key 'no_such_key'"):
            load_config(write(tmp_path / (section or "top"), data))


def test_every_required_key_is_required_by_the_loader_and_every_optional_one_is_not(tmp_path):
    """The schema's required lists are the loader's: each required key removed is refused, each optional one
    the built-in configuration gives removed is accepted."""
    checked = 0
    for path, _node in _navigator_keys():
        data = builtin_data()
        try:
            _get(data, path)
        except KeyError:
            continue
        _drop(data, path)
        folder = tmp_path / path.replace(".", "_")
        if _required(path):
            with pytest.raises(ModelError) as refused:
                load_config(write(folder, data))
            assert path in str(refused.value)  # the refusal names the missing key
        else:
            load_config(write(folder, data))
        checked += 1
    assert checked >= 50


def test_every_default_in_the_schema_is_the_loaders(tmp_path):
    """For every optional key with a default: the configuration without it and with it at the schema's default
    load to the same configuration."""
    checked = []
    for path, node in _navigator_keys():
        if "default" not in node:
            continue
        without = builtin_data()
        parent = path.rpartition(".")[0]
        if parent and parent not in without:
            continue  # an optional section (outages, output) the built-in gives differently: not this key's test
        try:
            _drop(without, path)
        except KeyError:
            pass
        with_default = copy.deepcopy(without)
        _set(with_default, path, node["default"])
        a = load_config(write(tmp_path / f"{path}_without", without))
        b = load_config(write(tmp_path / f"{path}_default", with_default))
        assert _comparable(a) == _comparable(b), path
        checked.append(path)
    assert {"imu.time_offset_s", "imu.gap_factor", "imu.gap_action", "alignment.rest_min_s",
            "nhc.rate_max_deg_s", "gnss.velocity_latency_s"} <= set(checked)


def test_the_log_format_branches_of_the_schema_are_the_formats_declarations():
    """imu:/gnss: keys per format (the schema's if/then branches) against logs.registry: keys, required, defaults,
    choices."""
    from modelgen.navigator.logs.formats import REQUIRED
    from modelgen.navigator.logs.registry import COMMON_KEYS, FORMATS, formats_for

    for section in ("imu", "gnss"):
        node = load_schema()["properties"][section]
        assert set(COMMON_KEYS[section]) <= set(node["properties"])
        branches = {b["if"]["properties"]["format"]["const"]: b["then"] for b in node["allOf"]}
        assert sorted(branches) == sorted(formats_for(section))
        for name, then in branches.items():
            declared = {o.key: o for o in FORMATS[name].options(section)}
            flat = {}
            for key, sub in then["properties"].items():
                if "properties" in sub:
                    flat.update({f"{key}.{inner}": leaf for inner, leaf in sub["properties"].items()})
                else:
                    flat[key] = sub
            assert set(flat) == set(declared), (section, name)
            for key, option in declared.items():
                leaf = flat[key]
                if option.default is not REQUIRED and option.default is not None:
                    assert leaf["default"] == option.default, (section, name, key)
                if option.choices:
                    assert leaf["enum"] == list(option.choices), (section, name, key)
                top = key.split(".")[0]
                required_here = (then["properties"][top].get("required", []) if "." in key else then["required"])
                assert (key.split(".")[-1] in required_here) == (option.default is REQUIRED), (section, name, key)
            names = set(then["propertyNames"]["enum"])
            assert names == set(COMMON_KEYS[section]) | {k.split(".")[0] for k in declared}


def test_the_loaders_key_sets_come_from_the_schema():
    sets = key_sets()
    assert sets["imu.columns"] == {"count", "time", "accel", "gyro"}
    assert sets["outages"] == {"first_after_s", "length_s", "period_s", "end_margin_s", "windows"}
    assert "parameters" in sets[""] and "parameters" not in sets  # any parameter name: the model checks them


def test_the_documentation_page_carries_the_schemas_key_table():
    page = PAGE.read_text(encoding="utf-8")
    assert with_key_table(page) == page, "python -m modelgen.navigator.config_schema docs/replay-configuration.md"
    for path, _node in keys():
        assert f"| `{path}` |" in page, path


def test_every_key_the_documentation_and_readme_name_exists_in_the_schema():
    """Backticked key paths (`imu.gap_action`, `outages.windows` ...) in the replay pages and the README's section."""
    known = {path.split(" (")[0] for path, _ in keys()}
    sections = set(load_schema()["properties"])
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    own_logs = readme.split("## Flying your own logs", 1)[1].split("\n## ", 1)[0]
    texts = {"README.md": own_logs, **{p.name: p.read_text(encoding="utf-8")
                                       for p in (PAGE, REPO / "docs" / "replay.md")}}
    named = 0
    for name, text in texts.items():
        for token in re.findall(r"`([a-z_]+(?:\.[a-z0-9_*]+)+)`", text):
            if token.split(".")[0] not in sections:
                continue
            named += 1
            if token.endswith(".*"):
                assert any(k.startswith(token[:-1]) for k in known), (name, token)
            else:
                assert token in known, (name, token)
    assert named >= 30


def test_replay_help_points_to_the_documentation():
    from click.testing import CliRunner

    from modelgen.navigator.cli import replay

    text = CliRunner().invoke(replay, ["--help"]).output
    assert "Flying your own logs" in text and "docs/replay-configuration.md" in text
    assert "README" in text and "replay_config.schema.json" in text


def test_key_table_has_a_row_with_unit_and_default_for_each_numeric_key():
    table = key_table_markdown()
    assert "| `imu.gap_factor` | number > 0 |  | `3.0` |" in table
    assert "| `alignment.rest_window_s` | number > 0 | s | required |" in table
    assert "| `noise.gyro_white.unit` |" in table
