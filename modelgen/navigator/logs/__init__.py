"""The recorded logs a replay flies: one reader per format behind one registry.

Formats (docs/log-formats.md): IMU as CSV (:mod:`.imu_csv`), GNSS as an RTKLIB
.pos solution (:mod:`.rtklib_pos`), and both from a PX4 ULog (:mod:`.ulog`)
or a ROS 2 bag (:mod:`.ros2bag`); the aiding sensors' own logs (odometer,
barometer) as time-and-value CSV (:mod:`.scalar_csv`).  Every reader returns the same records
(:mod:`.records`: SI units, GPS time), and the format-independent checks
(:mod:`.checks`: IMU gaps, GNSS fixes) apply to all of them alike.

The interface with the navigator loop, for IMU gaps: ``ImuLog.gaps`` lists
every interval longer than ``imu.gap_factor`` times the median interval.  By
default (``imu.gap_action: refuse``) such a log is refused.  With
``propagate`` the log is handed on with its gaps, and the navigator must (1)
propagate the covariance over each gap's whole length, and (2) apply no GNSS
epoch that falls inside a gap (``navigator.prepare`` drops them, noted,
using :func:`.checks.epochs_inside_gaps`), so that epochs are never stacked
on the first sample after a gap.
"""

from modelgen.navigator.logs.checks import (GAP_ACTIONS, apply_gap_policy, check_gnss_fixes, check_logs,
                                            epochs_inside_gaps, find_gaps)
from modelgen.navigator.logs.files import MAX_LOG_BYTES
from modelgen.navigator.logs.formats import LogFormat, LogSource, Option
from modelgen.navigator.logs.imu_csv import ImuColumns, read_imu_csv
from modelgen.navigator.logs.records import ACCEL_UNITS, GYRO_UNITS, STANDARD_GRAVITY, GnssLog, ImuGap, ImuLog
from modelgen.navigator.logs.registry import (FORMATS, SCALAR_STREAMS, read_gnss, read_imu, read_scalar, schema,
                                              source_from_config)
from modelgen.navigator.logs.scalar_csv import ScalarLog
from modelgen.navigator.logs.rtklib_pos import read_rtklib_pos

__all__ = ["ACCEL_UNITS", "FORMATS", "GAP_ACTIONS", "GYRO_UNITS", "MAX_LOG_BYTES", "STANDARD_GRAVITY", "GnssLog",
           "ImuColumns", "ImuGap", "ImuLog", "LogFormat", "LogSource", "Option", "apply_gap_policy",
           "check_gnss_fixes", "check_logs", "epochs_inside_gaps", "find_gaps", "read_gnss", "read_imu", "read_imu_csv",
           "read_scalar", "ScalarLog", "SCALAR_STREAMS",
           "read_rtklib_pos", "schema", "source_from_config"]
