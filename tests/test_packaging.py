"""A non-editable install ships the templates, models and data files."""

import subprocess
import sys
import zipfile

from conftest import REPO


def test_wheel_contains_templates_models_and_data(tmp_path):
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(tmp_path), str(REPO)],
        check=True,
    )
    (wheel,) = tmp_path.glob("modelgen-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for template in (REPO / "templates").glob("*.j2"):
        assert f"modelgen/templates/{template.name}" in names
    for model in (REPO / "modelgen" / "models").glob("*.yaml"):
        assert f"modelgen/models/{model.name}" in names
    for data in (REPO / "modelgen" / "data").glob("*.yaml"):
        assert f"modelgen/data/{data.name}" in names
    assert not any(n.startswith(("tests/", "generated/", "bench/")) for n in names)
