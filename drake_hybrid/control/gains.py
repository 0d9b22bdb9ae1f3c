"""Gains and modes of the hybrid control laws, validated.

The paper's gains (section 3):

====================  ==========  ======================  =================================
name (code)           symbol      size                    role
====================  ==========  ======================  =================================
velocity              K_v         (d-m) x (d-m)           velocity loop, eigenvalues -eig(K_v)
position              K_p         (d-m) x (d-m)           position/impedance modes (Remark 3, 3.2-6)
force_proportional    K_fp        m x m                   force loop, (I + K_fp) xi-dot + K_fi xi = 0
force_integral        K_fi        m x m                   force loop
force_damping         K_fd        m x m                   force rows' motion on a compliant contact: a_f = -K_fd C-dot
impedance_mass        M_d         (d-m) x (d-m)           impedance mode: M_d (e'' + K_v e' + K_p e) = F_v
null_space_damping    K_n         scalar (1/s)            n > d only: q-ddot_0 = -K_n q-dot
constraint_frequency  w_c         scalar (rad/s)          kinematic rows: C-ddot + 3 w_c C-dot + 2 w_c^2 C = 0
====================  ==========  ======================  =================================

Each gain may be given as a scalar (times I), a vector (diagonal) or a matrix.
``HybridGains`` stores them as flat lists (YAML-friendly): one entry means a
scalar times I, k entries a diagonal, k*k entries a full matrix (row-major).
K_v, K_p, K_fi and M_d must be symmetric positive definite and K_fp and K_fd symmetric
positive semidefinite; anything else raises ``GainError`` naming the gain. Each loop the gains
design must also be sane (``ValidatedGains.check_rates``, ``check_poles``): decay at ``MIN_RATE`` =
1e-6 1/s or faster (a gain of 1e-300 is positive definite in name only), be no faster than
``MAX_RATE`` = 1e6 1/s and, for a sampled controller of period h, than its sampling rate 1/h; K_fp
and M_d stay within a factor 1e6 of 1.

M_d is the impedance's mass along the velocity rows (kg, kg m^2 on a turning row). The paper's
impedance (3.2-1) has unit mass, the default: e'' + K_v e' + K_p e = F_v. A heavier M_d keeps
the roots K_v and K_p design and divides the force the impedance yields to by M_d
(K_0 = M_d^-1 - S, docs/theory.md §5): what keeps the roots where they are designed on a contact
that drags (docs/drake_notes.md, "The simulated contact's drag and the impedance's roots").

K_fd is not the paper's: its law commands no acceleration along the force rows (a_f = 0 in (3.0-11)),
which rigid contact enforces (E_f r-ddot = -E_f-dot r-dot, (3.0-7)). On a compliant contact the force
rows move, and with a_f = 0 nothing but the contact's own dissipation damps that motion: a row of
inertia Lambda on a contact of stiffness k and damping c closes as
Lambda s^3 + (Lambda K_fd + (1 + K_fp) c) s^2 + ((1 + K_fp) k + K_fi c) s + K_fi k = 0, whose fast pair
is unstable for Lambda K_fi / (1 + K_fp) > (1 + K_fp) c + Lambda K_fd (a flat tool's moment rows:
docs/disc.md). a_f = -K_fd C-dot (in contact) damps it and leaves the rigid-contact design as it is
(C-dot = 0 there); its price is the slow root's shift, to first order
s_0 Lambda s_0 (s_0 + K_fd) / ((1 + K_fp) k) with s_0 = -K_fi / (1 + K_fp): small where k is large.
Default 0: the paper's law.
"""

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

from drake_hybrid.core.arguments import describe, number, numeric_array
from drake_hybrid.core.errors import ArgumentError, GainError
from drake_hybrid.core.hints import Array


