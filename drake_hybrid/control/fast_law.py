"""The float fast path of the law: all numerics between the Drake calls compiled with numba.

``FastLaw.build`` is called by ``HybridController`` at construction for T == float. It generates,
from the user's sympy expressions, a small module for the constraint (the chart maps, then C, E_f,
E_f-dot nu, E_f-dot for a kernel E_p, or a given E_p and E_p-dot nu; the pieces and the selector of a
``SelectingConstraint``), which writes them into a scratch vector; ``fast_kernels.law_from_terms``
then runs the rest of the law. Two compiled calls per tick, not one, so that a new constraint
compiles only its own module (about 1.5 s) and never the law again (about 40 s, once per machine).
The generated source is written once to a cache folder (``DRAKE_HYBRID_CACHE``, default
``~/.cache/drake_hybrid``), keyed by its hash and the kernels' source, so numba's ``cache=True``
keeps the machine code between runs. Nothing compiles at import; the first tick loads the compiled
law from the cache (recording the time in ``FastLaw.compile_seconds``) or, when it is not there yet,
hands the compile to a background job and keeps this controller on the generic law
(``control.fast_compile``; ``DRAKE_HYBRID_COMPILE=foreground`` compiles at the first tick instead).

Per tick (``evaluate``): the Drake calls the law needs (pose, J_g, J_g-dot v, v, and M or h + g
where the law needs them), the two compiled calls, and for n = d one inverse dynamics call and a
small compiled ``finish`` (the saturation; h + g only when a limit is exceeded). With
``normal_force_axis="tool"`` the compiled law reads the normal row along the tool's axis itself
(``fast_kernels.wrench_along_tool_axis``: the end-effector frame's z from the pose it already has, E
as the law factors it), so that reading costs no second evaluation of the constraint space; the
generic law does it with ``normal_force.tool_axis_wrench``. Any condition the generic law answers with an error (chart
or rank singularity, non-finite actuation) falls back to ``law.evaluate_law`` for that evaluation,
which raises the same error; so there is one law, and ``tests/test_fast_law.py`` checks that both
paths give every output port to 1e-12.

The generated module is exact or it does not run: where it is first compiled (or loaded), its terms
are checked against sympy's own 30-digit evaluation of the expressions they came from at a sample
point (``verify_generated``, core/oracle.py); a disagreement raises ``CodeGenerationError`` naming the
term.

AutoDiffXd controllers keep the generic path. Without numba (not installed, or it fails to import)
``build`` warns once and returns None; so does a constraint the compiler does not handle (e.g. a
``SelectingConstraint`` without a symbolic ``selector``): the generic path then runs.
"""

import hashlib
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import sympy

from pydrake.multibody.tree import JacobianWrtVariable

from drake_hybrid.control import fast_compile
from drake_hybrid.control import fast_kernels as kernels
from drake_hybrid.control.damping import damped_step
from drake_hybrid.control.fast_compile import cache_folder
from drake_hybrid.control.fast_kernels import DONE, NEEDS_BASE_TORQUE, NEEDS_INVERSE_DYNAMICS
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.control.normal_force import normal_row
from drake_hybrid.core.charts import EulerZXZChart, PlanarChart, PoseChart
from drake_hybrid.core.constraints import SelectingConstraint
from drake_hybrid.core.oracle import check_against_sympy
from drake_hybrid.core.projections import GivenVelocityProjection, KernelVelocityProjection
from drake_hybrid.core.symbolic import ELEMENTARY_FUNCTIONS, SIGN_SOURCE, straight_line_program, time_derivative

_WARNED = []
_FUNCTIONS = ", ".join(ELEMENTARY_FUNCTIONS) + ", pi, pow, e as E"
# What every generated module starts with: the names straight_line_program's code calls.
MODULE_HEADER = f"import numpy as np\nfrom math import {_FUNCTIONS}\nfrom numba import njit\n\n\n@njit(cache=True)\n{SIGN_SOURCE}\n"


def _kernels_version():
    return hashlib.sha256(Path(kernels.__file__).read_bytes() + Path(__file__).read_bytes()).hexdigest()[:16]


