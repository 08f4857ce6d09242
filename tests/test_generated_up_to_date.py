"""The committed generated/ is exactly what the generator produces now.

The comparison holds for the sympy and jinja2 releases in constraints.txt (they
shape the generated text); CI installs exactly those.  With other releases the
comparison is skipped and says why, since a difference would then say nothing
about the generator.
"""

from importlib.metadata import version

import pytest

from modelgen.codegen.generate import generate_code
from modelgen.derive.symbolic import derive
from modelgen.model.loading import builtin_models, load_model
from modelgen.fileio.output import MANIFEST_NAME

from conftest import REPO


def _pinned_versions() -> dict[str, str]:
    pins = {}
    for line in (REPO / "constraints.txt").read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if "==" in line:
            package, release = line.split("==")
            pins[package.strip()] = release.strip()
    return pins


def test_constraints_pin_the_packages_that_shape_generated_text():
    assert set(_pinned_versions()) == {"sympy", "jinja2"}


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_code_matches_generator(name):
    mismatched = {p: (v, version(p)) for p, v in _pinned_versions().items() if version(p) != v}
    if mismatched:
        pytest.skip(f"generated/ was made with {mismatched} (pinned, installed): install with -c constraints.txt")
    folder = REPO / "generated" / name
    assert folder.is_dir(), f"generated/{name} is missing: run `modelgen generate --all`"
    files = generate_code(derive(load_model(name))).files
    committed = {p.name for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
    assert committed == set(files), f"generated/{name}: files differ; run `modelgen generate --all`"
    for filename, text in files.items():
        assert (folder / filename).read_text(encoding="utf-8") == text, (
            f"generated/{name}/{filename} is stale: run `modelgen generate --all` and commit"
        )


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_code_records_the_pinned_sympy_and_jinja2(name):
    pins = _pinned_versions()
    stamp = f"(sympy {pins['sympy']}, jinja2 {pins['jinja2']})"
    for filename in (f"{name}.h", f"{name}.c", f"{name}.py", "README.md"):
        assert stamp in (REPO / "generated" / name / filename).read_text(encoding="utf-8"), (
            f"generated/{name}/{filename} does not say it was made with the pinned {stamp}"
        )


def test_no_generated_folder_without_a_model():
    models = set(builtin_models()) | {"options"}
    stray = [p.name for p in (REPO / "generated").iterdir() if p.is_dir() and p.name not in models]
    assert not stray, f"generated/ has folders for unknown models: {stray}"


@pytest.fixture(scope="module")
def golden():
    from modelgen.codegen.golden import GOLDEN_MODEL, golden_files

    return golden_files(derive(load_model(GOLDEN_MODEL)))


def test_every_option_family_has_a_committed_golden_folder_and_no_other(golden):
    """float, UD, packed, sequential and standard form each differ from the default files."""
    from modelgen.codegen.golden import GOLDEN_OPTIONS
    from modelgen.codegen.options import FORMS, SCALARS, STORAGES, UPDATES

    covered = {(o.scalar, o.form, o.storage, o.update, o.covariance_update) for o in GOLDEN_OPTIONS}
    for family, values in (("scalar", SCALARS), ("form", FORMS), ("storage", STORAGES), ("update", UPDATES)):
        index = ("scalar", "form", "storage", "update").index(family)
        assert {c[index] for c in covered} | {"double", "covariance", "full", "vector"} >= set(values), family
    assert {c[4] for c in covered} >= {"standard"}
    on_disk = {p.name for p in (REPO / "generated" / "options").iterdir() if p.is_dir()}
    assert on_disk == set(golden), "generated/options differs: run `python -m modelgen.codegen.golden generated/options`"


def test_committed_option_golden_files_match_generator(golden):
    mismatched = {p: (v, version(p)) for p, v in _pinned_versions().items() if version(p) != v}
    if mismatched:
        pytest.skip(f"generated/ was made with {mismatched} (pinned, installed): install with -c constraints.txt")
    for folder_name, files in golden.items():
        folder = REPO / "generated" / "options" / folder_name
        committed = {p.name for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
        assert committed == set(files), f"generated/options/{folder_name}: files differ"
        for filename, text in files.items():
            assert (folder / filename).read_text(encoding="utf-8") == text, (
                f"generated/options/{folder_name}/{filename} is stale: "
                "run `python -m modelgen.codegen.golden generated/options` and commit"
            )


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_folder_has_a_manifest_of_exactly_its_files(name):
    """Without it, `modelgen run` on a fresh clone would refuse to replace generated/<model>/ (issue 10, item 6)."""
    from modelgen.fileio.output import read_manifest, sha256_file

    folder = REPO / "generated" / name
    manifest = read_manifest(folder)
    assert manifest is not None, f"generated/{name} has no {MANIFEST_NAME}: run `modelgen generate --all --force` once"
    on_disk = {p.name: sha256_file(p) for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
    assert manifest == on_disk, f"generated/{name}/{MANIFEST_NAME} does not match the files: run `modelgen generate --all`"
