"""The registry of aiding sensors: the profile's ``filter.aiding`` name -> its plug-in.

Each entry follows :class:`modelgen.simulation.aiding.AidingSensor` and lives
in one module: the Doppler radar (:mod:`modelgen.simulation.doppler`), the GPS
position/velocity receiver (:mod:`modelgen.simulation.gps`) and the GPS
pseudo-range receiver (:mod:`modelgen.simulation.pseudorange`).  The profile
loader, the flight and the report ask the profile's sensor object, so a new
sensor touches no other module.  How to add one:

1. Write its module: a settings dataclass (SI), a record of what it outputs per
   epoch (``times``, ``valid``...), and its plug-in.  A sensor of velocity
   and/or position subclasses
   :class:`~modelgen.simulation.ins_aiding.NavigationQuantitySensor` and gives
   ``name``, ``read_settings`` (its profile section, read with
   :class:`~modelgen.simulation.profile_keys.ProfileSection`), ``period``,
   ``noise_parameters``, ``simulate_at`` and ``fix``; any other sensor
   implements :class:`~modelgen.simulation.aiding.AidingSensor` with its own
   navigator, as ``pseudorange`` does.
2. Register it: add it to :data:`SENSORS` here, or call :func:`register_sensor`
   before loading a profile (tests/simulation/test_aiding_sensors.py flies a
   toy sensor that way).
3. In the profile: a section of the sensor's name, ``filter.aiding: <name>``
   and ``filter.measurements.<name>`` mapping the model's measurements to
   navigation quantities.
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
