"""The README: its two commands are the ones CI runs; its model and library guarantees moved with the text.

The model language's examples and error message are held by tests/docs/test_model_language.py,
the navigation library's table by tests/docs/test_navigation_library.py, and every example of
the site by tests/docs/test_examples.py.
"""

import re

from conftest import REPO


def test_readme_test_command_is_what_ci_runs():
    """README's second command is the one .ci/run runs (CI runs what users are told to run)."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    commands = re.findall(r"```sh\n(pip install [^\n]+)\n```", readme)
    assert len(commands) == 2, commands
    assert commands[1] in (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert all("-c constraints.txt" in c for c in commands[:2])
