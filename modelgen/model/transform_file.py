"""Model files that make a new state set from an existing model.

Such a file names a ``base`` model (built-in name or a path relative to the
file) and a list of ``transforms`` applied in order, so that a reduced or
augmented filter goes through the whole pipeline with one command::

    model: ned_doppler13_reduced
    title: Suboptimal filter I of the core paper (13 states)
    base: ned_doppler18
    transforms:
      - markov_to_white: {states: [nabla_x, nabla_y, nabla_z]}
      - augment:
          states: [{name: doppler_scale_factor, symbol: k_d}]
          equations: {k_d: "0"}
          measurement_terms: {Z_n: "V_n*k_d", Z_e: "V_e*k_d"}

The steps are the functions of ``modelgen.model.transform`` with the same names and
arguments.  Errors name the file, the line and the step.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Mapping

from modelgen.model import transform
from modelgen.model.check_scenario import build_check_spec, merge_check_sections, parse_check_section
from modelgen.errors import ModelError
from modelgen.model.declaration import ErrorModel, Noise, Parameter, State, check_free_text, check_identifier
from modelgen.model.file_fields import free_text, notes_text

TOP_KEYS = {"model", "title", "base", "transforms", "notes", "source", "check"}
STEPS = {
    "keep_states": {"states", "measurements"},
    "markov_to_white": {"states", "strength"},
    "augment": {"states", "equations", "noises", "parameters", "measurement_terms"},
}


def _items(cls: type, raw: Any, where: str, lines: Mapping[str, str] | None = None, key: str = "") -> list:
    """The declarations of an ``augment`` list; each carries the line of its entry (``lines[key[j]]``) as its place."""
    if raw is None:
        return []
    if not isinstance(raw, list) or not all(isinstance(e, dict) and "name" in e for e in raw):
        raise ModelError(f"{where}: must be a list of mappings, each with a 'name'")
    lines = lines or {}
    try:
        return [cls(**{k: (str(v) if k in {"psd", "expression", "variance"} else v) for k, v in e.items()},
                    places={"": lines[f"{key}[{j}]"]} if lines.get(f"{key}[{j}]") else {})
                for j, e in enumerate(raw)]
    except TypeError as exc:
        raise ModelError(f"{where}: {exc}") from None


def _names(raw: Any, where: str) -> list[str]:
    if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
        raise ModelError(f"{where}: must be a list of state names")
    return raw


def _apply(model: ErrorModel, step: str, args: Mapping[str, Any], where: str, lines: Mapping[str, str] | None = None,
           key: str = "") -> ErrorModel:
    """One transformation step; intermediate models get generated names; ``key``: the step's key in ``lines``."""
    try:
        if step == "keep_states":
            return transform.keep_states(
                model, _names(args.get("states"), f"{where}.states"), name=f"{model.name}_kept", measurements=args.get("measurements")
            )
        if step == "markov_to_white":
            return transform.markov_to_white(
                model,
                _names(args.get("states"), f"{where}.states"),
                name=f"{model.name}_white",
                strength=args.get("strength", "low_frequency"),
            )
        return transform.augment(
            model,
            _items(State, args.get("states"), f"{where}.states", lines, f"{key}.states"),
            equations={k: str(v) for k, v in (args.get("equations") or {}).items()},
            noises=_items(Noise, args.get("noises"), f"{where}.noises", lines, f"{key}.noises"),
            parameters=_items(Parameter, args.get("parameters"), f"{where}.parameters", lines, f"{key}.parameters"),
            measurement_terms={k: str(v) for k, v in (args.get("measurement_terms") or {}).items()} or None,
            name=f"{model.name}_augmented",
        )
    except ModelError as exc:
        raise ModelError(f"{where}: {exc}") from None


def load_transformed_model(
    data: Mapping[str, Any], lines: Mapping[str, str], filename: str, load_base: Callable[[str | Path], ErrorModel]
) -> ErrorModel:
    """Build the model a transform file describes (see module doc)."""
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise ModelError(f"{lines.get(unknown[0], filename)}: unknown key {unknown[0]!r} (expected one of {sorted(TOP_KEYS)})")
    if "model" not in data:
        raise ModelError(f"{filename}: missing required key 'model'")
    base = str(data["base"])
    relative = Path(filename).parent / base
    model = load_base(relative if relative.suffix in (".yaml", ".yml") and relative.exists() else base)
    base_check = model.check
    steps = data.get("transforms") or []
    if not isinstance(steps, list):
        raise ModelError(f"{lines.get('transforms', filename)}: 'transforms' must be a list of steps")
    for i, entry in enumerate(steps):
        where = f"{lines.get(f'transforms[{i}]', filename)}: transforms[{i}]"
        if not isinstance(entry, dict) or len(entry) != 1:
            raise ModelError(f"{where}: each step is a mapping with one key, one of {sorted(STEPS)}")
        ((step, args),) = entry.items()
        if step not in STEPS:
            raise ModelError(f"{where}: unknown transformation {step!r} (expected one of {sorted(STEPS)})")
        args = args or {}
        extra = sorted(set(args) - STEPS[step])
        if extra:
            raise ModelError(f"{where}: {step} has unknown argument {extra[0]!r} (allowed: {sorted(STEPS[step])})")
        model = _apply(model, step, args, f"{where} ({step})", lines, f"transforms[{i}].{step}")
    name = str(data["model"])
    check_identifier(name, f"{lines.get('model', filename)}: model name", model_name=True)
    title = free_text(data, "title", lines, filename, model.title)
    source = free_text(data, "source", lines, filename, f"{model.source}; transformed from {base}")
    notes = notes_text(data, lines, filename)
    for key, text in (("title", title), ("source", source), *((f"notes[{i}]", n) for i, n in enumerate(notes))):
        check_free_text(text, f"{lines.get(key, lines.get(key.split('[')[0], filename))}: model {name!r}, {key}", multiline=key != "title")
    model = replace(model, check=inherited_check(base_check, data, lines, filename, model))
    return replace(
        model,
        name=name,
        title=title,
        source=source,
        notes=(*model.notes, *notes),
    )


def inherited_check(base_check: Any, data: Mapping[str, Any], lines: Mapping[str, str], filename: str, model: ErrorModel) -> Any:
    """The base model's check scenario with this file's ``check:`` laid over it (modelgen.model.check_scenario).

    Without a ``check:`` of its own the file inherits the base's scenario when
    that still gives every parameter and state a value, and has none otherwise
    (an added state needs a sigma only the file can give); with one, the
    merged scenario must be complete.
    """
    own = parse_check_section(data["check"], lines, filename) if "check" in data else None
    if own is not None:  # this file's own names must exist; only inherited ones may name removed states
        build_check_spec({"step_s": 1.0, "steps": 1, **own, "parameters": own.get("parameters", {})}, model, lines.get("check", filename), partial=True)
    merged = merge_check_sections(base_check.as_section() if base_check is not None else None, own)
    if own is None:
        try:  # the base's scenario, if it still covers every state and parameter; else none (synthetic, labelled)
            return build_check_spec(merged, model, lines.get("check", filename), inherited=True)
        except ModelError:
            return None
    return build_check_spec(merged, model, lines.get("check", filename), inherited=True)
