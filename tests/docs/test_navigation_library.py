"""docs/navigation-library.md documents every function and constant of the navigation library."""

from docs.pages import page_text
from modelgen.model.navlib import NAVLIB_CONSTANTS, NAVLIB_FUNCTIONS


def test_every_navigation_library_function_and_constant_is_documented():
    text = page_text("navigation-library.md")
    missing = [name for name in (*NAVLIB_FUNCTIONS, *NAVLIB_CONSTANTS) if f"`{name}" not in text]
    assert missing == []
