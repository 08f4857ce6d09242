"""The navigator's error-state filter: finding the model a configuration names."""

from __future__ import annotations

import re

import pytest

from modelgen.errors import ModelError
from modelgen.navigator.errorstate import model_path


def test_a_model_that_is_neither_built_in_nor_a_file_is_refused_naming_the_configuration_line(tmp_path):
    """Before: the configuration file alone, no line."""
    path = tmp_path / "replay.yaml"
    path.write_text("navigator: x\nmodel: no_such_model\n")
    with pytest.raises(ModelError, match=rf"^{re.escape(str(path))}:2: model 'no_such_model' is neither a built-in model nor a file"):
        model_path("no_such_model", str(path))
