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
    backend_templates = sorted((REPO / "modelgen" / "codegen" / "backends").rglob("*.j2"))
    assert {p.parent.name for p in backend_templates} == {"templates", "harness"}
    for template in backend_templates:
        assert template.relative_to(REPO).as_posix() in names
    assert any(n.endswith("/navigator_source.c.j2") for n in names)
    assert not (REPO / "templates").exists(), "templates live with their backend, not at the repository root"
    for model in (REPO / "modelgen" / "models").glob("*.yaml"):
        assert f"modelgen/models/{model.name}" in names
    for data in (REPO / "modelgen" / "data").glob("*.yaml"):
        assert f"modelgen/data/{data.name}" in names
    shipped = [p for p in (REPO / "modelgen" / "data" / "drives").rglob("*") if p.is_file()]
    shipped += list((REPO / "modelgen" / "navigator" / "models").glob("*.yaml"))
    assert len(shipped) >= 5, "the recorded drive (logs, README, LICENSE) and the navigator's model"
    for path in shipped:  # modelgen replay with no arguments flies these after a plain pip install
        assert path.relative_to(REPO).as_posix() in names
    assert not any(n.startswith(("tests/", "generated/", "bench/")) for n in names)
