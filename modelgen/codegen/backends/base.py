"""The interface every backend implements: ``Backend`` and the jinja2 environment of its templates."""


from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Protocol

import jinja2
import numpy as np

from modelgen.codegen.description import FilterDescription
from modelgen.codegen.escape import FILTERS
from modelgen.codegen.kernels import OperationCount
from modelgen.codegen.options import CodegenOptions
from modelgen.derivation.symbolic import DerivedModel, parameter_vector
from modelgen.errors import ModelError


class Scenario(Protocol):
    """What :meth:`Backend.run` flies: a constant operating point for ``len(measurements(derived))`` filter cycles.

    ``modelgen.checks.code_check.CheckScenario`` is one; the backends know it
    only by these members (codegen sits below checks).
    """

    parameters: Mapping[str, float]
    initial_covariance: np.ndarray
    step: float

    def x0(self) -> np.ndarray: ...

    def measurements(self, derived: DerivedModel) -> np.ndarray: ...


def named_parameters(derived: DerivedModel, scenario: Scenario) -> dict[str, float]:
    """Every parameter of the scenario by its spelled-out name, the model's defaults filled in."""
    values = parameter_vector(derived.model, scenario.parameters)
    return dict(zip(derived.model.parameter_names, values))


class BackendUnavailable(ModelError):
    """A backend's toolchain is missing on this machine (no C++ compiler): its run is skipped, with a warning."""


#: x and P after every step of a scenario.
Trajectory = list[tuple[np.ndarray, np.ndarray]]

#: (folder of the generated files, derived model, scenario, the options they were generated with, a build folder or None)
Runner = Callable[[Path, DerivedModel, Scenario, CodegenOptions, "Path | None"], Trajectory]
#: (folder of the generated files, derived model, the options, the run's build folder): builds ahead what run builds
Preparer = Callable[[Path, DerivedModel, CodegenOptions, Path], None]


@functools.lru_cache(maxsize=None)
def environment(*folders: Path) -> jinja2.Environment:
    """The templates' environment over ``folders``, with one escaping filter per output language (``escape``).

    One per set of folders and process, so that each template is compiled once (compiling
    them is about 40 % of generating the paper's model); jinja2 reloads a template whose
    file changed, and rendering has no state, so the output never depends on what ran before.
    """
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader([str(f) for f in folders]),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,  # HTML escaping: none of the output languages is HTML (see escape)
    )
    env.filters.update(FILTERS)
    return env


@dataclass(frozen=True)
class Backend:
    """One output language: its context builder, template folders and file list.

    ``files`` maps an output file name (``{p}`` is the model's name) to the
    product template that renders it; ``harness`` holds the templates that
    drive or test the product and are rendered on request only.
    """

    name: str
    context: Callable[[FilterDescription], dict[str, object]]
    templates: Path
    files: tuple[tuple[str, str], ...]
    harness: Path | None = None
    finish: Callable[[str, str], str] | None = None  # (file name, text) -> text, e.g. line wrapping
    verbatim: tuple[Path, ...] = ()  # files of the product copied byte for byte (the C runtime)
    runner: Runner | None = None  # flies a scenario through the built product (run)
    counter: Callable[[FilterDescription], dict[str, OperationCount]] | None = None  # its own operation counts (costs)
    preparer: Preparer | None = None  # builds ahead, in another thread, through the compile cache (prepare)

    def run(self, folder: Path, derived: DerivedModel, scenario: Scenario, options: CodegenOptions | None = None,
            build_dir: Path | None = None) -> Trajectory:
        """x and P after every step of ``scenario``, by this backend's files in ``folder`` (built and loaded as a user would).

        ``options`` are those the files were generated with; ``build_dir``
        keeps what a compiled language builds (None: a temporary folder).
        Raises ValueError or ModelError when the product refuses an input of
        the scenario (the contract).
        """
        if self.runner is None:
            raise NotImplementedError(f"backend {self.name!r} cannot run a scenario")
        return self.runner(Path(folder), derived, scenario, options or CodegenOptions(), build_dir)

    def prepare(self, folder: Path, derived: DerivedModel, options: CodegenOptions, build_dir: Path) -> None:
        """Build now, through the compile cache, what :meth:`run` in ``build_dir`` will build (a compiler process:
        another thread may run it while this one does other work); run then takes it from the cache.  Nothing
        for a backend that builds nothing; a build that fails here fails again, and is reported, in run."""
        if self.preparer is not None:
            self.preparer(Path(folder), derived, options, Path(build_dir))

    def costs(self, description: FilterDescription) -> dict[str, OperationCount]:
        """The operation counts of this backend's own kernels (``predict (C)``), written into every file header."""
        return self.counter(description) if self.counter is not None else {}

    def environment(self) -> jinja2.Environment:
        """The jinja2 environment over the product (and harness) templates."""
        return environment(*[f for f in (self.templates, self.harness) if f is not None])

    def render(self, description: FilterDescription) -> dict[str, str]:
        """Every product file of this backend for one filter: file name -> text."""
        env, context = self.environment(), self.context(description)
        name = description.model.name
        files = {file.format(p=name): env.get_template(t).render(context) for file, t in self.files}
        if self.finish is not None:
            files = {file: self.finish(file, text) for file, text in files.items()}
        files.update({path.name: path.read_text(encoding="utf-8") for path in self.verbatim})
        return files

    def render_template(self, description: FilterDescription, template: str, **extra: object) -> str:
        """One more template (harness or product) with this backend's context and ``extra``."""
        return self.environment().get_template(template).render({**self.context(description), **extra})
