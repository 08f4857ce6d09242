"""Golden files: the paper's model generated once per option family, committed under generated/options/.

Only the default options are generated for every model (``generated/<model>/``);
without these a change to the UD, packed, sequential, standard-form or float
templates would never show as a diff.  Each folder holds the files that depend
on the options (the C header and source, its build files and README); the
Python module does not depend on them and lives in ``generated/<model>/``.
``tests/test_generated_up_to_date.py`` checks that they are what the generator
makes now.  Regenerate with ``python -m modelgen.codegen.golden generated/options``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from modelgen.codegen.generate import generate_code
from modelgen.codegen.options import CodegenOptions
from modelgen.fileio.output import write_atomically

#: The model of the golden files: the paper's.
GOLDEN_MODEL = "ned_doppler18"

#: One variant per option family, each differing from the default in that family alone
#: (and the single-precision UD filter of the embedded targets).
GOLDEN_OPTIONS: tuple[CodegenOptions, ...] = (
    CodegenOptions(scalar="float"),
    CodegenOptions(form="ud"),
    CodegenOptions(scalar="float", form="ud"),
    CodegenOptions(storage="packed"),
    CodegenOptions(update="sequential"),
    CodegenOptions(covariance_update="standard"),
)


def golden_files(derived) -> dict[str, dict[str, str]]:
    """Folder name (``<model>_<options slug>``) -> file name -> text, for every golden variant."""
    out = {}
    for options in GOLDEN_OPTIONS:
        files = generate_code(derived, options).files
        out[f"{derived.model.name}_{options.slug()}"] = {
            name: text for name, text in files.items() if not name.endswith(".py")
        }
    return out


def write_golden_files(folder: Path) -> list[Path]:
    """Write every golden variant of the paper's model under ``folder`` (atomically, one folder each)."""
    from modelgen.derivation.symbolic import derive
    from modelgen.model.loading import load_model

    derived = derive(load_model(GOLDEN_MODEL))
    return [write_atomically(Path(folder) / name, files, force=True) for name, files in golden_files(derived).items()]


if __name__ == "__main__":  # python -m modelgen.codegen.golden [folder]
    for path in write_golden_files(Path(sys.argv[1] if len(sys.argv) > 1 else "generated/options")):
        print(f"wrote {path}")
