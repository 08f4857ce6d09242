"""The committed generated/ is exactly what the generator produces now.

The comparison holds for the sympy and jinja2 releases in constraints.txt (they
shape the generated text); CI installs exactly those.  With other releases the
comparison is skipped and says why, since a difference would then say nothing
about the generator.

The golden files (generated/<model>/ of every built-in model, as ``modelgen
generate --all --force`` writes them, and generated/options/) are regenerated
with one option: ``python -m pytest tests/test_generated_up_to_date.py
--regenerate-golden`` writes them from the generator, then checks them.
"""

from importlib.metadata import version

import pytest

from modelgen.codegen.generate import generate_code
from modelgen.model.loading import builtin_models
from modelgen.fileio.output import MANIFEST_NAME

from conftest import REPO

#: The one command that regenerates every golden file (then checks it).
REGENERATE = "python -m pytest tests/test_generated_up_to_date.py --regenerate-golden"


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


def _skip_unless_pinned_versions(regenerate: bool) -> None:
    mismatched = {p: (v, version(p)) for p, v in _pinned_versions().items() if version(p) != v}
    if mismatched and regenerate:
        pytest.fail(f"--regenerate-golden: generated/ is made with {mismatched} (pinned, installed): "
                    "install with -c constraints.txt first")
    if mismatched:
        pytest.skip(f"generated/ was made with {mismatched} (pinned, installed): install with -c constraints.txt")


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_code_matches_generator(name, derived_builtin, regenerate_golden):
    _skip_unless_pinned_versions(regenerate_golden)
    derived = derived_builtin(name)
    if regenerate_golden:
        from modelgen.jobs import generate

        generate(derived, REPO / "generated", force=True)  # what `modelgen generate --all --force` writes
    folder = REPO / "generated" / name
    assert folder.is_dir(), f"generated/{name} is missing: run `{REGENERATE}`"
    files = generate_code(derived).files
    committed = {p.name for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
    assert committed == set(files), f"generated/{name}: files differ; run `{REGENERATE}`"
    for filename, text in files.items():
        assert (folder / filename).read_text(encoding="utf-8") == text, (
            f"generated/{name}/{filename} is stale: run `{REGENERATE}` and commit"
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
def golden(derived_builtin, regenerate_golden):
    from modelgen.codegen.golden import GOLDEN_MODEL, golden_files, write_golden_files

    if regenerate_golden:
        _skip_unless_pinned_versions(regenerate_golden)
        write_golden_files(REPO / "generated" / "options")
    return golden_files(derived_builtin(GOLDEN_MODEL))


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
    assert on_disk == set(golden), f"generated/options differs: run `{REGENERATE}` (and remove folders of variants that are gone)"


def test_committed_option_golden_files_match_generator(golden):
    _skip_unless_pinned_versions(False)
    for folder_name, files in golden.items():
        folder = REPO / "generated" / "options" / folder_name
        committed = {p.name for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
        assert committed == set(files), f"generated/options/{folder_name}: files differ"
        for filename, text in files.items():
            assert (folder / filename).read_text(encoding="utf-8") == text, (
                f"generated/options/{folder_name}/{filename} is stale: "
                f"run `{REGENERATE}` and commit"
            )


@pytest.mark.parametrize("name", builtin_models())
def test_committed_generated_folder_has_a_manifest_of_exactly_its_files(name):
    """Without it, `modelgen run` on a fresh clone would refuse to replace generated/<model>/ (issue 10, item 6)."""
    from modelgen.fileio.output import read_manifest, sha256_file

    folder = REPO / "generated" / name
    manifest = read_manifest(folder)
    assert manifest is not None, f"generated/{name} has no {MANIFEST_NAME}: run `{REGENERATE}`"
    on_disk = {p.name: sha256_file(p) for p in folder.iterdir() if p.is_file() and p.name != MANIFEST_NAME}
    assert manifest == on_disk, f"generated/{name}/{MANIFEST_NAME} does not match the files: run `{REGENERATE}`"