class ControlMode(enum.Enum):
    """The three laws of the paper."""

    VELOCITY_FORCE = "velocity-force"      # (3.1-12)
    POSITION_FORCE = "position-force"      # Remark 3
    IMPEDANCE_FORCE = "impedance-force"    # (3.2-6)

    @classmethod
    def parse(cls, mode: Union["ControlMode", str], owner: Optional[str] = None) -> "ControlMode":
        """``mode`` (a ControlMode or its value) as a ControlMode; ArgumentError (naming ``owner`` if given)."""
        if isinstance(mode, cls):
            return mode
        try:
            return cls(mode if owner is not None else str(mode))
        except ValueError:
            if owner is not None:
                raise ArgumentError(f"{owner}: mode must be one of {[m.value for m in cls]}, got {describe(mode)}") \
                    from None
            raise ArgumentError(f"unknown control mode '{mode}'; mode must be one of {[m.value for m in cls]}") \
                from None

    @property
    def integrates_position(self) -> bool:
        """True if the law uses e_p = integral of e_p' (and so needs K_p)."""
        return self is not ControlMode.VELOCITY_FORCE


# Sane bounds of a gain (the module docstring). A designed loop that decays slower than MIN_RATE (1/s)
# takes eleven days to converge, one faster than MAX_RATE is faster than any actuator. A sampled
# controller also realizes no loop as fast as its sampling rate 1/h: forward Euler's pole 1 - s h of a
# loop at s is then <= 0 (it overshoots at every tick, and is unstable beyond 2/h), so every designed
# |s| must stay within MAX_RATE_PERIOD / h.
MIN_RATE, MAX_RATE = 1e-6, 1e6
MAX_RATE_PERIOD = 1.0
MAX_RATIO = 1e6            # dimensionless gains (K_fp) and the impedance mass M_d (kg) relative to 1


def _given_form(array, given_shape):
    """How a gain was given, for a message: "is a scalar", "has k diagonal entries", "is a k x k matrix"."""
    shape = tuple(given_shape) if given_shape is not None else array.shape
    if len(shape) > 2:
        return f"is an array of shape {list(shape)}, not a scalar, a vector or a matrix"
    if len(shape) == 2:
        return f"is a {shape[0]}x{shape[1]} matrix"
    if len(shape) == 0 or array.size == 1:
        return "is a scalar"
    side = math.isqrt(array.size)
    if given_shape is None and side > 1 and side * side == array.size:
        return f"has {array.size} entries (a {side}x{side} matrix, flattened, or {array.size} diagonal entries)"
    return f"has {array.size} diagonal entries"


def gain_matrix(gain: ArrayLike, size: int, name: str, semidefinite: bool = False,
                given_shape: Optional[Tuple[int, ...]] = None) -> Array:
    """``gain`` as a symmetric size x size matrix; GainError if it is not (semi)definite.

    Accepts a scalar, a vector (diagonal), a matrix, or the flat lists that
    HybridGains stores (1, size or size*size entries); ``given_shape``: the shape the user gave
    (HybridGains keeps it), for the message. ``size`` 0 (no rows) gives the empty matrix."""
    size = number(size, "size", f"gain {name}", low=0, integer=True, error=GainError)
    array = numeric_array(gain, f"gain {name}", "HybridGains", error=GainError)
    wanted = (f"a scalar, {size} diagonal entries or a {size}x{size} matrix"
              + (f" ({size * size} entries, row-major)" if size > 1 else ""))
    if array.ndim == 1 and array.size == 1:
        array = array.reshape(())
    elif array.ndim == 1 and array.size == size * size and size > 1:
        array = array.reshape(size, size)
    if array.ndim == 0:
        matrix = float(array) * np.eye(size)
    elif array.ndim == 1 and array.size == size:
        matrix = np.diag(array)
    elif array.ndim == 2 and array.shape == (size, size):
        matrix = array.copy()
    else:
        rows = f"{size} row" + ("" if size == 1 else "s")
        raise GainError(f"gain {name} {_given_form(array, given_shape)}; for {rows} it must be {wanted}")
    if size == 0:
        return matrix
    if not np.allclose(matrix, matrix.T, rtol=0, atol=1e-12 * max(1.0, np.abs(matrix).max())):
        raise GainError(f"gain {name} must be symmetric, got {matrix.tolist()}")
    eigenvalues = np.linalg.eigvalsh(matrix)
    if semidefinite and eigenvalues.min() < 0:
        raise GainError(f"gain {name} must be positive semidefinite; its eigenvalues are {eigenvalues.tolist()}")
    if not semidefinite and eigenvalues.min() <= 0:
        raise GainError(f"gain {name} must be positive definite; its eigenvalues are {eigenvalues.tolist()}")
    return matrix


