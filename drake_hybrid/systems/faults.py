"""Faults injected into a simulation, to measure how the controller survives them.

``SensorFaultInjector``
    between the wrench sensor and what reads it: white noise, a constant bias, and dropouts
    (NaN samples, or stale ones: the sensor repeats its last sample), random or at given times.
    It also outputs the sensor's sequence number (a packet counter that does not advance on a
    stale sample), which ``wrench_conditioner.WrenchConditioner`` uses to reject stale samples.
``JointFriction``
    Coulomb friction in the simulated arm's joints, -tau_c tanh(v / v_s) (viscous friction is
    the joints' damping, set by ``tasks.config.ModelErrorConfig.joint_damping``).

Both act on the simulation only; the controller's model knows nothing of them. The noise and
the random dropouts are functions of the seed and the sample index only, so a run is
reproducible and a sample reads the same whenever it is evaluated. Their AutoDiffXd instances
compute on values (an injected fault has no derivative); ``JointFriction`` differentiates.
"""

import math
import sys
from dataclasses import dataclass, field
from typing import List

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import tanh as drake_tanh
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.errors import ConfigError, DimensionError, check_fields
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.templates import default_instantiation

DROPOUT_KINDS = ("nan", "stale")
_BLOCK = 4096          # samples of noise drawn at once (per seed and block index)


@dataclass
class SensorFaultConfig:
    """Faults of the wrench sensor (``ScenarioConfig.sensor_faults``); all off by default.

    noise_std: standard deviation (N) of white noise on each force component [f].
    torque_noise_std: the same (N m) on each torque component [n].
    bias: a constant [n; f] (6 entries, N m and N, world frame) added to every sample; empty = none.
    dropout_probability: per sample, the chance that a dropout of ``dropout_samples`` begins.
    dropout_samples: length of a random dropout (samples).
    dropout_times: start times (s) of scheduled dropouts, each ``dropout_duration`` long.
    dropout_duration: s, the length of each scheduled dropout.
    dropout_kind: "nan" (the sample is NaN) or "stale" (the last sample is repeated).
    seed: of the noise and the random dropouts.
    """

    noise_std: float = 0.0
    torque_noise_std: float = 0.0
    bias: List[float] = field(default_factory=list)
    dropout_probability: float = 0.0
    dropout_samples: int = 1
    dropout_times: List[float] = field(default_factory=list)
    dropout_duration: float = 0.0
    dropout_kind: str = "nan"
    seed: int = 0

    def active(self):
        return bool(self.noise_std > 0 or self.torque_noise_std > 0 or any(b != 0 for b in self.bias)
                    or self.dropout_probability > 0 or (self.dropout_times and self.dropout_duration > 0))

    def validate(self):
        """ValueError (or DimensionError) naming the first bad field."""
        check_fields(self, "sensor_faults.", nonnegative=("noise_std", "torque_noise_std", "dropout_duration"))
        if self.bias and len(self.bias) != 6:
            raise DimensionError(f"sensor_faults.bias must have 6 entries [n; f] or none, got {len(self.bias)}")
        if not 0 <= float(self.dropout_probability) <= 1:
            raise ConfigError(f"sensor_faults.dropout_probability must be in [0, 1], got {self.dropout_probability}")
        if int(self.dropout_samples) < 1:
            raise ConfigError(f"sensor_faults.dropout_samples must be >= 1, got {self.dropout_samples}")
        if self.dropout_kind not in DROPOUT_KINDS:
            raise ConfigError(f"sensor_faults.dropout_kind must be one of {DROPOUT_KINDS}, got '{self.dropout_kind}'")
        return self