# ------------------------------------------------------------------------------------------------
# Code generation: the constraint terms as one straight-line program per piece
# ------------------------------------------------------------------------------------------------

def _piece_terms(constraint, projection, chart):
    """The sympy matrices [C, E_f, E_f-dot nu, E_f-dot, E_p or 0 x d, E_p-dot nu or 0] (E_f-dot: the
    kernel projection's rate, and the split of a lagged wrench, law.measured_forces)."""
    C, E_f, curvature = constraint.symbolic_terms
    d = chart.velocity_size
    E_f_dot = time_derivative(E_f, chart.configuration_symbols, chart.configuration_rate)
    if isinstance(projection, KernelVelocityProjection):
        return [C, E_f, curvature, E_f_dot, sympy.zeros(0, d), sympy.zeros(0, 1)]
    E_p, E_p_dot_nu = projection.symbolic_terms
    return [C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu]


def _piece_source(name, terms, chart):
    entries = [entry for matrix in terms for entry in matrix]
    assignments, results, printer = straight_line_program(entries)
    lines = ["@njit(cache=True)", f"def {name}(_x, _nu):"]
    for argument, symbols in (("_x", chart.configuration_symbols), ("_nu", chart.velocity_symbols)):
        for i, symbol in enumerate(symbols):
            lines.append(f"    {printer.doprint(symbol)} = {argument}[{i}]")
    for target, code in assignments:
        lines.append(f"    {target} = {code}")
    position = 0
    outputs = []
    for index, matrix in enumerate(terms):
        rows, cols = matrix.shape
        column = index in (0, 2, 5)
        shape = f"({rows},)" if column else f"({rows}, {cols})"
        lines.append(f"    _o{index} = np.empty({shape})")
        for r in range(rows):
            for c in range(cols):
                target = f"_o{index}[{r}]" if column else f"_o{index}[{r}, {c}]"
                lines.append(f"    {target} = {results[position]}")
                position += 1
        outputs.append(f"_o{index}")
    lines.append(f"    return {', '.join(outputs)}")
    return "\n".join(lines)


def _compiled_pieces(space):
    """The constraint pieces the generated module compiles for ``space`` (one, or a
    SelectingConstraint's), or None where the generic law must run."""
    constraint, projection = space.constraint, space.velocity_projection
    if not isinstance(projection, (KernelVelocityProjection, GivenVelocityProjection)):
        return None
    if isinstance(constraint, SelectingConstraint):
        if constraint.selector is None or not all(hasattr(p, "symbolic_terms") for p in constraint.pieces):
            return None
        return constraint.pieces
    if hasattr(constraint, "symbolic_terms"):
        return [constraint]
    return None


def generate_source(space):
    """The generated module's source for ``space`` (a ConstraintSpace), or None if not supported."""
    constraint, projection, chart = space.constraint, space.velocity_projection, space.chart
    pieces = _compiled_pieces(space)
    if pieces is None:
        return None
    parts = [MODULE_HEADER, "from drake_hybrid.control.fast_kernels import store_terms, task_kinematics\n"]
    for i, piece in enumerate(pieces):
        parts.append(_piece_source(f"_terms_{i}", _piece_terms(piece, projection, chart), chart))
    call = "    C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu = _terms_{}(x, nu)"
    if len(pieces) == 1:
        body = [call.format(0)]
    else:
        selector = sympy.Matrix(constraint.selector)
        parts.append(_piece_source("_selector", [selector, sympy.zeros(0, 1), sympy.zeros(0, 1), sympy.zeros(0, 1),
                                                 sympy.zeros(0, 1), sympy.zeros(0, 1)], chart)
                     .replace("np.empty((0, 1))", "np.empty((0,))"))
        body = ["    piece = np.argmax(np.abs(_selector(x, nu)[0]))"]
        for i in range(len(pieces)):
            body += [f"    {'if' if i == 0 else 'elif'} piece == {i}:", "    " + call.format(i)]
        body += ["    else:", "    " + call.format(0)]
    parts.append("\n".join(
        ["@njit(cache=True)",
         "def terms_into(terms, X, J_g, A_bias, v, reals, ints):",
         "    ok, x, nu, J, bias = task_kinematics(X, J_g, A_bias, v, reals, ints)",
         "    if not ok:",
         "        return 1"] + body +
        ["    store_terms(terms, x, nu, J, bias, C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu, ints)",
         "    return 0"]))
    return "\n\n\n".join(parts) + "\n"