def _flat(gain):
    return [float(v) for v in np.asarray(gain, dtype=float).reshape(-1)]


GAIN_LISTS = ("velocity", "position", "force_proportional", "force_integral", "impedance_mass", "force_damping")


@dataclass
class HybridGains:
    """The paper's gains (see the module docstring). Give scalars, vectors or matrices; they are
    stored as flat lists (1, k or k*k entries). Every gain is checked here (numbers, finite; the
    scalars' signs) and against the task's sizes, definiteness and sane rates by ``matrices``
    (GainError naming the gain).

    velocity: K_v (1/s), the velocity rows' gain: in velocity-force mode each row's error decays as
        e^(-K_v t), the designed eigenvalues -eig(K_v).
    position: K_p (1/s^2), the position error's gain in position-force and impedance-force modes:
        each row's roots solve s^2 + K_v s + K_p = 0 (unused in velocity-force mode).
    force_proportional: K_fp (1, dimensionless), the force error's proportional gain.
    force_integral: K_fi (1/s), the force error's integral gain: each force row's eigenvalue is
        -K_fi / (1 + K_fp).
    force_damping: K_fd (1/s), not the paper's: the force rows' commanded acceleration a_f = -K_fd C-dot in
        contact (the module docstring), which damps a compliant contact's motion along them and leaves the
        rigid-contact eigenvalues as they are; 0 (default) is the paper's a_f = 0.
    null_space_damping: K_n (1/s), only for a redundant arm (n joints > d chart coordinates): the law
        adds -N^T M K_n q-dot, so the self-motion the task leaves free (J's null space) decays as
        e^(-K_n t) instead of drifting; unused when n = d.
    constraint_frequency: w_c (rad/s), the rows the controller holds itself (``kinematic_rows``,
        no force commanded): C-ddot + 3 w_c C-dot + 2 w_c^2 C = 0, roots -w_c and -2 w_c.
    impedance_mass: M_d (kg on a translational row, kg m^2 on a rotational one), the impedance's
        mass in impedance-force mode, M_d (e'' + K_v e' + K_p e) = F_v; 1 is the paper's unit mass.
    """

    velocity: List[float] = field(default_factory=lambda: [10.0])
    # K_p = 21: the position rows' roots s^2 + 10 s + 21 at -3 and -7, distinct (not the critically
    # damped double root -5 of K_p = 25): a linearization tells distinct roots apart (a double root
    # splits by the square root of any perturbation), and the slowest root's five time constants
    # bound the transient (a double root's (1 + 5) e^-5 = 4 % of the initial error is not within 2 %).
    position: List[float] = field(default_factory=lambda: [21.0])
    force_proportional: List[float] = field(default_factory=lambda: [0.5])
    force_integral: List[float] = field(default_factory=lambda: [15.0])
    force_damping: List[float] = field(default_factory=lambda: [0.0])    # K_fd (1/s): a_f = -K_fd C-dot; 0: paper
    null_space_damping: float = 10.0
    constraint_frequency: float = 15.0
    impedance_mass: List[float] = field(default_factory=lambda: [1.0])   # M_d, impedance mode; 1: the paper's

    def __post_init__(self):
        shapes = {}
        for name in GAIN_LISTS:
            array = numeric_array(getattr(self, name), name, "HybridGains", error=GainError)
            if array.ndim > 2:
                raise GainError(f"HybridGains: {name} must be a scalar, a vector (the diagonal) or a k x k matrix, got "
                                f"an array of shape {list(array.shape)}")
            shapes[name] = array.shape
            setattr(self, name, _flat(array))
        self._check_scalars()
        self._given_shapes = shapes          # how each gain was given (a k x k matrix or k entries), for messages

    def _check_scalars(self):
        """K_n >= 0 and w_c > 0, numbers within the sane rates (also after a field was set anew)."""
        self.null_space_damping = number(self.null_space_damping, "null_space_damping", "HybridGains", low=0.0,
                                         high=MAX_RATE, unit="1/s", error=GainError)
        self.constraint_frequency = number(self.constraint_frequency, "constraint_frequency", "HybridGains",
                                           low=MIN_RATE, high=MAX_RATE, unit="rad/s", error=GainError)

    def _matrix(self, name, size, label, semidefinite=False):
        return gain_matrix(getattr(self, name), size, label, semidefinite,
                           getattr(self, "_given_shapes", {}).get(name))

    def matrices(self, velocity_size: int, force_size: int, mode: Union[ControlMode, str],
                 control_period: Optional[float] = None) -> "ValidatedGains":
        """Validated matrices (K_v, K_p, K_fp, K_fi) for d - m = velocity_size, m = force_size; with a
        ``control_period`` h, every designed rate is also checked to stay below 1/h."""
        mode = ControlMode.parse(mode)
        K_v = self._matrix("velocity", velocity_size, "velocity (K_v)")
        K_p = (self._matrix("position", velocity_size, "position (K_p)") if mode.integrates_position
               else np.zeros((velocity_size, velocity_size)))
        K_fp = self._matrix("force_proportional", force_size, "force_proportional (K_fp)", semidefinite=True)
        K_fi = self._matrix("force_integral", force_size, "force_integral (K_fi)")
        self._check_scalars()
        M_d = self._matrix("impedance_mass", velocity_size, "impedance_mass (M_d)")
        K_fd = self._matrix("force_damping", force_size, "force_damping (K_fd)", semidefinite=True)
        gains = ValidatedGains(K_v, K_p, K_fp, K_fi, float(self.null_space_damping), float(self.constraint_frequency),
                               M_d, K_fd)
        gains.check_rates(mode, control_period)
        return gains

    def as_lists(self, velocity_size: int, force_size: int, mode: Union[ControlMode, str]) -> Dict[str, Any]:
        """The gains as nested lists (for summary.json), keyed as in the CLI's summary."""
        return self.matrices(velocity_size, force_size, mode).as_lists()


