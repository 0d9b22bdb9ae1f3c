"""Gains and modes of the hybrid control laws, validated.

The paper's gains (section 3):

====================  ==========  ======================  =================================
name (code)           symbol      size                    role
====================  ==========  ======================  =================================
velocity              K_v         (d-m) x (d-m)           velocity loop, eigenvalues -eig(K_v)
position              K_p         (d-m) x (d-m)           position/impedance modes (Remark 3, 3.2-6)
force_proportional    K_fp        m x m                   force loop, (I + K_fp) xi-dot + K_fi xi = 0
force_integral        K_fi        m x m                   force loop
impedance_mass        M_d         (d-m) x (d-m)           impedance mode: M_d (e'' + K_v e' + K_p e) = F_v
null_space_damping    K_n         scalar (1/s)            n > d only: q-ddot_0 = -K_n q-dot
constraint_frequency  w_c         scalar (rad/s)          kinematic rows: C-ddot + 3 w_c C-dot + 2 w_c^2 C = 0
====================  ==========  ======================  =================================

Each gain may be given as a scalar (times I), a vector (diagonal) or a matrix.
``HybridGains`` stores them as flat lists (YAML-friendly): one entry means a
scalar times I, k entries a diagonal, k*k entries a full matrix (row-major).
K_v, K_p, K_fi and M_d must be symmetric positive definite and K_fp symmetric
positive semidefinite; anything else raises ``GainError`` naming the gain.

M_d is the impedance's mass along the velocity rows (kg, kg m^2 on a turning row). The paper's
impedance (3.2-1) has unit mass, the default: e'' + K_v e' + K_p e = F_v. A heavier M_d keeps
the roots K_v and K_p design and divides the force the impedance yields to by M_d
(K_0 = M_d^-1 - S, docs/theory.md §5): what keeps the roots where they are designed on a contact
that drags (docs/drake_notes.md, "The simulated contact's drag and the impedance's roots").
"""

import enum
from dataclasses import dataclass, field
from typing import List

import numpy as np

from drake_hybrid.core.errors import GainError, check_fields


class ControlMode(enum.Enum):
    """The three laws of the paper."""

    VELOCITY_FORCE = "velocity-force"      # (3.1-12)
    POSITION_FORCE = "position-force"      # Remark 3
    IMPEDANCE_FORCE = "impedance-force"    # (3.2-6)

    @classmethod
    def parse(cls, mode):
        if isinstance(mode, cls):
            return mode
        try:
            return cls(str(mode))
        except ValueError:
            raise ValueError(f"unknown control mode '{mode}'; use one of {[m.value for m in cls]}") from None

    @property
    def integrates_position(self):
        """True if the law uses e_p = integral of e_p' (and so needs K_p)."""
        return self is not ControlMode.VELOCITY_FORCE


def gain_matrix(gain, size, name, semidefinite=False):
    """``gain`` as a symmetric size x size matrix; GainError if it is not (semi)definite.

    Accepts a scalar, a vector (diagonal), a matrix, or the flat lists that
    HybridGains stores (1, size or size*size entries)."""
    try:
        array = np.asarray(gain, dtype=float)
    except (TypeError, ValueError):
        raise GainError(f"gain {name} must be numeric, got {gain!r}") from None
    if array.ndim == 1 and array.size == 1:
        array = array.reshape(())
    elif array.ndim == 1 and array.size == size * size and size > 1:
        array = array.reshape(size, size)
    if array.ndim == 0:
        matrix = float(array) * np.eye(size)
    elif array.ndim == 1:
        if array.size != size:
            raise GainError(f"gain {name} has {array.size} diagonal entries; it must have {size}")
        matrix = np.diag(array)
    elif array.ndim == 2:
        if array.shape != (size, size):
            raise GainError(f"gain {name} is {array.shape[0]}x{array.shape[1]}; it must be {size}x{size}")
        matrix = array.copy()
    else:
        raise GainError(f"gain {name} must be a scalar, a vector or a matrix, got an array of shape {array.shape}")
    if not np.all(np.isfinite(matrix)):
        raise GainError(f"gain {name} has non-finite entries: {matrix.tolist()}")
    if not np.allclose(matrix, matrix.T, rtol=0, atol=1e-12 * max(1.0, np.abs(matrix).max())):
        raise GainError(f"gain {name} must be symmetric, got {matrix.tolist()}")
    eigenvalues = np.linalg.eigvalsh(matrix) if size else np.zeros(0)
    if semidefinite and eigenvalues.size and eigenvalues.min() < 0:
        raise GainError(f"gain {name} must be positive semidefinite; its eigenvalues are {eigenvalues.tolist()}")
    if not semidefinite and eigenvalues.size and eigenvalues.min() <= 0:
        raise GainError(f"gain {name} must be positive definite; its eigenvalues are {eigenvalues.tolist()}")
    return matrix