NUMBA_POINTS = 3           # sample points verify_generated checks (sympy's 30-digit evaluation: ~10 ms each)


def verify_generated(module, space):
    """Check the generated module's compiled terms of every piece (and the selector) against sympy at
    ``NUMBA_POINTS`` sample points (``symbolic.check_against_sympy``); raises CodeGenerationError naming the term. Called
    where the module is first compiled or loaded: the numba path is exact, or it does not run."""
    pieces, chart = _compiled_pieces(space), space.chart
    arguments = [chart.configuration_symbols, chart.velocity_symbols]

    def flat(outputs):
        return np.concatenate([np.asarray(output, dtype=float).reshape(-1) for output in outputs])

    for i, piece in enumerate(pieces):
        terms = _piece_terms(piece, space.velocity_projection, chart)
        function = getattr(module, f"_terms_{i}")
        check_against_sympy(f"numba terms of '{piece.name}'", [entry for matrix in terms for entry in matrix],
                            arguments, {"numba": lambda x, nu, function=function: flat(function(x, nu))},
                            points=NUMBA_POINTS)
    if len(pieces) > 1:
        check_against_sympy(f"numba selector of '{space.constraint.name}'", list(space.constraint.selector),
                            arguments, {"numba": lambda x, nu: flat(module._selector(x, nu)[:1])}, points=NUMBA_POINTS)


def load_generated(source):
    """Write ``source`` to the cache folder (once, by its hash) and import it."""
    digest = hashlib.sha256((source + _kernels_version()).encode()).hexdigest()[:20]
    name = f"drake_hybrid_fast_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    folder = cache_folder()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.py"
    if not path.exists():
        temporary = folder / f".{name}.{os.getpid()}.tmp"
        temporary.write_text(source)
        os.replace(temporary, path)                 # atomic: parallel workers may write the same file
    return fast_compile.import_file(path)


# ------------------------------------------------------------------------------------------------
# Constants
# ------------------------------------------------------------------------------------------------

def _chart_block(chart):
    if isinstance(chart, PlanarChart):
        u_E = np.asarray(chart._u_E, dtype=float)
        return kernels.CHART_PLANAR, np.concatenate([chart.origin, chart.axis_x, chart.axis_y, u_E, chart.normal])
    if isinstance(chart, EulerZXZChart):
        return kernels.CHART_EULER, np.zeros(0)
    if isinstance(chart, PoseChart):
        return kernels.CHART_POSE, np.zeros(0)
    return None, None


