"""Code generation: a derived model and its options become a verified Python module and C99 filter.

The language-neutral part lives here (``structure`` of the sparse matrices,
``expressions`` after CSE, ``kernels`` as descriptions of targets and terms,
``layout`` sizes, ``options``, ``contract``, gathered in ``description``);
``backends/c`` and ``backends/python`` print it through their printers and
templates, ``generate`` renders every backend and ``golden`` the per-option
golden files; ``build`` and ``toolchain`` compile and load the C for the checks.
"""
