"""The toolchain helpers read stack, call graph, link maps and driver output correctly."""

import numpy as np
import pytest

from modelgen.codegen import toolchain
from modelgen.errors import ModelError


def test_stack_usage_and_call_graph_are_read_from_gcc_files(tmp_path):
    (tmp_path / "a.su").write_text("a.c:3:5:main\t40\tstatic\na.c:9:6:leaf\t16\tstatic\na.c:12:6:grow\t8\tdynamic\n")
    (tmp_path / "a.ci").write_text(
        'graph: { title: "a.c"\nnode: { title: "main" label: "main" }\n'
        'edge: { sourcename: "main" targetname: "leaf" label: "a.c:4:3" }\n'
        'edge: { sourcename: "main" targetname: "grow" label: "a.c:5:3" }\n}\n'
    )
    frames, edges = toolchain.read_stack_usage(tmp_path)
    assert frames == {"main": (40, "static"), "leaf": (16, "static"), "grow": (8, "dynamic")}
    assert edges == {"main": {"leaf", "grow"}}
    assert toolchain.worst_case_stack("main", {k: v[0] for k, v in frames.items()}, edges) == 56


def test_worst_case_stack_refuses_recursion():
    with pytest.raises(ModelError, match="recursion"):
        toolchain.worst_case_stack("a", {"a": 8, "b": 8}, {"a": {"b"}, "b": {"a"}})


def test_forbidden_symbols_are_looked_for_only_in_what_was_linked(tmp_path):
    map_file = tmp_path / "x.map"
    map_file.write_text(
        "Discarded input sections\n .text.malloc 0x0 0x10 libc.a(malloc.o)\n"
        "Linker script and memory map\n .text.main 0x8000 0x20 main.o\n 0x8000 main\n .text.printf 0x8020 0x40 libc.a(printf.o)\n 0x8020 printf\n"
    )
    assert toolchain.forbidden_symbols_in_map(map_file) == ["printf"]


@pytest.mark.parametrize("scalar,ud", [("double", False), ("float", True)])
def test_driver_output_is_split_into_steps(scalar, ud):
    n = 3
    dtype = np.float64 if scalar == "double" else np.float32
    records = []
    for k in range(2):
        x = np.arange(n) + k
        P = np.eye(n) * (k + 1)
        parts = [np.array([0, 2 * k], dtype=np.int32).tobytes(), x.astype(dtype).tobytes(), P.astype(dtype).tobytes()]
        if ud:
            parts.append(np.full(n, 0.5 + k, dtype=dtype).tobytes())
        records.append(b"".join(parts))
    steps = toolchain.decode_run(b"".join(records), n, scalar, ud)
    assert len(steps) == 2 and steps[1].update_status == 2
    assert np.array_equal(steps[1].x, np.arange(n) + 1) and np.array_equal(steps[1].P, 2 * np.eye(n))
    assert (steps[1].D is not None) == ud
    with pytest.raises(ModelError, match="whole number"):
        toolchain.decode_run(b"".join(records)[:-1], n, scalar, ud)


def test_scenario_encoding_has_the_driver_layout():
    data = toolchain.encode_scenario(2, np.ones(4), 60.0, np.zeros(3), np.eye(3), np.zeros((2, 2)), "float")
    assert len(data) == 4 + 4 * (4 + 1 + 3 + 9 + 4)
    assert np.frombuffer(data[:4], dtype=np.int32)[0] == 2
