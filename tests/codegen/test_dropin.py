"""The generated C folder drops into a build as it is: make, CMake, README example."""

import re
import shutil
import subprocess

import pytest

from modelgen.codegen.build import compiler
from modelgen.codegen.generate import generate_code, write_atomically
from modelgen.codegen.options import CodegenOptions

pytestmark = pytest.mark.compile


@pytest.fixture(scope="module")
def folder(paper_derived, tmp_path_factory):
    return write_atomically(tmp_path_factory.mktemp("dropin") / "ned_doppler18", generate_code(paper_derived).files)


def readme_example(folder):
    text = (folder / "README.md").read_text()
    blocks = re.findall(r"```c\n(.*?)```", text, re.S)
    assert len(blocks) == 1, "the README has one C usage example"
    return blocks[0]


def run(command, cwd):
    result = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    assert result.returncode == 0, f"{' '.join(command)}\n{result.stdout}\n{result.stderr}"
    return result


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_plain_makefile_builds_the_static_library(folder, tmp_path):
    work = shutil.copytree(folder, tmp_path / "make")
    run(["make", f"CC={compiler()}", "CFLAGS=-std=c99 -O1 -Wall -Wextra -Werror -pedantic"], work)
    assert (work / "libned_doppler18.a").is_file()


@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed")
def test_cmake_builds_the_library_and_the_readme_example_links_against_it(folder, tmp_path):
    # a consumer project that uses the folder through add_subdirectory, as the README says
    app = tmp_path / "app"
    app.mkdir()
    (app / "main.c").write_text(readme_example(folder))
    (app / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.10)\nproject(app C)\n"
        f"add_subdirectory({folder.as_posix()} filter)\n"
        "add_executable(app main.c)\ntarget_link_libraries(app PRIVATE ned_doppler18)\n"
    )
    build = tmp_path / "build"
    run(["cmake", "-S", str(app), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release", "-DCMAKE_C_FLAGS=-O1"], tmp_path)
    run(["cmake", "--build", str(build)], tmp_path)
    result = subprocess.run([str(build / "app")], capture_output=True)
    assert result.returncode in (0, 1, 2), "the example returns one of the documented status codes"


def test_readme_example_is_about_ten_lines_of_strict_c99(folder, tmp_path):
    example = readme_example(folder)
    body = example[example.index("int main(void)") :]
    statements = [line for line in body.splitlines() if line.strip() not in ("", "{", "}")]
    assert len(statements) <= 16
    source = tmp_path / "example.c"
    source.write_text(example)
    run([compiler(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I", str(folder), "-c", str(source), "-o", str(tmp_path / "example.o")], tmp_path)


@pytest.mark.parametrize("options", [CodegenOptions(scalar="float", form="ud"), CodegenOptions(storage="packed", update="sequential")], ids=lambda o: o.slug())
def test_readme_example_compiles_for_other_options(paper_derived, tmp_path, options):
    out = write_atomically(tmp_path / "f", generate_code(paper_derived, options).files)
    (tmp_path / "example.c").write_text(readme_example(out))
    run([compiler(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-I", str(out), "-o", str(tmp_path / "example"), str(tmp_path / "example.c"), str(out / "ned_doppler18.c"), "-lm"], tmp_path)
    assert subprocess.run([str(tmp_path / "example")]).returncode in (0, 1, 2)