@TemplateSystem.define("SensorFaultInjector_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def SensorFaultInjector_(T):

    class Impl(LeafSystem_[T]):
        """A faulty wrench sensor: the ideal wrench in, the faulty samples and a sequence number out.

        .. pydrake_system::

            name: SensorFaultInjector
            input_ports:
            - wrench
            output_ports:
            - faulty_wrench
            - sequence

        Sample k is the reading of the plant step at k h (the wrench input is constant from
        k h until the next step): index k = floor(t / h). Its value is

            wrench + bias + noise_k           (fresh)
            NaN                               (a "nan" dropout)
            the previous sample's value       (a "stale" dropout; the sequence does not advance)

        with noise_k ~ N(0, diag(torque_noise_std^2 I, noise_std^2 I)), a function of the seed and
        k. State: [last emitted sample (6), sequence], advanced at the controller's tick.

        Args:
            config: SensorFaultConfig.
            period: the sampling period h (s), normally the control period.
        """

        def _construct(self, config, period, converter=None):
            LeafSystem_[T].__init__(self, converter)
            config.validate()
            if not (period is not None and float(period) > 0):
                raise ValueError(f"SensorFaultInjector: period must be positive, got {period}")
            self.config, self.period = config, float(period)
            self._bias = np.asarray(config.bias, dtype=float) if config.bias else np.zeros(6)
            self._scale = np.array([config.torque_noise_std] * 3 + [config.noise_std] * 3, dtype=float)
            self._blocks = {}
            self._input = self.DeclareVectorInputPort("wrench", 6)
            self.DeclareDiscreteState(7)
            declare_periodic_update(self, self.period, tick_offset(self.period), self._update)
            self.DeclareVectorOutputPort("faulty_wrench", 6, self._calc_wrench)
            self.DeclareVectorOutputPort("sequence", 1, self._calc_sequence)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.config, other.period, converter=converter)

        # -- the sample sequence (pure functions of the seed and k) ---------------------------------
        def sample_index(self, time):
            return int(math.floor(float(value(time)) / self.period + 1e-9))

        def _random_block(self, block):
            # Deterministic in (seed, block); shared by every context, like a table of constants.
            if block not in self._blocks:
                generator = np.random.default_rng([int(self.config.seed), int(block)])
                self._blocks[block] = (generator.standard_normal((_BLOCK, 6)), generator.random(_BLOCK))
            return self._blocks[block]

        def noise(self, k):
            normal, _ = self._random_block(k // _BLOCK)
            return self._scale * normal[k % _BLOCK]

        def _dropout_starts(self, k):
            _, uniform = self._random_block(k // _BLOCK)
            return uniform[k % _BLOCK] < self.config.dropout_probability

        def dropped(self, k):
            """True if sample k is lost (random or scheduled dropout)."""
            config = self.config
            if config.dropout_probability > 0 and any(
                    self._dropout_starts(j) for j in range(max(0, k - int(config.dropout_samples) + 1), k + 1)):
                return True
            t = k * self.period
            return any(start - 1e-12 <= t < start + config.dropout_duration - 1e-12 for start in config.dropout_times)

        def _sample(self, context):
            """(emitted sample, new sequence) for the sample at ``context``'s time."""
            k = self.sample_index(context.get_time())
            state = value(context.get_discrete_state(0).CopyToVector())
            last, sequence = state[:6], state[6]
            if self.dropped(k):
                if self.config.dropout_kind == "nan":
                    return np.full(6, np.nan), sequence
                return last, sequence
            return value(self._input.Eval(context)) + self._bias + self.noise(k), sequence + 1.0

        def _calc_wrench(self, context, output):
            output.SetFromVector(self._sample(context)[0])

        def _calc_sequence(self, context, output):
            output.SetFromVector([self._sample(context)[1]])

        def _update(self, context, discrete_state):
            sample, sequence = self._sample(context)
            state = value(context.get_discrete_state(0).CopyToVector())
            last = sample if all_finite(sample) else state[:6]
            discrete_state.get_mutable_vector(0).SetFromVector(np.concatenate([last, [sequence]]))

        def set_initial_sample(self, context, wrench):
            """Start with ``wrench`` as the last emitted sample (what a stale first sample repeats)."""
            context.get_mutable_discrete_state(0).SetFromVector(np.concatenate([value(np.asarray(wrench)), [0.0]]))

    return Impl


SensorFaultInjector = default_instantiation(SensorFaultInjector_)


@TemplateSystem.define("JointFriction_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def JointFriction_(T):

    class Impl(LeafSystem_[T]):
        """Coulomb friction -tau_c tanh(v / v_s) in the joints of one model instance.

        .. pydrake_system::

            name: JointFriction
            input_ports:
            - state
            output_ports:
            - generalized_force

        ``state`` is the instance's [q; v]; ``generalized_force`` has the size of the whole
        plant's velocities (for ``plant.get_applied_generalized_force_input_port()``), zero
        outside the instance. v_s regularizes the discontinuity at v = 0; on a discrete plant the
        force is explicit, so keep tau_c / v_s well below (joint inertia) / (time step).

        Args:
            plant: the simulation plant (finalized).
            model_instance: the arm.
            coulomb: tau_c (N m), a scalar or one entry per joint of the instance.
            regularization_speed: v_s (rad/s).
        """

        def _construct(self, plant, model_instance, coulomb, regularization_speed=0.05, converter=None):
            LeafSystem_[T].__init__(self, converter)
            n = plant.num_velocities(model_instance)
            tau_c = np.full(n, float(coulomb)) if np.ndim(coulomb) == 0 else np.asarray(coulomb, dtype=float)
            if tau_c.shape != (n,):
                raise DimensionError(f"JointFriction: coulomb must be a scalar or have {n} entries, got {tau_c.shape}")
            if np.any(tau_c < 0) or not float(regularization_speed) > 0:
                raise ValueError(f"JointFriction: coulomb must be >= 0 and regularization_speed positive, got "
                                 f"{tau_c.tolist()}, {regularization_speed}")
            self._plant, self._instance = plant, model_instance
            self.coulomb, self.regularization_speed = tau_c, float(regularization_speed)
            self._indices = plant.GetVelocitiesFromArray(model_instance, np.arange(plant.num_velocities())).astype(int)
            self._size, self._n = plant.num_velocities(), n
            self.DeclareVectorInputPort("state", 2 * n)
            self.DeclareVectorOutputPort("generalized_force", self._size, self._calc)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._plant, other._instance, other.coulomb, other.regularization_speed,
                            converter=converter)

        def _calc(self, context, output):
            ratio = self.get_input_port(0).Eval(context)[self._n:] / self.regularization_speed
            smooth_sign = np.tanh(ratio) if ratio.dtype != object else np.array([drake_tanh(r) for r in ratio])
            force = np.zeros(self._size, dtype=ratio.dtype)
            force[self._indices] = -self.coulomb * smooth_sign
            output.SetFromVector(force)

    return Impl


JointFriction = default_instantiation(JointFriction_)