def pack_constants(controller, law, space):
    """(reals, ints) of ``fast_kernels`` for a HybridController and its LawConstants, or None (the
    generic law runs: a chart the kernels do not know)."""
    chart = space.chart
    kind, chart_values = _chart_block(chart)
    if kind is None:
        return None
    n, d, m, k = controller.num_joints, chart.velocity_size, space.force_size, space.velocity_size
    projection = space.velocity_projection
    kernel = isinstance(projection, KernelVelocityProjection)
    gains = law.gains
    chart_tolerance = getattr(chart, "singularity_tolerance", 0.0)
    scalars = np.array([space.constraint.rank_tolerance, projection.rank_tolerance if kernel else 0.0,
                        space.invertibility_tolerance, chart_tolerance, gains.constraint_frequency,
                        gains.null_space_damping, law.singularity_threshold, law.max_joint_acceleration,
                        law.approach_speed or 0.0, law.approach_gain or 0.0, law.wrench_lag])
    mechanism = law.velocity_row_inertia is not None
    # damping.damping_compensation's and damping.step_task_mobility's condition: a discrete plant, damping in the model.
    damped = damped_step(law.joint_damping, law.plant_time_step)
    blocks = [gains.velocity, gains.position, gains.force_proportional, gains.force_integral, law.force_controlled,
              law.actuation_from_torque, law.effort_limits, controller._end_effector_point, chart_values,
              projection.basis if kernel else np.zeros(0), projection._half_lower if kernel else np.zeros(0),
              law.velocity_row_inertia if mechanism else np.zeros(0),
              law.plant_time_step * np.asarray(law.joint_damping, dtype=float) if damped else np.zeros(0),
              gains.impedance_inverse_mass, gains.force_damping]
    reals, offsets, position = [scalars], [], scalars.size
    for block in blocks:
        block = np.ascontiguousarray(block, dtype=float).reshape(-1)
        offsets.append(position)
        reals.append(block)
        position += block.size
    ints = np.zeros(kernels.INT_SIZE, dtype=np.int64)
    ints[:kernels.I_GUARDED + 1] = [n, d, m, k, kind, int(law.mode.integrates_position),
                                    int(law.mode is ControlMode.IMPEDANCE_FORCE), int(kernel), int(law.anti_windup),
                                    int(law.approach_speed is not None)]
    ints[kernels.I_OFFSET_KV:kernels.I_OFFSET_HALF_LOWER + 1] = offsets[:11]
    (ints[kernels.I_OFFSET_MECHANISM], ints[kernels.I_OFFSET_DAMPING], ints[kernels.I_OFFSET_INVERSE_MASS],
     ints[kernels.I_OFFSET_KFD]) = offsets[11:]
    ints[kernels.I_MECHANISM], ints[kernels.I_DAMPING] = int(mechanism), int(damped)
    ints[kernels.I_CONFIGURATION] = chart.configuration_size
    ints[kernels.I_COMPENSATE_TANGENTIAL] = int(law.compensate_tangential_force)
    ints[kernels.I_TOOL_AXIS_ROW] = (normal_row(m, tuple(space.constraint.kinematic_rows))
                                     if controller.normal_force_axis == "tool" else -1)
    return np.concatenate(reals), ints


def _warn_once(message):
    if not _WARNED:
        _WARNED.append(message)
        warnings.warn(message, stacklevel=3)


# ------------------------------------------------------------------------------------------------
# The fast path
# ------------------------------------------------------------------------------------------------

def kernels_loaded():
    """True once the law's compiled kernels are in this process (compiled, or loaded from numba's
    disk cache); before that, the first tick loads them (about 0.4 s) or, on a first run with an
    empty cache, starts numba compiling them in the background (30-65 s on 2 shared cores, as the
    README says; control/fast_compile.py) and runs the generic law."""
    return bool(getattr(kernels.law_from_terms, "signatures", True))


