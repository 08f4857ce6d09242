"""summary.md says how a configuration's numbers were chosen only as far as the configuration itself says it."""

from __future__ import annotations

from pathlib import Path

from modelgen.navigator.config import builtin_config_path, load_config
from modelgen.navigator.report import _how_chosen, _tuning_lines

DATA = Path(__file__).parent / "data"


def test_a_configuration_without_a_tuning_record_is_not_credited_with_the_builtin_drives_tuning_stages():
    config = load_config(DATA / "excerpt.yaml")
    assert not config.tuning
    text = _how_chosen(config) + "\n".join(_tuning_lines(config))
    assert "states no tuning" in text
    assert "NIS" not in text and "stage" not in text and "autocorrelation" not in text


def test_the_builtin_drive_repeats_its_own_tuning_record_key_by_key():
    config = load_config(builtin_config_path())
    lines = _tuning_lines(config)
    assert "states no tuning" not in _how_chosen(config)
    for key, how in config.tuning.items():
        assert any(line.startswith(f"| {key} | ") for line in lines), key
