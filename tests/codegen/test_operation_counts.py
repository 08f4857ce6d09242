"""The operation counts printed in the headers agree with the code that is emitted.

Rule: ``predict (C): <mul> mul + <add> add`` counts the floating-point
operations of the unrolled prediction, so every ``*`` and every ``+`` in the
right-hand sides of its straight-line statements is counted: the state lines
``w->xn[i] = ...`` of ``<model>_predict`` and the statements of the static
kernel functions it calls (``phi_times_p_row_*``, ``propagate_row_*``,
``phi_times_u_row_*``); a row of M = Phi P printed as a loop over column pairs
counts its body once per pair.  The finiteness probes (``check += v - v``) and the
stores of a computed value (``... = v``) are not arithmetic of the filter and
are not counted.  In the UD form the Thornton sweep is a loop, not unrolled
text: its share is :func:`~modelgen.codegen.kernels.thornton_cost`, and the
rest must match the text.
"""

from __future__ import annotations

import re

import pytest

from modelgen.codegen.generate import generate_code
from modelgen.codegen.kernels import thornton_cost
from modelgen.codegen.options import CodegenOptions, all_combinations
from modelgen.codegen.structure import filter_structure

KERNEL = re.compile(r"^\w+ \w+ ((?:phi_times_p|propagate|phi_times_u)_row_\d+|state_predict)\(.*?\n\{\n(.*?)\n\}\n", re.S | re.M)


def _count(statements: list[str]) -> tuple[int, int]:
    """(``*``, ``+``) in the right-hand sides, two-lane products counted by lane, without probes and stores of ``v``."""
    mul = add = 0
    for statement in statements:
        statement = " ".join(statement.split())
        if not statement or statement.startswith("check +=") or "=" not in statement:
            continue
        target, value = statement.split(" = ", 1) if " = " in statement else ("", "")
        if value.strip() == "v" or target.endswith("scalar v, check"):
            continue
        # a two-lane product is two multiplications, adding it to the lanes two additions, summing the lanes one
        mul += value.count("*") + 2 * value.count("lane_pair_product(") + 2 * value.count("lane_pair_add_product(")
        add += value.count("+") + 2 * value.count("lane_pair_add_product(") + value.count("lane_pair_sum(")
    return mul, add


PAIR_LOOP = re.compile(r"for \(c = 0; c \+ 1 < (\d+); c \+= 2\) \{\n(.*?)\n    \}\n", re.S)


def _kernel_count(body: str) -> tuple[int, int]:
    """A kernel's count: its straight-line statements, a loop over column pairs (a row of M = Phi P) once per pair."""
    mul, add = 0, 0
    for trips, loop in PAIR_LOOP.findall(body):
        m, a = _count(loop.split(";"))
        mul, add = mul + m * (int(trips) // 2), add + a * (int(trips) // 2)
    m, a = _count(PAIR_LOOP.sub("", body).split(";"))
    return mul + m, add + a


def emitted_predict_count(source: str, model: str) -> tuple[int, int]:
    """Multiplications and additions written out in the predict of one generated C source."""
    kernels = [_kernel_count(body + "\n") for _, body in KERNEL.findall(source)]
    statements = []
    predict = source[source.index(f"int {model}_predict(") :]
    predict = predict[: predict.index("\n}\n")]
    predict = re.sub(r"/\*.*?\*/", "", predict, flags=re.S)  # a comment may precede the first statement
    # x_n = Phi x inline (UD); a statement may follow the closing brace of a loop before it
    statements += [t for s in predict.split(";") if (t := s.lstrip("{} \n\t")).startswith(("w->xn[", "acc = "))]
    mul, add = _count(statements)
    return mul + sum(m for m, _ in kernels), add + sum(a for _, a in kernels)


def printed_predict_count(header: str) -> tuple[int, int]:
    found = re.search(r"predict \(C\): (\d+) mul \+ (\d+) add", header)
    assert found, "the header prints no predict (C) count"
    return int(found.group(1)), int(found.group(2))


@pytest.mark.parametrize("name", ["ned_doppler18", "gps_pseudorange11", "ned_doppler32_augmented"])
@pytest.mark.parametrize(
    "options", [CodegenOptions(), CodegenOptions(storage="packed"), CodegenOptions(form="ud")], ids=lambda o: o.slug()
)
def test_printed_predict_count_is_the_count_of_the_emitted_statements(name, options, derived_builtin):
    derived = derived_builtin(name)
    files = generate_code(derived, options).files
    mul, add = emitted_predict_count(files[f"{name}.c"], name)
    printed_mul, printed_add = printed_predict_count(files[f"{name}.h"])
    if options.ud:
        sweep = thornton_cost(filter_structure(derived.structure("F"), derived.structure("G"), derived.structure("H"), 9))
        printed_mul, printed_add = printed_mul - sweep.multiplications, printed_add - sweep.additions
    assert (mul, add) == (printed_mul, printed_add)
    assert mul > 0


def test_every_option_prints_the_same_predict_count_as_its_source_says(paper_derived):
    for options in all_combinations("float"):
        files = generate_code(paper_derived, options).files
        assert printed_predict_count(files["ned_doppler18.h"]) == printed_predict_count(files["ned_doppler18.c"])


def test_the_count_rule_sees_a_changed_kernel(paper_derived):
    """A statement with one more product would change the count: the test can fail."""
    source = generate_code(paper_derived).files["ned_doppler18.c"]
    mul, add = emitted_predict_count(source, "ned_doppler18")
    tampered = source.replace("w->xn[0] = ", "w->xn[0] = t->Phi[0][0]*f->x[0] + ", 1)
    assert emitted_predict_count(tampered, "ned_doppler18") == (mul + 1, add + 1)


def test_small_blocks_are_static_and_large_ones_are_not_inlined(paper_derived):
    """A block of at most SMALL_BLOCK_TERMS (24) terms is a plain static function (the compiler inlines it); a larger one is <M>_BLOCK (noinline)."""
    source = generate_code(paper_derived).files["ned_doppler18.c"]
    found = {name: kind for kind, name in re.findall(r"^(static|NED_DOPPLER18_BLOCK) \w+ (\w+)\(", source, re.M)}
    assert found["phi_times_p_row_0"] == found["propagate_row_0"] == found["state_predict"] == "NED_DOPPLER18_BLOCK"
    assert found["process_noise_row_0"] == "NED_DOPPLER18_BLOCK"
    # rows of a random constant (7) and of a Markov state (10): a handful of terms each
    assert found["propagate_row_7"] == found["propagate_row_10"] == found["phi_times_p_row_10"] == "static"
    assert found["process_noise_row_10"] == "static"
