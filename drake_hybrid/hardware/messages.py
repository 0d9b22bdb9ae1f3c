"""What the controller and the robot say to each other over LCM, and the limits the controller's
side enforces on it.

Channels (Drake's and drake-franka-driver's defaults)::

    PANDA_STATUS   lcmt_panda_status    robot -> controller   q, v, tau_ext (utime in us)
    PANDA_COMMAND  lcmt_panda_command   controller -> robot   joint torques (CONTROL_MODE_TORQUE)
    FT_SENSOR      lcmt_force_torque    robot -> controller   wrench in the sensor frame (timestamp in us)

Torque commands follow the Franka driver's convention: the driver adds its own gravity
compensation, so the command is the law's actuation *minus* the gravity torque g(q) the law
includes (``HardwareConfig.driver_compensates_gravity``).

The F/T message carries the wrench the tool exerts on the wrist through the sensor, at the
sensor's origin, expressed in the sensor frame (the weld between wrist and tool), plus the
sensor's bias; tool weight and bias are removed on the controller's side
(``wrench.ForceTorqueConditioning``).
"""

import enum
import math
from dataclasses import dataclass, field
from typing import List, Optional

from drake_hybrid.core.errors import ConfigError

STATUS_CHANNEL = "PANDA_STATUS"
COMMAND_CHANNEL = "PANDA_COMMAND"
FORCE_TORQUE_CHANNEL = "FT_SENSOR"

# Franka Panda: joint torque limits (N m) and torque-rate limit (N m / s) of the robot's datasheet.
PANDA_TORQUE_LIMITS = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
PANDA_TORQUE_RATE_LIMIT = 1000.0


class HardwareFault(enum.IntEnum):
    """Why the controller's side stopped commanding (0: it did not). Stops latch: a stopped
    controller stays stopped until it is restarted."""

    NONE = 0
    WAITING_FOR_STATUS = 1      # no valid status yet: nothing is published
    STATUS_STALE = 2            # the newest valid status is older than max_status_age: zero task torque
    FORCE_TORQUE_STALE = 3      # the newest valid F/T reading is older than max_force_torque_age: hold


class Rejection(enum.IntEnum):
    """Why a message was rejected (the held values age; a stop follows when they are too old)."""

    NONE = 0
    NON_FINITE = 1              # a NaN or inf field
    WRONG_SIZE = 2              # num_joints differs from the arm's
    OUT_OF_ORDER = 3            # its timestamp is older than the newest accepted one


@dataclass
class HardwareConfig:
    """The controller's side on a real arm: channels, wrench source, message ages and command limits.

    ``wrench_source``: "force_torque" (an lcmt_force_torque sensor in the wrist weld) or
    "external_torque" (no F/T sensor: the driver's external-torque estimate mapped to a wrench at
    the end-effector point through J^-T, least squares for a redundant arm)."""

    wrench_source: str = "force_torque"
    status_channel: str = STATUS_CHANNEL
    command_channel: str = COMMAND_CHANNEL
    force_torque_channel: str = FORCE_TORQUE_CHANNEL
    max_status_age: float = 0.01                 # s: older -> STATUS_STALE (zero task torque)
    max_force_torque_age: float = 0.01           # s: older -> FORCE_TORQUE_STALE (hold)
    torque_limits: Optional[List[float]] = None  # N m per joint (None: the plant's effort limits)
    torque_rate_limit: float = PANDA_TORQUE_RATE_LIMIT   # N m / s, every joint
    hold_stiffness: float = 50.0                 # N m / rad, the joint-space hold after an F/T stop
    hold_damping: float = 5.0                    # N m s / rad
    driver_compensates_gravity: bool = True      # the Franka driver adds g(q) itself
    force_torque_bias: List[float] = field(default_factory=lambda: [0.0] * 6)   # [t; f] in the sensor frame
    damping_time_step: float = 0.0               # s: the robot's discrete step for its model joint damping
                                                 # (control.damping); 0 on a real arm, the plant's in a HIL test

    def validate(self, prefix="hardware."):
        if self.wrench_source not in ("force_torque", "external_torque"):
            raise ConfigError(f"{prefix}wrench_source must be 'force_torque' or 'external_torque', "
                              f"got {self.wrench_source!r}")
        for name in ("max_status_age", "max_force_torque_age", "torque_rate_limit"):
            number = getattr(self, name)
            if not (isinstance(number, (int, float)) and number > 0 and math.isfinite(number)):
                raise ConfigError(f"{prefix}{name} must be a positive finite number, got {number!r}")
        for name in ("hold_stiffness", "hold_damping", "damping_time_step"):
            number = getattr(self, name)
            if not (isinstance(number, (int, float)) and number >= 0 and math.isfinite(number)):
                raise ConfigError(f"{prefix}{name} must be a finite number >= 0, got {number!r}")
        if self.torque_limits is not None and not all(isinstance(x, (int, float)) and x > 0 and math.isfinite(x)
                                                      for x in self.torque_limits):
            raise ConfigError(f"{prefix}torque_limits must be positive finite numbers (N m), got {self.torque_limits}")
        if len(self.force_torque_bias) != 6 or not all(math.isfinite(x) for x in self.force_torque_bias):
            raise ConfigError(f"{prefix}force_torque_bias must be 6 finite numbers [tx, ty, tz, fx, fy, fz], "
                              f"got {self.force_torque_bias}")
        for name in ("status_channel", "command_channel", "force_torque_channel"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ConfigError(f"{prefix}{name} must be a non-empty channel name, got {getattr(self, name)!r}")
        return self


def microseconds(time):
    """An LCM timestamp (int64 us) of ``time`` (s)."""
    return int(round(float(time) * 1e6))
