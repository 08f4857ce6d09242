"""C literals and the scalar type's spellings: the only place that knows ``1.0F`` and ``sqrtf``."""

from __future__ import annotations

from modelgen.codegen.backends.printing import scalar_value


def c_number(value: float | None, scalar: str) -> str:
    """A C floating literal of ``value`` (None counts as 0) in the scalar type (``F`` suffix for float).

    Rounded to the type first (``backends.printing.scalar_value``): 0 where it
    underflows, ModelError beyond the type's range, so that the literal compiles.
    """
    number = float(value or 0.0)
    text = repr(number if scalar_value(number, scalar) != 0.0 else 0.0)
    if "e" not in text and "." not in text:
        text += ".0"
    return text + ("F" if scalar == "float" else "")


def scalar_spellings(scalar: str) -> dict[str, str]:
    """Constants and math functions of the scalar type, by their template names."""
    single = scalar == "float"
    return {
        "one": "1.0F" if single else "1.0",
        "zero": "0.0F" if single else "0.0",
        "half": "0.5F" if single else "0.5",
        "sqrt": "sqrtf" if single else "sqrt",
        "fabs": "fabsf" if single else "fabs",
        "exp": "expf" if single else "exp",
        "ldexp": "ldexpf" if single else "ldexp",
        "frexp": "frexpf" if single else "frexp",
        "huge": "HUGE_VALF" if single else "HUGE_VAL",
        "epsilon": "FLT_EPSILON" if single else "DBL_EPSILON",
    }


def scalar_bytes(scalar: str) -> int:
    """Size of one scalar of the generated C (IEEE binary32 or binary64)."""
    return 4 if scalar == "float" else 8