def _flat(gain):
    array = np.asarray(gain, dtype=float)
    return [float(v) for v in array.reshape(-1)]


@dataclass
class HybridGains:
    """The paper's gains (see the module docstring). Give scalars, vectors or matrices; they are
    stored as flat lists (1, k or k*k entries).

    velocity: K_v (1/s), the velocity rows' gain: in velocity-force mode each row's error decays as
        e^(-K_v t), the designed eigenvalues -eig(K_v).
    position: K_p (1/s^2), the position error's gain in position-force and impedance-force modes:
        each row's roots solve s^2 + K_v s + K_p = 0 (unused in velocity-force mode).
    force_proportional: K_fp (1, dimensionless), the force error's proportional gain.
    force_integral: K_fi (1/s), the force error's integral gain: each force row's eigenvalue is
        -K_fi / (1 + K_fp).
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
    null_space_damping: float = 10.0
    constraint_frequency: float = 15.0
    impedance_mass: List[float] = field(default_factory=lambda: [1.0])   # M_d, impedance mode; 1: the paper's

    def __post_init__(self):
        for name in ("velocity", "position", "force_proportional", "force_integral", "impedance_mass"):
            try:
                setattr(self, name, _flat(getattr(self, name)))
            except (TypeError, ValueError):
                raise GainError(f"gain {name} must be numeric, got {getattr(self, name)!r}") from None

    def matrices(self, velocity_size, force_size, mode):
        """Validated matrices (K_v, K_p, K_fp, K_fi) for d - m = velocity_size, m = force_size."""
        mode = ControlMode.parse(mode)
        K_v = gain_matrix(self.velocity, velocity_size, "velocity (K_v)")
        K_p = (gain_matrix(self.position, velocity_size, "position (K_p)") if mode.integrates_position
               else np.zeros((velocity_size, velocity_size)))
        K_fp = gain_matrix(self.force_proportional, force_size, "force_proportional (K_fp)", semidefinite=True)
        K_fi = gain_matrix(self.force_integral, force_size, "force_integral (K_fi)")
        check_fields(self, "gain ", positive=("constraint_frequency",), nonnegative=("null_space_damping",),
                     error=GainError)
        M_d = gain_matrix(self.impedance_mass, velocity_size, "impedance_mass (M_d)")
        return ValidatedGains(K_v, K_p, K_fp, K_fi, float(self.null_space_damping), float(self.constraint_frequency),
                              M_d)

    def as_lists(self, velocity_size, force_size, mode):
        """The gains as nested lists (for summary.json), keyed as in the CLI's summary."""
        g = self.matrices(velocity_size, force_size, mode)
        return {"velocity": g.velocity.tolist(), "position": g.position.tolist(),
                "force_proportional": g.force_proportional.tolist(), "force_integral": g.force_integral.tolist(),
                "impedance_mass": g.impedance_mass.tolist()}


@dataclass
class ValidatedGains:
    velocity: np.ndarray
    position: np.ndarray
    force_proportional: np.ndarray
    force_integral: np.ndarray
    null_space_damping: float
    constraint_frequency: float
    impedance_mass: np.ndarray = None          # M_d (k x k); None: the paper's unit mass
    force_rate: np.ndarray = field(init=False)
    impedance_inverse_mass: np.ndarray = field(init=False)     # M_d^-1, the law's and the analyses'

    def __post_init__(self):
        if self.impedance_mass is None:
            self.impedance_mass = np.eye(self.velocity.shape[0])
        self.impedance_inverse_mass = np.linalg.inv(self.impedance_mass)
        # G = (I + K_fp)^-1 K_fi: the force loop's rate matrix (3.1-14).
        m = self.force_proportional.shape[0]
        self.force_rate = np.linalg.solve(np.eye(m) + self.force_proportional, self.force_integral)