class FastLaw:
    """The compiled law of one float HybridController (see the module docstring).

    ``compile_seconds``: the first tick's compile (or cache load) time, None before it.
    ``fallbacks``: evaluations handed to the generic law (errors, non-finite results).
    ``disabled``: the first tick could not compile (warned once); the generic law runs.
    ``compiling``: the compiled law was not on disk at the first tick: a background job compiles it
    (``fast_compile``, process id ``compile_job``) and this controller runs the generic law throughout.
    """

    def __init__(self, module, reals, ints, controller, space):
        self._module, self._space = module, space
        self._terms_into = module.terms_into
        self._law = kernels.law_from_terms
        self._terms = np.zeros(kernels.terms_size(ints))         # scratch, used within one evaluation only
        self._finish = kernels.finish_inverse_dynamics
        self.reals, self.ints = reals, ints
        n, d = controller.num_joints, controller.task_size
        k, m = controller.velocity_size, controller.force_size
        self._plant = controller.kinematics.plant
        self._frame = controller.kinematics.frame
        self._world = self._plant.world_frame()
        self._point = controller._end_effector_point
        self._needs_mass_matrix = controller.mode is ControlMode.IMPEDANCE_FORCE or n > d
        self._redundant = n > d
        # Drake returns Eigen matrices column-major: a placeholder M of the same layout (2 x 2, so numba
        # does not type it C-contiguous), so that every controller shares one compiled signature.
        self._empty_matrix, self._empty_vector = np.zeros((2, 2), order="F"), np.zeros(0)
        self._zero_acceleration = np.zeros(n)
        # The normal row read along the tool's axis in the kernel (control.normal_force): the axis is X's z column.
        self.reads_tool_axis = bool(ints[kernels.I_TOOL_AXIS_ROW] >= 0)
        self._no_axis = np.zeros(3)
        starts = np.cumsum([0, n, k, m, m, k, m, k, m, k])
        self._slices = [slice(a, b) for a, b in zip(starts[:-1], starts[1:])]
        self._scalars = int(starts[-1])
        size = self._scalars + kernels.OUTPUT_SCALARS + 2 * n                 # kernels.output_size
        self._joint_acceleration_slice = slice(size - 2 * n, size - n)      # q-ddot (n = d), then tau_f
        self.compile_seconds = None
        self.fallbacks = 0
        self.disabled = False
        self.compiling, self.compile_job = False, None
        self._module_path = getattr(module, "__file__", None)

    @classmethod
    def build(cls, controller, law, space):
        """The FastLaw of ``controller`` (float), or None (generic path) with a one-line warning
        when numba is not available."""
        if kernels.NUMBA_ERROR is not None:
            _warn_once(f"drake_hybrid: numba unavailable ({kernels.NUMBA_ERROR}); the controller runs its generic "
                       "(slower) law")
            return None
        source = generate_source(space)
        constants = pack_constants(controller, law, space)
        if source is None or constants is None:
            return None
        return cls(load_generated(source), constants[0], constants[1], controller, space)

    def evaluate(self, plant_context, forces, v, integrals, desired_velocity, desired_acceleration, desired_force,
                 wrench, phase, approach_reference):
        """The ControlSolution, or None when the generic law must run (it raises or handles the case);
        ``v``: the plant context's generalized velocities (from the state the controller set);
        ``approach_reference``: the guarded move's C_r (m)."""
        plant, world, frame, point = self._plant, self._world, self._frame, self._point
        X = plant.CalcRelativeTransform(plant_context, world, frame).GetAsMatrix34()
        tool_axis = X[:, 2].copy() if self.reads_tool_axis else self._no_axis
        J_g = plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, point, world, world)
        A_bias = plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, point, world,
                                                   world).get_coeffs()
        M, base = self._empty_matrix, self._empty_vector
        if self._needs_mass_matrix:
            M = plant.CalcMassMatrix(plant_context)
        if self._redundant:
            base = plant.CalcInverseDynamics(plant_context, self._zero_acceleration, forces)
        phase = int(phase)
        reals, ints, terms = self.reals, self.ints, self._terms
        if self.compile_seconds is None:
            # The first call compiles (or loads from the cache), or leaves the compile to a background job
            # and this controller on the generic law (control/fast_compile.py); a constraint numba cannot
            # compile leaves it on the generic law too, with a one-line warning.
            if self.disabled or self.compiling:
                return None
            start = time.perf_counter()
            try:
                calls = self._calls(plant, plant_context, forces, X, J_g, A_bias, v, desired_velocity,
                                    desired_acceleration, desired_force, wrench, tool_axis, integrals, phase,
                                    approach_reference, M, base)
                if not fast_compile.compiled(calls) and fast_compile.policy() == "background":
                    self._compile_in_background(calls)
                    return None
                self._terms_into(terms, X, J_g, A_bias, v, reals, ints)
                self._law(terms, v, desired_velocity, desired_acceleration, desired_force, wrench, tool_axis,
                          integrals, phase, approach_reference, M, base, reals, ints)
                fast_compile.record(calls)
            except Exception as error:
                self.disabled = True
                message = " ".join(str(error).split())[:200]
                warnings.warn(f"drake_hybrid: the fast law could not be compiled ({type(error).__name__}: "
                              f"{message}); this controller runs the generic law", stacklevel=2)
                return None
            self.compile_seconds = time.perf_counter() - start
            verify_generated(self._module, self._space)      # CodeGenerationError: never run a wrong term
        if self._terms_into(terms, X, J_g, A_bias, v, reals, ints) != 0:
            self.fallbacks += 1                       # the chart's singularity: the generic law raises
            return None
        status, out = self._law(terms, v, desired_velocity, desired_acceleration, desired_force, wrench, tool_axis,
                                integrals, phase, approach_reference, M, base, reals, ints)
        if status == NEEDS_INVERSE_DYNAMICS:
            torque = plant.CalcInverseDynamics(plant_context, out[self._joint_acceleration_slice], forces)
            status = self._finish(out, torque, base, reals, ints)
            if status == NEEDS_BASE_TORQUE:
                base = plant.CalcInverseDynamics(plant_context, self._zero_acceleration, forces)
                status = self._finish(out, torque, base, reals, ints)
        if status != DONE:
            self.fallbacks += 1
            return None
        return CompiledSolution(out, phase, self._slices, self._scalars)

    def _calls(self, plant, plant_context, forces, X, J_g, A_bias, v, desired_velocity, desired_acceleration,
               desired_force, wrench, tool_axis, integrals, phase, approach_reference, M, base):
        """[(compiled function, the numba types of this tick's call)] of the three compiled calls."""
        terms, reals, ints = self._terms, self.reals, self.ints
        law = (terms, v, desired_velocity, desired_acceleration, desired_force, wrench, tool_axis, integrals, phase,
               approach_reference, M, base, reals, ints)
        out = np.zeros(self._joint_acceleration_slice.stop + self.ints[kernels.I_N])     # as law_kernel's
        torque = plant.CalcInverseDynamics(plant_context, self._zero_acceleration, forces)  # as Drake returns it
        return [(self._terms_into, fast_compile.signature_of((terms, X, J_g, A_bias, v, reals, ints))),
                (self._law, fast_compile.signature_of(law)),
                (self._finish, fast_compile.signature_of((out, torque, base, reals, ints)))]

    def _compile_in_background(self, calls):
        """This controller keeps the generic law; numba compiles ``calls`` in a background job (one per
        machine at a time) for the controllers built after it, unless an earlier job failed."""
        self.compiling = True
        error = fast_compile.failure()
        if error is not None:
            _warn_once(f"drake_hybrid: numba could not compile the fast law ({error}); the controllers run the "
                       f"generic law (delete {fast_compile.cache_folder() / 'failed'} to try again)")
            return
        self.compile_job = fast_compile.start_job(calls, self._module_path)


