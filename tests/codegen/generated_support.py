"""Generate, compile and load a model's Python and C in a temporary folder (shared by the codegen tests)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from modelgen.codegen.build import CompiledFilter, compile_shared_library, load_python_module
from modelgen.codegen.generate import GeneratedCode, generate_code
from modelgen.codegen.layout import ModelSizes
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel, derive
from modelgen.model.loading import load_model_text


@dataclass
class Built:
    """One model's generated code, written, compiled and loaded."""

    derived: DerivedModel
    code: GeneratedCode
    folder: Path
    python: ModuleType
    library: Path

    def c_filter(self, options: CodegenOptions) -> CompiledFilter:
        model = self.derived.model
        return CompiledFilter(self.library, model.name, ModelSizes.of(self.derived), model.parameter_names, options=options)


def write_files(folder: Path, files: dict[str, str]) -> Path:
    """Write generated files plainly (the tests do not exercise the atomic writer)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (folder / name).write_text(text, encoding="utf-8", newline="\n")
    return folder


def build(derived: DerivedModel, folder: Path, options: CodegenOptions | None = None) -> Built:
    """Generate ``derived`` with ``options`` into ``folder``, compile its C strictly, import its Python.

    The library comes through the suite's compile cache (tests/conftest.py: private to the run, shared by its
    workers): the same generated C at -O1 is compiled once in a run, wherever another test compiled it first
    (tests/codegen/test_options.py compiles every option combination of the paper's model).
    """
    options = options or CodegenOptions()
    code = generate_code(derived, options)
    write_files(folder, code.files)
    name = derived.model.name
    library = compile_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so", ("-O1",), cache=True)
    return Built(derived, code, folder, load_python_module(folder / f"{name}.py"), library)


def build_text(text: str, folder: Path, options: CodegenOptions | None = None) -> Built:
    """As :func:`build`, from the YAML text of a model file."""
    return build(derive(load_model_text(text, filename="m.yaml")), folder, options)
