"""The committed generated/ is exactly what the generator produces now."""

import pytest

from modelgen.codegen.generate import generate_code
from modelgen.derivation import derive
from modelgen.modelfile import builtin_models, load_model

from conftest import REPO


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_code_matches_generator(name):
    folder = REPO / "generated" / name
    assert folder.is_dir(), f"generated/{name} is missing: run `modelgen generate --all`"
    files = generate_code(derive(load_model(name))).files
    committed = {p.name for p in folder.iterdir() if p.is_file()}
    assert committed == set(files), f"generated/{name}: files differ; run `modelgen generate --all`"
    for filename, text in files.items():
        assert (folder / filename).read_text(encoding="utf-8") == text, (
            f"generated/{name}/{filename} is stale: run `modelgen generate --all` and commit"
        )


def test_no_generated_folder_without_a_model():
    models = set(builtin_models())
    stray = [p.name for p in (REPO / "generated").iterdir() if p.is_dir() and p.name not in models]
    assert not stray, f"generated/ has folders for unknown models: {stray}"