def _field(index):
    return property(lambda solution: solution.out[solution.slices[index]])


class CompiledSolution:
    """A ControlSolution (control/law.py) read from the fast path's output vector, field by field on access."""

    __slots__ = ("out", "contact_phase", "slices", "_scalars")

    def __init__(self, out, contact_phase, slices, scalars):
        self.out, self.contact_phase, self.slices, self._scalars = out, contact_phase, slices, scalars

    actuation, velocity_error, force_error, constraint_value, projected_velocity, force, tangential_force, \
        force_integral_rate, position_error_rate = (_field(i) for i in range(9))

    def diagnostics_vector(self):
        """law.ControlSolution.diagnostics_vector: one slice of the output (its layout is the same)."""
        return self.out[self.slices[1].start:self.slices[6].stop]

    def integral_rates_vector(self, size):
        """law.ControlSolution.integral_rates_vector: one slice of the output."""
        start = self.slices[7].start
        return self.out[start:start + size]

    @property
    def wrench_valid(self):
        return bool(self.out[self._scalars + kernels.S_WRENCH_VALID])

    @property
    def saturation_scale(self):
        return float(self.out[self._scalars + kernels.S_SCALE])

    @property
    def actuator_clipped(self):
        return bool(self.out[self._scalars + kernels.S_CLIPPED])

    @property
    def smallest_singular_value(self):
        sigma_min = float(self.out[self._scalars + kernels.S_SIGMA_MIN])
        return None if sigma_min != sigma_min else sigma_min        # NaN: not computed (None in law.py)

    @property
    def singularity_damping(self):
        return float(self.out[self._scalars + kernels.S_DAMPING])