@dataclass
class ValidatedGains:
    velocity: Array
    position: Array
    force_proportional: Array
    force_integral: Array
    null_space_damping: float
    constraint_frequency: float
    impedance_mass: Optional[Array] = None     # M_d (k x k); None: the paper's unit mass (I once constructed)
    force_damping: Optional[Array] = None      # K_fd (m x m); None: zero, the paper's law (I once constructed)
    force_rate: Array = field(init=False)
    impedance_inverse_mass: Array = field(init=False)     # M_d^-1, the law's and the analyses'

    def __post_init__(self):
        if self.impedance_mass is None:
            self.impedance_mass = np.eye(self.velocity.shape[0])
        self.impedance_inverse_mass = np.linalg.inv(self.impedance_mass)
        # G = (I + K_fp)^-1 K_fi: the force loop's rate matrix (3.1-14).
        m = self.force_proportional.shape[0]
        self.force_rate = np.linalg.solve(np.eye(m) + self.force_proportional, self.force_integral)
        if self.force_damping is None:
            self.force_damping = np.zeros((m, m))

    def as_lists(self) -> Dict[str, Any]:
        """The matrices as nested lists (summary.json's ``gains``)."""
        assert self.impedance_mass is not None          # set by __post_init__
        return {"velocity": self.velocity.tolist(), "position": self.position.tolist(),
                "force_proportional": self.force_proportional.tolist(), "force_integral": self.force_integral.tolist(),
                "impedance_mass": self.impedance_mass.tolist(),
                "force_damping": np.asarray(self.force_damping).tolist()}

    def check_sizes(self, velocity_size: int, force_size: int, owner: str) -> "ValidatedGains":
        """ArgumentError naming ``owner`` unless K_v is k x k and K_fi m x m (matrices validated for other sizes)."""
        if self.velocity.shape != (velocity_size, velocity_size) or \
                self.force_integral.shape != (force_size, force_size):
            raise ArgumentError(f"{owner}: gains are matrices for k = {self.velocity.shape[0]} velocity and m = "
                                f"{self.force_integral.shape[0]} force rows; the constraint space has k = "
                                f"{velocity_size}, m = {force_size}")
        return self

    def designed_poles(self, mode: Union[ControlMode, str]) -> Dict[str, Array]:
        """{gain: the poles s (1/s) of the loops it designs}: the velocity rows' -eig(K_v) (or the roots of
        s^2 + K_v s + K_p), the force rows' -eig((I + K_fp)^-1 K_fi), the kinematic rows' -w_c and -2 w_c,
        the null space's -K_n (when > 0)."""
        k = self.velocity.shape[0]
        integrates = ControlMode.parse(mode).integrates_position
        if integrates and k:
            companion = np.block([[np.zeros((k, k)), np.eye(k)], [-self.position, -self.velocity]])
            velocity_rows = np.linalg.eigvals(companion)
        else:
            velocity_rows = -np.linalg.eigvals(self.velocity) if k else np.zeros(0)
        poles = {"velocity (K_v)" + (" and position (K_p)" if integrates else ""): velocity_rows,
                 "force_proportional (K_fp) and force_integral (K_fi)":
                     -np.linalg.eigvals(self.force_rate) if self.force_rate.size else np.zeros(0),
                 "constraint_frequency (w_c)": -np.array([self.constraint_frequency, 2 * self.constraint_frequency])}
        if self.null_space_damping > 0:
            poles["null_space_damping (K_n)"] = -np.array([self.null_space_damping])
        return poles

    def check_rates(self, mode: Union[ControlMode, str], control_period: Optional[float] = None) -> None:
        """GainError naming the gain whose designed loop is too fast or too slow (``check_poles``), whose
        K_fp or M_d is beyond a factor MAX_RATIO of 1, or whose K_fd damps faster than the rates allow (it
        designs no pole of the rigid-contact loop, but a rate beyond 1/h overshoots at every tick)."""
        assert self.impedance_mass is not None and self.force_damping is not None     # set by __post_init__
        for name, poles in self.designed_poles(mode).items():
            check_poles(poles, name, control_period)
        damping = np.linalg.eigvalsh(self.force_damping) if self.force_damping.size else np.zeros(0)
        high = MAX_RATE if control_period is None else min(MAX_RATE, MAX_RATE_PERIOD / float(control_period))
        if damping.size and not float(damping.max()) <= high:
            raise GainError(f"gain force_damping (K_fd) has an eigenvalue of {float(damping.max()):.3g} 1/s, faster "
                            f"than {high:.4g} 1/s" + ("" if control_period is None else
                                                     f" (the sampling rate 1/h of control_period h = "
                                                     f"{float(control_period):g} s)"))
        for name, matrix, low, unit in (("force_proportional (K_fp)", self.force_proportional, 0.0, "(dimensionless)"),
                                        ("impedance_mass (M_d)", self.impedance_mass, 1.0 / MAX_RATIO,
                                         "kg (the paper's unit mass is 1)")):
            outside = [float(v) for v in np.linalg.eigvalsh(matrix) if not low <= v <= MAX_RATIO] if matrix.size else []
            if outside:
                raise GainError(f"gain {name} has an eigenvalue of {outside[0]:.3g} {unit}; it must be within "
                                f"[{low:g}, {MAX_RATIO:g}]")


