"""A non-editable install ships the templates, models and data files, under the distribution's own name."""

import os
import subprocess
import sys
import tomllib
import venv
import zipfile

import pytest

from conftest import REPO

#: the distribution's name on PyPI (``modelgen`` there is another project); the import name stays ``modelgen``
DISTRIBUTION = "modelgen-nav"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel pip builds from this checkout (no build isolation: hatchling is a test dependency)."""
    folder = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(folder), str(REPO)],
        check=True,
    )
    (built,) = folder.glob("*.whl")
    return built


def test_distribution_is_named_modelgen_nav_and_every_install_line_uses_it():
    """pyproject's name is the free one, its extras refer to it, and no document tells users to install `modelgen`."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["name"] == DISTRIBUTION
    assert project["scripts"] == {"modelgen": "modelgen.cli:main"}
    assert f"{DISTRIBUTION}[sim,parquet,docs,logs]" in project["optional-dependencies"]["test"]
    documents = [REPO / "README.md", *(REPO / "docs").rglob("*.md"), *(REPO / "modelgen").rglob("*.py")]
    wrong = [f"{path.relative_to(REPO)}: {line.strip()}" for path in documents
             for line in path.read_text(encoding="utf-8").splitlines()
             if "pip install modelgen" in line.replace("'", "").replace("`", "") and DISTRIBUTION not in line]
    assert wrong == []


def test_wheel_contains_templates_models_data_and_py_typed(wheel):
    assert wheel.name.startswith("modelgen_nav-")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "modelgen/py.typed" in names  # PEP 561: the annotations are for type checkers of users' code too
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
    shipped += list((REPO / "modelgen" / "data" / "mechanizations").glob("*.yaml"))  # modelgen run cross-checks these
    assert len(shipped) >= 5, "the recorded drive (logs, README, LICENSE) and the navigator's model"
    for path in shipped:  # modelgen replay with no arguments flies these after a plain pip install
        assert path.relative_to(REPO).as_posix() in names
    assert not any(n.startswith(("tests/", "generated/", "bench/", "docs/")) for n in names)
    metadata = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(metadata).decode()
    assert f"Name: {DISTRIBUTION}\n" in text


@pytest.mark.compile
def test_wheel_installs_into_a_fresh_venv_and_runs(wheel, tmp_path):
    """The wheel installed into a new virtual environment gives the `modelgen` command and the package.

    The venv sees the system's site-packages for the dependencies (installing
    numpy, sympy, CasADi ... afresh would take minutes and the network), but
    the wheel itself is installed into the venv with ``--no-deps``, and the
    test proves that the command and the import come from there, not from
    this checkout or an editable install.
    """
    home = tmp_path / "venv"
    venv.EnvBuilder(system_site_packages=True, with_pip=False).create(home)
    python = home / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index",
                    "--ignore-installed", "-q", str(wheel)], check=True, env=env, cwd=tmp_path)
    shown = subprocess.run([str(home / "bin" / "modelgen"), "--help"], capture_output=True, text=True, env=env,
                           cwd=tmp_path, check=True)
    assert "Turn inertial-navigation error models into verified Kalman-filter code" in shown.stdout
    assert "generate" in shown.stdout and "replay" in shown.stdout
    probe = ("import importlib.metadata, modelgen, modelgen.api; "
             "print(modelgen.__file__); print(importlib.metadata.version('modelgen-nav')); "
             "print(modelgen.load_model('ned_doppler18').name)")
    out = subprocess.run([str(python), "-c", probe], capture_output=True, text=True, env=env, cwd=tmp_path, check=True)
    location, version, model = out.stdout.split()
    assert location.startswith(str(home)), location
    assert version == tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["version"]
    assert model == "ned_doppler18"
