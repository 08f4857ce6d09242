"""modelgen's version: the one place it is written.

Generated files, manifests and the navigator's build cache record it; the
package root re-exports it as ``modelgen.__version__``.  It sits at the
floor of the layering (imports nothing), so every part may read it while
the package root itself stays free to offer the Python API on top.
"""

__version__ = "0.1.0"
