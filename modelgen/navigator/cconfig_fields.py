"""One field of the C navigator's configuration struct (:mod:`modelgen.navigator.cconfig` lists them all)."""

from __future__ import annotations

from dataclasses import dataclass

#: the fewest samples of a detector window (ZUPT, still detector): the sample counts are rounded up to it, and the
#: C refuses fewer (the bound of those fields)
WINDOW_SAMPLES_MIN = 2


@dataclass(frozen=True)
class Field:
    """One configuration field: name, C type (double or int), count (1, a number, or "P") and meaning with unit.

    Where its value may lie (checked by the generated ``<model>_navigator_config_check`` and by
    :func:`modelgen.navigator.cconfig.check`, both from :func:`modelgen.navigator.cconfig.bounds`):

    * ``key``: the replay configuration key the value comes from; the bounds of its node in
      ``modelgen/data/replay_config.schema.json`` (minimum, exclusiveMinimum, maximum, exclusiveMaximum; boolean and
      two-choice keys as 0 or 1; integers) apply to the value, mapped by ``scale``;
    * ``scale``: value = key value x scale (a positive number: the unit), ``"positive"`` (times further positive
      factors: only a bound at 0 carries over) or ``"chi2"`` (the chi-square quantile of a probability: 0 -> 0,
      1 -> infinity);
    * ``absent``: a value meaning "not given" (allowed besides the bounds);
    * ``minimum`` / ``maximum``: a derived value's own bounds (no key): a number or a header capacity
      (``"WINDOW_MAX"``, ``"REST_MAX"``: ``<P>_NAV_WINDOW_MAX`` ...);
    * ``not_above``: another field this one must not exceed;
    * ``origin``: the key a derived value (no ``key``) is computed from, named when it is refused.

    Every double must also be finite unless its upper bound is an included infinity.
    """

    name: str
    ctype: str
    count: int | str
    meaning: str
    key: str = ""
    scale: float | str = 1.0
    absent: float | None = None
    minimum: int | str | None = None
    maximum: int | str | None = None
    not_above: str = ""
    origin: str = ""
