"""The trajectory cache: bit for bit the generated flight, mapped read-only, never trusting or replacing a bad file."""

import types
from pathlib import Path

import numpy as np
import pytest

from modelgen.simulation import trajectory_cache
from modelgen.simulation.scenario import load_profile
from modelgen.simulation.trajectory import generate_trajectory
from modelgen.simulation.trajectory_cache import cached_trajectory, entry_paths, trajectory_key

IMU_RATE, RECORD_RATE = 50.0, 1.0


@pytest.fixture(scope="module")
def path():
    """36 s of the paper's flight (its first segments), 1,800 IMU samples at 50 Hz."""
    return load_profile("profile_000").with_changes(hours=0.01).path


@pytest.fixture(scope="module")
def made(path):
    return generate_trajectory(path, IMU_RATE, RECORD_RATE)


def same_flight(a, b) -> bool:
    return (a.record_every == b.record_every and a.imu_rate == b.imu_rate and np.array_equal(a.truth, b.truth)
            and np.array_equal(a.delta_theta, b.delta_theta) and np.array_equal(a.delta_velocity, b.delta_velocity))


def entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def test_a_cached_trajectory_is_bit_for_bit_the_generated_one_and_read_only(path, made, tmp_path):
    first = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)  # made and kept
    again = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)  # mapped from the entry
    key = trajectory_key(path, IMU_RATE, RECORD_RATE)
    assert entries(tmp_path) == [f"{key}.trajectory"]
    for trajectory in (first, again):
        assert same_flight(trajectory, made) and not trajectory.streamed
        for array in (trajectory.truth, trajectory.delta_theta, trajectory.delta_velocity):
            with pytest.raises(ValueError, match="read-only"):
                array[0, 0] = 1.0


def test_a_kept_flight_is_mapped_not_made_again(path, made, tmp_path, monkeypatch):
    cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)

    def refuse(*args, **kwargs):
        raise AssertionError("the trajectory was made again")

    monkeypatch.setattr(trajectory_cache, "generate_trajectory", refuse)
    mapped = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)
    assert same_flight(mapped, made)
    assert any(isinstance(base, np.memmap) for base in _bases(mapped.delta_theta))


def _bases(array):
    while array is not None:
        yield array
        array = getattr(array, "base", None)


def test_other_rates_or_another_flight_make_another_entry(path, tmp_path):
    keys = {trajectory_key(path, IMU_RATE, RECORD_RATE), trajectory_key(path, 2 * IMU_RATE, RECORD_RATE),
            trajectory_key(path, IMU_RATE, 2 * RECORD_RATE), trajectory_key(path.truncated(30.0), IMU_RATE, RECORD_RATE)}
    assert len(keys) == 4
    cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)
    shorter = cached_trajectory(path.truncated(30.0), IMU_RATE, RECORD_RATE, tmp_path)
    assert len(entries(tmp_path)) == 2
    assert same_flight(shorter, generate_trajectory(path.truncated(30.0), IMU_RATE, RECORD_RATE))


def test_other_trajectory_code_makes_another_entry(path, tmp_path, monkeypatch):
    source = tmp_path / "trajectory_maths.py"
    source.write_text("x = 1\n")
    monkeypatch.setattr(trajectory_cache, "SOURCES", (types.SimpleNamespace(__name__="maths", __file__=str(source)),))
    before = trajectory_key(path, IMU_RATE, RECORD_RATE)
    source.write_text("x = 2\n")
    assert trajectory_key(path, IMU_RATE, RECORD_RATE) != before


def test_a_damaged_entry_is_left_alone_and_the_flight_made_again_under_the_next_name(path, made, tmp_path):
    cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)
    first, second = entry_paths(tmp_path, trajectory_key(path, IMU_RATE, RECORD_RATE))[:2]
    damaged = bytearray(first.read_bytes())
    damaged[-5] ^= 0x40  # one bit of the last increment
    first.write_bytes(bytes(damaged))
    again = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)
    assert same_flight(again, made)
    assert first.read_bytes() == bytes(damaged) and second.exists()
    cut = tmp_path / "cut-short"  # an entry cut short is not trusted either
    cut.write_bytes(second.read_bytes()[:-8])
    shapes = trajectory_cache._shapes(made.n_samples, made.record_every)
    key = trajectory_key(path, IMU_RATE, RECORD_RATE)
    assert trajectory_cache._mapped(second, key, shapes) is not None and trajectory_cache._mapped(cut, key, shapes) is None


def test_a_file_not_modelgens_at_an_entry_name_is_left_alone(path, made, tmp_path):
    name = entry_paths(tmp_path, trajectory_key(path, IMU_RATE, RECORD_RATE))[0]
    name.write_text("a user's notes\n")
    trajectory = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path)
    assert same_flight(trajectory, made) and name.read_text() == "a user's notes\n"
    assert len(entries(tmp_path)) == 2  # the user's file and the entry under the next name; no temporary file left


def test_two_workers_keeping_the_same_flight_leave_one_entry(path, made, tmp_path):
    shapes = trajectory_cache._shapes(made.n_samples, made.record_every)
    key = trajectory_key(path, IMU_RATE, RECORD_RATE)
    arrays = [made.truth, made.delta_theta, made.delta_velocity]
    a = trajectory_cache._store(tmp_path, key, arrays, shapes)
    b = trajectory_cache._store(tmp_path, key, arrays, shapes)  # the second finds the first's entry and uses it
    assert a is not None and b is not None and entries(tmp_path) == [f"{key}.trajectory"]
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_a_cache_that_cannot_be_written_or_a_flight_too_large_still_gives_the_trajectory(path, made, tmp_path,
                                                                                         monkeypatch):
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    trajectory = cached_trajectory(path, IMU_RATE, RECORD_RATE, blocked / "trajectories")
    assert same_flight(trajectory, made) and not trajectory.delta_theta.flags.writeable
    monkeypatch.setattr(trajectory_cache, "MAX_ENTRY_BYTES", 1000)
    large = cached_trajectory(path, IMU_RATE, RECORD_RATE, tmp_path / "cache")
    assert same_flight(large, made) and entries(tmp_path / "cache") == []


def test_the_cache_is_beside_the_compile_cache(tmp_path, monkeypatch):
    from modelgen.codegen.build import CACHE_ENV, library_cache_folder

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    assert trajectory_cache.trajectory_cache_folder() == tmp_path / "trajectories"
    assert library_cache_folder() == tmp_path / "libraries"


def test_every_field_of_the_flight_path_is_in_the_key(path):
    import dataclasses

    keys = {trajectory_key(path, IMU_RATE, RECORD_RATE)}
    for field in dataclasses.fields(path):
        if field.name not in ("name", "segments"):
            keys.add(trajectory_key(dataclasses.replace(path, **{field.name: getattr(path, field.name) + 1e-3}),
                                    IMU_RATE, RECORD_RATE))
    segment = path.segments[0]
    for field in dataclasses.fields(segment):
        if field.name != "name":
            changed = dataclasses.replace(segment, **{field.name: getattr(segment, field.name) + 1e-3})
            keys.add(trajectory_key(dataclasses.replace(path, segments=(changed, *path.segments[1:])), IMU_RATE, RECORD_RATE))
    assert len(keys) == 1 + (len(dataclasses.fields(path)) - 2) + (len(dataclasses.fields(segment)) - 1)
