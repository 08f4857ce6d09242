"""The registry of aiding sensors: the profile's ``filter.aiding`` name -> its plug-in.

Each entry follows :class:`modelgen.simulation.aiding.AidingSensor` and lives
in one module: the Doppler radar (:mod:`modelgen.simulation.doppler`), the GPS
position/velocity receiver (:mod:`modelgen.simulation.gps`) and the GPS
pseudo-range receiver (:mod:`modelgen.simulation.pseudorange`).  Adding a
sensor is writing its module and calling :func:`register_sensor` (or adding it
to :data:`SENSORS` here); the profile loader, the flight and the report then
know it without any other change.
"""

from __future__ import annotations

from modelgen.errors import ModelError
from modelgen.simulation.aiding import AidingSensor
from modelgen.simulation.doppler import DOPPLER
from modelgen.simulation.gps import GPS
from modelgen.simulation.pseudorange import PSEUDORANGE

#: aiding name (profile ``filter.aiding`` and the profile section of its keys) -> plug-in
SENSORS: dict[str, AidingSensor] = {sensor.name: sensor for sensor in (DOPPLER, GPS, PSEUDORANGE)}


def register_sensor(sensor: AidingSensor) -> None:
    """Make ``sensor`` known to profiles by its name; a name already taken is refused."""
    if not sensor.name or sensor.name in SENSORS:
        raise ModelError(f"aiding sensor {sensor.name!r}: the name is empty or already registered")
    SENSORS[sensor.name] = sensor


def aiding_sensor(name: str) -> AidingSensor:
    """The plug-in registered as ``name``; an unknown name is refused with the known ones."""
    if name not in SENSORS:
        raise ModelError(f"aiding sensor {name!r} is not registered (known: {', '.join(SENSORS)})")
    return SENSORS[name]
