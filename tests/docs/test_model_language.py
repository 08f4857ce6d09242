"""The model language page (docs/model-language.md): its error message is what modelgen prints, its transform works.

(Its model examples load, and those with a check scenario pass `generate --check`: tests/docs/test_examples.py.)
"""

import re

from click.testing import CliRunner

from docs.pages import page_text, yaml_block
from modelgen.cli import main


def test_the_documented_error_message_is_what_modelgen_prints(tmp_path):
    path = tmp_path / "schuler_loop.yaml"
    model = yaml_block("model-language.md", "model: schuler_loop")
    path.write_text(model.replace("dV_n: g*phi_e + nabla", "dV_n: g*phi_e + nablaa"), encoding="utf-8")
    result = CliRunner().invoke(main, ["generate", str(path), "--out", str(tmp_path / "gen")])
    assert result.exit_code == 2
    line, message = re.search(r"modelgen: error: schuler_loop\.yaml:(\d+): (.*)", page_text("model-language.md")).groups()
    assert f"{path}:{line}: {message}" in result.output
    assert not (tmp_path / "gen").exists()


def test_the_transform_example_builds_a_14_state_model(tmp_path):
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    path = tmp_path / "reduced.yaml"
    path.write_text(yaml_block("model-language.md", "model: ned_doppler13_reduced"), encoding="utf-8")
    derived = derive(load_model(path))
    assert derived.n_states == 14 and derived.model.state_names[-1] == "doppler_scale_factor"
