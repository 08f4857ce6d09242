"""The one exception type users see for bad input."""


class ModelError(ValueError):
    """A model, model file, scenario or measurement is malformed.

    The message always names the problem and where it is (file, key, line,
    equation), so that it can be shown to the user as it is.
    """