def check_poles(poles: ArrayLike, name: str, control_period: Optional[float] = None) -> None:
    """GainError naming the gain ``name`` if a loop it designs (poles s, 1/s) is faster than MAX_RATE, or, for
    a sampled controller of period h (``control_period``), not slower than MAX_RATE_PERIOD / h; or decays
    slower than MIN_RATE (-Re s < MIN_RATE: a time constant of more than eleven days is not a design)."""
    values: Array = np.atleast_1d(np.asarray(poles, dtype=complex))
    if not values.size:
        return
    high, why = MAX_RATE, ""
    if control_period is not None:
        high = min(MAX_RATE, MAX_RATE_PERIOD / float(control_period))
        why = (f" (the sampling rate 1/h of this controller's control_period h = {float(control_period):g} s: a loop "
               "as fast overshoots at every tick, and twice as fast is unstable)")
    fastest = float(np.max(np.abs(values)))
    if not fastest <= high:
        raise GainError(f"gain {name} designs a loop of rate {fastest:.3g} 1/s, faster than {high:.4g} 1/s{why}")
    slowest = float(np.min(-values.real))
    if not slowest >= MIN_RATE:
        raise GainError(f"gain {name} designs a loop that decays at {slowest:.3g} 1/s (a time constant of "
                        f"{1.0 / slowest if slowest > 0 else math.inf:.3g} s), slower than {MIN_RATE:g} 1/s: "
                        "not a design")
