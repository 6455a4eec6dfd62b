"""Sensor error models: each a frozen dataclass of 1-sigma specifications in SI.

Every model has ``draw(rng)``, returning the run's random constants as a dataclass with
``as_dict()`` (JSON-friendly, for ``Metadata.true_errors``), and ``measure(errors, truth..., rng)``,
a pure function of its inputs producing the stream columns of ``navreplay.core.streams.FIELDS``.

========================  ===========================================  ====================
module                    model                                        stream
========================  ===========================================  ====================
:mod:`.imu`               strapdown gyro + accelerometer triads        imu
:mod:`.gps`               GNSS position fix and velocity               gps, gps_vel
:mod:`.magnetometer`      three-axis magnetometer, WMM earth field     mag
:mod:`.master_ins`        gimballed master INS (Euler, velocity)       master_ins
:mod:`.speed_log`         propeller-RPM speed log, sea current         speed_log
:mod:`.depth`             depth sensor                                 depth
:mod:`.noise`             white-noise conversions, Gauss-Markov, RW    -
:mod:`.specs`             the models as sensor specifications: TOML    -
                          tables in datasheet units, metadata
========================  ===========================================  ====================
"""

from navreplay.sensors.depth import DepthErrors, DepthModel  # noqa: F401
from navreplay.sensors.gps import GpsErrors, GpsMeasurement, GpsModel  # noqa: F401
from navreplay.sensors.imu import (  # noqa: F401
    ImuErrors,
    ImuGrade,
    ImuMeasurement,
    ImuModel,
    imu_grade,
)
from navreplay.sensors.magnetometer import (  # noqa: F401
    MagnetometerErrors,
    MagnetometerModel,
    WmmEpoch,
    decimal_year,
    earth_field_n,
)
from navreplay.sensors.master_ins import MasterInsErrors, MasterInsModel  # noqa: F401
from navreplay.sensors.speed_log import (  # noqa: F401
    SpeedLogErrors,
    SpeedLogModel,
    ground_velocity,
    rpm_axis_b,
    water_speed_along_axis,
)
