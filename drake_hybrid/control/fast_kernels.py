"""The float numerics of the law (control/law.py) compiled with numba: the fast path's kernels.

``control.fast_law`` generates, per constraint, a small module whose ``tick`` evaluates the
user's C, E_f, E_f-dot (and a given E_p, E_p-dot nu) compiled from sympy and then calls
``law_kernel`` below: the chart maps, the kernel E_p, the rank margins, E = [E_p; E_f] factored
once for the wrench split (3.0-8) and r-ddot* (3.0-11), the three laws (3.1-12), Remark 3,
(3.2-6), the mechanism force F_m = I_v a_p, the compensations F_c = -F_v and F_h = -F on the held
rows, the held and guarded rows, u_f, tau_f, J^-1 (bounded) or the dynamically consistent Lambda
(bounded), the discrete step's damping compensation h B a* and its task mobility J (M + h B)^-1 J^T
(for K_0), the saturation and the integral rates. Every function mirrors one of control/law.py,
control/damping.py, core/projections.py, core/charts.py or control/safety.py line by line, so the two
paths agree to rounding (tests/test_fast_law.py checks every output port to 1e-12).

Small matrices (d <= 6, n <= 7) are multiplied and factored by hand-written loops: a LAPACK or
BLAS call through numba costs more than the arithmetic here. Conditions the generic path answers
with an error (chart or rank singularity, non-finite actuation) return status ``FALLBACK``; the
controller then runs the generic law, which raises the error with its message.

Constants travel in two arrays built by ``fast_law.pack_constants``: ``reals`` (scalars at the
``R_*`` indices, then blocks) and ``ints`` (sizes and flags at the ``I_*`` indices, then the blocks'
offsets in ``reals``). Nothing here compiles at import (numba compiles on first call; cache=True).
"""

# Longer than 500 lines because it is one numba cache unit: one compiled kernel per line of the law and the
# helpers they call (LU, Cholesky, bisection, charts), cached together.

import math

import numpy as np

try:
    from numba import njit as _njit
    NUMBA_ERROR = None
except Exception as error:                   # not installed or broken: fast_law warns, the generic law runs
    _njit, NUMBA_ERROR = None, error


def compiled(function):
    """numba.njit (compiled on first call, cached on disk; IEEE division as numpy); the plain function without numba."""
    return _njit(cache=True, error_model="numpy")(function) if _njit is not None else function


# -- layout of ``ints`` ----------------------------------------------------------------------------
I_N, I_D, I_M, I_K, I_CHART, I_POSITION, I_IMPEDANCE, I_KERNEL, I_ANTI_WINDUP, I_GUARDED = range(10)
(I_OFFSET_KV, I_OFFSET_KP, I_OFFSET_KFP, I_OFFSET_KFI, I_OFFSET_MASK, I_OFFSET_B_INVERSE, I_OFFSET_LIMITS,
 I_OFFSET_POINT, I_OFFSET_CHART, I_OFFSET_BASIS, I_OFFSET_HALF_LOWER) = range(10, 21)
I_CONFIGURATION = 21          # size of the chart's configuration x
I_COMPENSATE_TANGENTIAL = 22  # 1: cancel the measured F_v and the held rows' F (law.tangential_compensation,
#                               law.held_row_compensation)
I_MECHANISM = 23              # 1: the mechanism force F_m = I_v a_p (law.mechanism_force)
I_DAMPING = 24                # 1: a damped discrete step: h B a* and K_0's J (M + h B)^-1 J^T (control.damping)
I_OFFSET_MECHANISM, I_OFFSET_DAMPING = 25, 26   # offsets of I_v (k x k) and h B (n) in ``reals``
I_OFFSET_INVERSE_MASS = 27    # offset of M_d^-1 (k x k), the impedance's inverse mass (law.impedance_gain)
I_OFFSET_KFD = 28             # offset of K_fd (m x m), the force rows' damping (law.force_row_damping)
I_TOOL_AXIS_ROW = 29          # the normal row read along the tool's axis (control.normal_force); -1: as E reads it
INT_SIZE = 30
# -- scalars at the start of ``reals`` -------------------------------------------------------------
(R_RANK_TOLERANCE, R_KERNEL_TOLERANCE, R_INVERTIBILITY_TOLERANCE, R_CHART_TOLERANCE, R_CONSTRAINT_FREQUENCY,
 R_NULL_SPACE_DAMPING, R_SINGULARITY_THRESHOLD, R_MAX_ACCELERATION, R_APPROACH_SPEED, R_APPROACH_GAIN,
 R_WRENCH_LAG) = range(11)
REAL_SCALARS = 11
CHART_PLANAR, CHART_EULER, CHART_POSE = 0, 1, 2
PHASE_APPROACH, PHASE_CONTACT = 1, 2
# -- status ------------------------------------------------------------------------------------------
DONE, FALLBACK, NEEDS_INVERSE_DYNAMICS, NEEDS_BASE_TORQUE = 0, 1, 2, 3
# -- scalars at the end of the output (after the vectors, see ``output_layout``) ---------------------
S_WRENCH_VALID, S_SCALE, S_CLIPPED, S_SIGMA_MIN, S_DAMPING = range(5)
OUTPUT_SCALARS = 5


@compiled
def output_size(n, k, m):
    """[u (n), e_p' (k), e_f (m), C (m), r-dot_p (k), F (m), F_v (k), xi-dot (m), e_p-dot (k), 5 scalars,
    q-ddot (n), tau_f (n)]."""
    return n + 4 * k + 4 * m + OUTPUT_SCALARS + 2 * n


# ------------------------------------------------------------------------------------------------
# Small dense linear algebra
# ------------------------------------------------------------------------------------------------

@compiled
def matmul(A, B):
    rows, inner, cols = A.shape[0], A.shape[1], B.shape[1]
    C = np.zeros((rows, cols))
    for i in range(rows):
        for p in range(inner):
            a = A[i, p]
            for j in range(cols):
                C[i, j] += a * B[p, j]
    return C


@compiled
def matvec(A, x):
    y = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        y[i] = s
    return y


@compiled
def transpose(A):
    return np.ascontiguousarray(A.T)


@compiled
def lu_factor(A):
    """(LU, pivots, singular) by partial pivoting (LAPACK getrf's choice of pivot)."""
    size = A.shape[0]
    LU = A.copy()
    pivots = np.arange(size)
    singular = False
    for j in range(size):
        p = j
        largest = abs(LU[j, j])
        for i in range(j + 1, size):
            if abs(LU[i, j]) > largest:
                largest, p = abs(LU[i, j]), i
        if p != j:
            for c in range(size):
                LU[j, c], LU[p, c] = LU[p, c], LU[j, c]
            pivots[j], pivots[p] = pivots[p], pivots[j]
        if LU[j, j] == 0.0:
            singular = True
            continue
        for i in range(j + 1, size):
            LU[i, j] /= LU[j, j]
            factor = LU[i, j]
            for c in range(j + 1, size):
                LU[i, c] -= factor * LU[j, c]
    return LU, pivots, singular


@compiled
def lu_solve(LU, pivots, b):
    size = LU.shape[0]
    x = np.empty(size)
    for i in range(size):
        x[i] = b[pivots[i]]
    for i in range(size):
        for j in range(i):
            x[i] -= LU[i, j] * x[j]
    for i in range(size - 1, -1, -1):
        for j in range(i + 1, size):
            x[i] -= LU[i, j] * x[j]
        x[i] /= LU[i, i]
    return x


@compiled
def lu_solve_transpose(LU, pivots, b):
    """x with A^T x = b from A's factors (P A = L U: A^T = U^T L^T P)."""
    size = LU.shape[0]
    y = b.copy()
    for i in range(size):
        for j in range(i):
            y[i] -= LU[j, i] * y[j]
        y[i] /= LU[i, i]
    for i in range(size - 1, -1, -1):
        for j in range(i + 1, size):
            y[i] -= LU[j, i] * y[j]
    x = np.empty(size)
    for i in range(size):
        x[pivots[i]] = y[i]
    return x


@compiled
def inverse(A):
    """(A^-1, singular)."""
    size = A.shape[0]
    LU, pivots, singular = lu_factor(A)
    result = np.zeros((size, size))
    if singular:
        return result, True
    unit = np.zeros(size)
    for j in range(size):
        unit[:] = 0.0
        unit[j] = 1.0
        result[:, j] = lu_solve(LU, pivots, unit)
    return result, False


@compiled
def solve_matrix(A, B):
    """(A^-1 B, singular) for a matrix B."""
    LU, pivots, singular = lu_factor(A)
    X = np.zeros((A.shape[0], B.shape[1]))
    if singular:
        return X, True
    for j in range(B.shape[1]):
        X[:, j] = lu_solve(LU, pivots, np.ascontiguousarray(B[:, j]))
    return X, False


@compiled
def cholesky(S):
    """(L, ok): L L^T = S, ok False where S is not (numerically) positive definite."""
    size = S.shape[0]
    L = np.zeros((size, size))
    for j in range(size):
        diagonal = S[j, j]
        for i in range(j):
            diagonal -= L[j, i] * L[j, i]
        if not diagonal > 0.0:
            return L, False
        L[j, j] = math.sqrt(diagonal)
        for row in range(j + 1, size):
            s = S[row, j]
            for i in range(j):
                s -= L[row, i] * L[j, i]
            L[row, j] = s / L[j, j]
    return L, True


@compiled
def rank_margin_of_rows(A):
    """linalg.rank_margin for a wide A (rows fewer than columns): sqrt(det(A A^T) / prod |a_i|^2)."""
    rows = A.shape[0]
    if rows == 0:
        return 1.0
    norms = np.zeros(rows)
    for i in range(rows):
        for j in range(A.shape[1]):
            norms[i] += A[i, j] * A[i, j]
    if not norms.min() > 0.0:
        return 0.0
    gram = matmul(A, transpose(A))
    LU, _, singular = lu_factor(gram)
    if singular:
        return 0.0
    determinant = 1.0
    for i in range(rows):
        determinant *= LU[i, i]
    ratio = abs(determinant) / norms.prod()
    return math.sqrt(ratio) if math.isfinite(ratio) else 0.0


@compiled
def rank_margin_of_factored(A, LU, singular):
    """linalg.LUFactorization.rank_margin: |det A| / prod |a_i| from A's LU factors."""
    if singular:
        return 0.0
    product, determinant = 1.0, 1.0
    for i in range(A.shape[0]):
        row = 0.0
        for j in range(A.shape[1]):
            row += A[i, j] * A[i, j]
        if not row > 0.0:
            return 0.0
        product *= row
        determinant *= LU[i, i]
    margin = abs(determinant) / math.sqrt(product)
    return margin if math.isfinite(margin) else 0.0


@compiled
def all_finite(x):
    return math.isfinite(x.sum())


# ------------------------------------------------------------------------------------------------
# Chart maps (core/charts.py) and the end-effector kinematics (core/kinematics.py)
# ------------------------------------------------------------------------------------------------

@compiled
def _euler_rate_inverse(phi, theta):
    """T(eta)^-1 of EulerZXZChart."""
    sp, cp, st, ct = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
    return np.array([[-sp * ct / st, cp * ct / st, 1.0], [cp, sp, 0.0], [sp / st, -cp / st, 0.0]])


@compiled
def task_kinematics(X, J_g, A_bias, v, reals, ints):
    """(ok, x, nu, J, J-dot q-dot) from X_WE (3 x 4), J_g (6 x n), A_bias, v: EndEffectorKinematics.evaluate."""
    n, d, chart = ints[I_N], ints[I_D], ints[I_CHART]
    point = reals[ints[I_OFFSET_POINT]:ints[I_OFFSET_POINT] + 3]
    R = np.ascontiguousarray(X[:, :3])
    p = np.empty(3)
    for i in range(3):
        p[i] = X[i, 3] + R[i, 0] * point[0] + R[i, 1] * point[1] + R[i, 2] * point[2]
    V = matvec(J_g, v)
    J = np.empty((d, n))
    nu = np.empty(d)
    bias = np.empty(d)
    if chart == CHART_PLANAR:
        c = ints[I_OFFSET_CHART]
        origin, e1, e2 = reals[c:c + 3], reals[c + 3:c + 6], reals[c + 6:c + 9]
        u_E, normal = reals[c + 9:c + 12], reals[c + 12:c + 15]
        q = p - origin
        u_W = matvec(R, u_E)
        x = np.array([e1 @ q, e2 @ q, math.atan2(e2 @ u_W, e1 @ u_W)])
        for j in range(n):
            J[0, j] = e1[0] * J_g[3, j] + e1[1] * J_g[4, j] + e1[2] * J_g[5, j]
            J[1, j] = e2[0] * J_g[3, j] + e2[1] * J_g[4, j] + e2[2] * J_g[5, j]
            J[2, j] = normal[0] * J_g[0, j] + normal[1] * J_g[1, j] + normal[2] * J_g[2, j]
        nu[0], nu[1], nu[2] = e1 @ V[3:], e2 @ V[3:], normal @ V[:3]
        bias[0], bias[1], bias[2] = e1 @ A_bias[3:], e2 @ A_bias[3:], normal @ A_bias[:3]
        return True, x, nu, J, bias
    if chart == CHART_POSE:
        x = np.empty(12)
        x[:3] = p
        for i in range(3):
            for j in range(3):
                x[3 + 3 * i + j] = R[i, j]
        for r in range(3):
            nu[r], nu[r + 3] = V[r + 3], V[r]
            bias[r], bias[r + 3] = A_bias[r + 3], A_bias[r]
            for j in range(n):
                J[r, j], J[r + 3, j] = J_g[r + 3, j], J_g[r, j]
        return True, x, nu, J, bias
    # EulerZXZChart
    theta = math.acos(min(1.0, max(-1.0, R[2, 2])))
    phi = math.atan2(R[0, 2], -R[1, 2])
    psi = math.atan2(R[2, 0], R[2, 1])
    x = np.array([p[0], p[1], p[2], phi, theta, psi])
    if abs(math.sin(theta)) < reals[R_CHART_TOLERANCE]:
        return False, x, nu, J, bias
    T_inverse = _euler_rate_inverse(phi, theta)
    angular = matvec(T_inverse, V[:3])
    J_angular = matmul(T_inverse, np.ascontiguousarray(J_g[:3]))
    for r in range(3):
        nu[r], nu[r + 3] = V[r + 3], angular[r]
        for j in range(n):
            J[r, j], J[r + 3, j] = J_g[r + 3, j], J_angular[r, j]
    sp, cp, st, ct = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
    pd, td, sd = nu[3], nu[4], nu[5]
    rate_bias = np.array([-sp * pd * td + (st * cp * pd + ct * sp * td) * sd,
                          cp * pd * td + (st * sp * pd - ct * cp * td) * sd,
                          -st * td * sd])                      # T-dot eta-dot
    angular_bias = matvec(T_inverse, A_bias[:3] - rate_bias)
    for r in range(3):
        bias[r], bias[r + 3] = A_bias[r + 3], angular_bias[r]
    return True, x, nu, J, bias


@compiled
def generalized_force(x, wrench, reals, ints):
    """w = B^T F of the chart (Chart.generalized_force)."""
    chart = ints[I_CHART]
    if chart == CHART_PLANAR:
        c = ints[I_OFFSET_CHART]
        e1, e2, normal = reals[c + 3:c + 6], reals[c + 6:c + 9], reals[c + 12:c + 15]
        return np.array([e1 @ wrench[3:], e2 @ wrench[3:], normal @ wrench[:3]])
    w = np.empty(6)
    w[:3] = wrench[3:]
    if chart == CHART_POSE:
        w[3:] = wrench[:3]
        return w
    phi, theta = x[3], x[4]
    sp, cp, st, ct = math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta)
    n = wrench[:3]
    w[3] = n[2]                                               # T^T n, T = [[0, cp, st sp], [0, sp, -st cp], [1, 0, ct]]
    w[4] = cp * n[0] + sp * n[1]
    w[5] = st * sp * n[0] - st * cp * n[1] + ct * n[2]
    return w


# ------------------------------------------------------------------------------------------------
# The kernel velocity projection (core/projections.KernelVelocityProjection.matrix_and_rate)
# ------------------------------------------------------------------------------------------------

@compiled
def kernel_projection(E_f, E_f_dot, nu, reals, ints):
    """(ok, E_p, E_p-dot nu)."""
    d, k = ints[I_D], ints[I_K]
    G = reals[ints[I_OFFSET_BASIS]:ints[I_OFFSET_BASIS] + k * d].reshape((k, d))
    half_lower = reals[ints[I_OFFSET_HALF_LOWER]:ints[I_OFFSET_HALF_LOWER] + k * k].reshape((k, k))
    E_f_T = transpose(E_f)
    A_inverse, singular = inverse(matmul(E_f, E_f_T))
    if singular:
        return False, E_f, nu
    pseudo_inverse = matmul(E_f_T, A_inverse)
    P_N = np.eye(d) - matmul(pseudo_inverse, E_f)
    B = matmul(pseudo_inverse, E_f_dot)
    A_dot = matmul(E_f_dot, E_f_T)
    A_dot = A_dot + A_dot.T
    P_N_dot = matmul(matmul(pseudo_inverse, A_dot), transpose(pseudo_inverse)) - B - B.T
    Y = matmul(G, P_N)
    Y_dot = matmul(G, P_N_dot)
    Y_T = transpose(Y)
    S = matmul(Y, Y_T)
    L, ok = cholesky(S)
    margin = 0.0
    if ok:
        diagonal, gram, positive = 1.0, 1.0, True
        for i in range(k):
            diagonal *= L[i, i]
            gram *= S[i, i]
            positive = positive and S[i, i] > 0.0
        margin = abs(diagonal) / math.sqrt(gram) if positive else 0.0
    if not margin >= reals[R_KERNEL_TOLERANCE]:
        return False, E_f, nu
    L_inverse, _ = inverse(L)
    E_p = matmul(L_inverse, Y)
    S_dot = matmul(Y_dot, Y_T)
    S_dot = S_dot + S_dot.T
    Phi = matmul(matmul(L_inverse, S_dot), transpose(L_inverse)) * half_lower
    L_dot = matmul(L, Phi)
    E_p_dot = matmul(L_inverse, Y_dot - matmul(L_dot, E_p))
    return True, E_p, matvec(E_p_dot, nu)


# ------------------------------------------------------------------------------------------------
# Protections (control/safety.py)
# ------------------------------------------------------------------------------------------------

@compiled
def _solution_norm(sigma, coefficients, damping):
    s = 0.0
    for i in range(sigma.size):
        value = sigma[i] * coefficients[i] / (sigma[i] * sigma[i] + damping)
        s += value * value
    return math.sqrt(s)


@compiled
def _mobility_norm(M_inverse_J_T, mobility, rhs, mu):
    shifted = mobility + mu * np.eye(mobility.shape[0])
    LU, pivots, singular = lu_factor(shifted)
    if singular:
        return np.inf
    x = matvec(M_inverse_J_T, lu_solve(LU, pivots, rhs))
    return math.sqrt(x @ x)


@compiled
def bounded_solve(J, rhs, threshold, max_norm):
    """safety.bounded_solve: (ok, x, sigma_min (nan = not computed), lambda^2)."""
    LU, pivots, singular = lu_factor(J)
    exact = np.zeros(J.shape[0])
    if not singular:
        exact = lu_solve(LU, pivots, rhs)
        if exact @ exact <= max_norm * max_norm:
            return True, exact, np.nan, 0.0
    if not (all_finite(J) and all_finite(rhs)):
        return False, exact, np.nan, 0.0
    U, sigma, _ = np.linalg.svd(J)
    sigma_min = sigma[-1]
    if not singular and sigma_min >= threshold:
        return True, exact, sigma_min, 0.0
    coefficients = matvec(transpose(U), rhs)
    scale = sigma[0] ** 2
    low, high = 1e-12 * scale, 1e6 * scale
    for _ in range(60):
        middle = math.sqrt(low * high)
        if _solution_norm(sigma, coefficients, middle) > max_norm:
            low = middle
        else:
            high = middle
    d = J.shape[0]
    J_T = transpose(J)
    LU, pivots, singular = lu_factor(matmul(J, J_T) + high * np.eye(d))
    if singular:
        return False, exact, sigma_min, high
    return True, matvec(J_T, lu_solve(LU, pivots, rhs)), sigma_min, high


@compiled
def bounded_task_inertia(J, M_inverse, mobility, rhs, threshold, max_norm):
    """safety.bounded_task_inertia: (ok, Lambda, sigma_min (nan = not computed), mu)."""
    d = J.shape[0]
    M_inverse_J_T = matmul(M_inverse, transpose(J))
    exact_norm = _mobility_norm(M_inverse_J_T, mobility, rhs, 0.0)
    if math.isfinite(exact_norm) and exact_norm <= max_norm:
        Lambda, singular = inverse(mobility)
        return not singular, Lambda, np.nan, 0.0
    if not (all_finite(J) and all_finite(mobility) and all_finite(rhs)):
        return False, mobility, np.nan, 0.0
    sigma_min = np.linalg.svd(J)[1][-1]
    if sigma_min >= threshold and math.isfinite(exact_norm):
        Lambda, singular = inverse(mobility)
        return not singular, Lambda, sigma_min, 0.0
    scale = np.trace(mobility) / d
    low, high = 1e-12 * scale, 1e6 * scale
    for _ in range(60):
        middle = math.sqrt(low * high)
        if _mobility_norm(M_inverse_J_T, mobility, rhs, middle) > max_norm:
            low = middle
        else:
            high = middle
    Lambda, singular = inverse(mobility + high * np.eye(d))
    return not singular, Lambda, sigma_min, high


@compiled
def saturate(out, base_torque, reals, ints):
    """safety.saturate on the actuation held in ``out`` (B^-1 tau), given the base torque h + g."""
    n = ints[I_N]
    limits = reals[ints[I_OFFSET_LIMITS]:ints[I_OFFSET_LIMITS] + n]
    B_inverse = reals[ints[I_OFFSET_B_INVERSE]:ints[I_OFFSET_B_INVERSE] + n * n].reshape((n, n))
    actuation = out[:n].copy()
    base = matvec(B_inverse, base_torque)
    task = actuation - base
    scale = 1.0
    for i in range(n):
        b, t, limit = base[i], task[i], limits[i]
        if abs(b) > limit:
            scale = 0.0
            break
        if t > 0 and b + t > limit:
            scale = min(scale, (limit - b) / t)
        elif t < 0 and b + t < -limit:
            scale = min(scale, (-limit - b) / t)
    scale = max(scale, 0.0)
    clipped = False
    for i in range(n):
        clipped = clipped or abs(base[i]) > limits[i]
        value = base[i] + scale * (actuation[i] - base[i])
        if abs(value) > limits[i]:
            value = math.copysign(limits[i], value) if value != 0.0 else 0.0
        out[i] = value
    return scale, clipped


@compiled
def finish(out, torque, base_torque, reals, ints):
    """u = saturate(B^-1 tau); the integral rates (frozen while saturated). Status DONE, FALLBACK
    (non-finite actuation) or NEEDS_BASE_TORQUE (a limit is exceeded and ``base_torque`` is empty)."""
    n, k, m = ints[I_N], ints[I_K], ints[I_M]
    limits = reals[ints[I_OFFSET_LIMITS]:ints[I_OFFSET_LIMITS] + n]
    B_inverse = reals[ints[I_OFFSET_B_INVERSE]:ints[I_OFFSET_B_INVERSE] + n * n].reshape((n, n))
    actuation = matvec(B_inverse, torque)
    out[:n] = actuation
    within = True
    for i in range(n):
        if not abs(actuation[i]) <= limits[i]:
            within = False
    scale, clipped = 1.0, False
    if not within:
        if base_torque.size == 0:
            return NEEDS_BASE_TORQUE
        scale, clipped = saturate(out, base_torque, reals, ints)
    if not all_finite(out[:n]):
        return FALLBACK
    s = n + 4 * k + 4 * m
    out[s + S_SCALE] = scale
    out[s + S_CLIPPED] = 1.0 if clipped else 0.0
    frozen = ints[I_ANTI_WINDUP] != 0 and (scale < 1.0 or clipped)
    if frozen:                                                # conditional integration: xi-dot, e_p-dot = 0
        rates = n + 3 * k + 3 * m
        for i in range(m + k):
            out[rates + i] = out[rates + i] * 0.0
    return DONE


@compiled
def damping_compensation(joint_acceleration, reals, ints):
    """damping.damping_compensation: h B a* (``reals`` holds h B, the product of the plant's step and the
    model's joint damping)."""
    n = ints[I_N]
    return reals[ints[I_OFFSET_DAMPING]:ints[I_OFFSET_DAMPING] + n] * joint_acceleration


@compiled
def step_task_mobility(J, M, mobility, reals, ints):
    """damping.step_task_mobility: (ok, J (M + h B)^-1 J^T) on a discrete plant with joint damping
    (``reals`` holds h B), else (True, ``mobility``); ok False if M + h B is singular."""
    if ints[I_DAMPING] == 0:
        return True, mobility
    n = ints[I_N]
    step_inertia = M.copy()
    for i in range(n):
        step_inertia[i, i] += reals[ints[I_OFFSET_DAMPING] + i]
    step_inverse, singular = inverse(step_inertia)
    if singular:
        return False, mobility
    return True, matmul(matmul(J, step_inverse), transpose(J))


@compiled
def finish_inverse_dynamics(out, inverse_dynamics, base_torque, reals, ints):
    """n = d: tau = ID(q, q-dot, q-ddot) + tau_f (tau_f stored in ``out``), then ``finish``."""
    n = ints[I_N]
    start = out.size - n
    torque = inverse_dynamics + out[start:]
    if ints[I_DAMPING] != 0:
        torque = torque + damping_compensation(out[start - n:start], reals, ints)
    return finish(out, torque, base_torque, reals, ints)


# ------------------------------------------------------------------------------------------------
# The normal row read along the tool's axis (control/normal_force.tool_axis_wrench)
# ------------------------------------------------------------------------------------------------

@compiled
def model_normal(E_f_row, reals, ints):
    """(ok, n): the unit direction in world of the force the E_f row reads (normal_force.model_normal): the
    translational part of the row as a covector on the spatial velocity [w; v]. The 6-D charts' task
    velocity starts with v (so that part is the row's first three entries); the planar chart's is
    (e_1 . v, e_2 . v, n . w)."""
    if ints[I_CHART] == CHART_PLANAR:
        c = ints[I_OFFSET_CHART]
        direction = E_f_row[0] * reals[c + 3:c + 6] + E_f_row[1] * reals[c + 6:c + 9]
    else:
        direction = E_f_row[:3].copy()
    length_squared = direction @ direction
    if not length_squared > 1e-24:
        return False, direction
    return True, direction / math.sqrt(length_squared)


@compiled
def wrench_along_tool_axis(x, E_f, LU, pivots, wrench, tool_axis, reals, ints):
    """(ok, W'): the measured wrench changed along the model's normal n so that the normal row's reading
    in E's dual basis is the force along the tool's axis (normal_force.force_along_tool_axis):
    W' = W + ((a_n . f - r(W)) / r([0; n])) [0; n], r(W) = (E^-T w(W))_row, a_n the axis signed towards n.
    Not ok where the row reads no force or not along n: the generic law raises the controller's error."""
    k, row = ints[I_K], ints[I_TOOL_AXIS_ROW]
    ok, normal = model_normal(E_f[row], reals, ints)
    if not ok:
        return False, wrench
    signed = tool_axis if tool_axis @ normal >= 0 else -tool_axis
    along_normal = np.zeros(6)
    along_normal[3:] = normal
    unit_reading = lu_solve_transpose(LU, pivots, generalized_force(x, along_normal, reals, ints))[k + row]
    if not abs(unit_reading) > 1e-9:
        return False, wrench
    reading = lu_solve_transpose(LU, pivots, generalized_force(x, wrench, reals, ints))[k + row]
    return True, wrench + ((signed @ wrench[3:] - reading) / unit_reading) * along_normal


# ------------------------------------------------------------------------------------------------
# The law (control/law.evaluate_law), from the chart quantities and the constraint terms
# ------------------------------------------------------------------------------------------------

@compiled
def law_kernel(x, nu, J, bias, C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu, v, desired_velocity,
               desired_acceleration, desired_force, wrench, tool_axis, integrals, phase, approach_reference, M,
               base_torque, reals, ints):
    """(status, out): DONE (``out`` complete), FALLBACK (run the generic law: it raises or handles the
    case) or NEEDS_INVERSE_DYNAMICS (n = d: q-ddot and tau_f are at the end of ``out``; call
    ``finish_inverse_dynamics`` with ID(q, q-dot, q-ddot)). ``tool_axis``: the end-effector frame's z in
    world, read where ``ints[I_TOOL_AXIS_ROW]`` names the normal row."""
    n, d, m, k = ints[I_N], ints[I_D], ints[I_M], ints[I_K]
    out = np.zeros(output_size(n, k, m))
    mask = reals[ints[I_OFFSET_MASK]:ints[I_OFFSET_MASK] + m]
    K_v = reals[ints[I_OFFSET_KV]:ints[I_OFFSET_KV] + k * k].reshape((k, k))
    K_p = reals[ints[I_OFFSET_KP]:ints[I_OFFSET_KP] + k * k].reshape((k, k))
    K_fp = reals[ints[I_OFFSET_KFP]:ints[I_OFFSET_KFP] + m * m].reshape((m, m))
    K_fi = reals[ints[I_OFFSET_KFI]:ints[I_OFFSET_KFI] + m * m].reshape((m, m))
    in_contact = phase == PHASE_CONTACT

    if not (all_finite(desired_velocity) and all_finite(desired_acceleration) and all_finite(desired_force)):
        return FALLBACK, out                                           # the controller names the port
    # E_p, E = [E_p; E_f] and the checks of ConstraintSpace.evaluate
    if rank_margin_of_rows(E_f) < reals[R_RANK_TOLERANCE] or not all_finite(E_f):
        return FALLBACK, out
    if ints[I_KERNEL] != 0:
        ok, E_p, E_p_dot_nu = kernel_projection(E_f, E_f_dot, nu, reals, ints)
        if not ok:
            return FALLBACK, out
    E = np.empty((d, d))
    E[:k] = E_p
    E[k:] = E_f
    LU, pivots, singular = lu_factor(E)
    if rank_margin_of_factored(E, LU, singular) < reals[R_INVERTIBILITY_TOLERANCE]:
        return FALLBACK, out

    # [F_v; F] = E^-T w (3.0-8), split where a lagged wrench was measured; a non-finite wrench is ignored
    wrench_valid = all_finite(wrench)
    if wrench_valid:
        if ints[I_TOOL_AXIS_ROW] >= 0:
            ok, wrench = wrench_along_tool_axis(x, E_f, LU, pivots, wrench, tool_axis, reals, ints)
            if not ok:
                return FALLBACK, out
        covector = generalized_force(x, wrench, reals, ints)
        split = lu_solve_transpose(LU, pivots, covector)
        if reals[R_WRENCH_LAG] > 0:
            split = lu_solve_transpose(LU, pivots, covector + reals[R_WRENCH_LAG] * matvec(transpose(E_f_dot),
                                                                                          split[k:]))
        tangential_force, force = split[:k], split[k:]
    else:
        tangential_force, force = np.zeros(k), desired_force.copy()
    projected_velocity = matvec(E_p, nu)                               # (3.0-6)
    velocity_error = projected_velocity - desired_velocity
    force_error = (force - desired_force) * mask

    a_p = desired_acceleration - matvec(K_v, velocity_error)          # (3.1-12)
    if ints[I_POSITION] != 0:
        a_p = a_p - matvec(K_p, integrals[m:])                          # Remark 3
    mechanism = ints[I_MECHANISM] != 0
    if mechanism:                                                      # F_m = I_v a_p
        I_v = reals[ints[I_OFFSET_MECHANISM]:ints[I_OFFSET_MECHANISM] + k * k].reshape((k, k))
        mechanism_force = matvec(I_v, a_p)
    else:
        mechanism_force = np.zeros(k)
    C_dot = matvec(E_f, nu)
    w_c = reals[R_CONSTRAINT_FREQUENCY]
    a_f = (-3.0 * w_c * C_dot - 2.0 * w_c * w_c * C) * (1.0 - mask)    # held (kinematic) rows
    if in_contact:                                                     # - K_fd C-dot on the force rows
        K_fd = reals[ints[I_OFFSET_KFD]:ints[I_OFFSET_KFD] + m * m].reshape((m, m))
        a_f = a_f - matvec(K_fd, C_dot) * mask
    M_inverse = M
    mobility = M
    if ints[I_IMPEDANCE] != 0 or n > d:
        M_inverse, singular = inverse(M)
        if singular:
            return FALLBACK, out
        mobility = matmul(matmul(J, M_inverse), transpose(J))          # J M^-1 J^T = Lambda^-1
    if ints[I_IMPEDANCE] != 0:                                         # K_0 [F_v; F_kinematic] (3.2-6)
        # the arm's answer to a force, through a damped discrete step's (M + h B)^-1 (control.damping)
        ok, response = step_task_mobility(J, M, mobility, reals, ints)
        if not ok:
            return FALLBACK, out
        kinematic = np.nonzero(mask == 0.0)[0]
        physical = np.nonzero(mask != 0.0)[0]
        motion_rows = np.empty((k + kinematic.size, d))
        motion_rows[:k] = E_p
        for i in range(kinematic.size):
            motion_rows[k + i] = E_f[kinematic[i]]
        force_rows = np.empty((physical.size, d))
        for i in range(physical.size):
            force_rows[i] = E_f[physical[i]]
        mobility_motion_T = matmul(response, transpose(motion_rows))
        M_fp = matmul(force_rows, mobility_motion_T)
        M_p = matmul(motion_rows, mobility_motion_T)
        K_0 = np.eye(M_p.shape[0]) - M_p
        inverse_mass = reals[ints[I_OFFSET_INVERSE_MASS]:ints[I_OFFSET_INVERSE_MASS] + k * k].reshape((k, k))
        K_0[:k, :k] += inverse_mass - np.eye(k)                        # M_d^-1 on the velocity rows
        if physical.size:
            M_f = matmul(matmul(force_rows, response), transpose(force_rows))
            correction, singular = solve_matrix(M_f, M_fp)
            if singular:
                return FALLBACK, out
            K_0 = K_0 + matmul(transpose(M_fp), correction)
        motion_force = np.empty(k + kinematic.size)
        motion_force[:k] = tangential_force + mechanism_force if mechanism else tangential_force
        for i in range(kinematic.size):
            motion_force[k + i] = force[kinematic[i]]
        compensation = matvec(K_0, motion_force)
        a_p = a_p + compensation[:k]
        for i in range(kinematic.size):
            a_f[kinematic[i]] += compensation[k + i]
    if not in_contact:                                                 # guarded move off the surface
        pressing = -desired_force * mask
        norm = math.sqrt(pressing @ pressing)
        direction = pressing / norm if norm > 0 else pressing
        speed = reals[R_APPROACH_SPEED] if phase == PHASE_APPROACH else 0.0
        gain = reals[R_APPROACH_GAIN]                                  # - K_a^2 (C - C_r): integral action
        a_f = a_f + (-2.0 * gain * (C_dot - speed * direction) - gain * gain * (C - approach_reference)) * mask
    rhs = np.empty(d)
    rhs[:k] = a_p - E_p_dot_nu
    rhs[k:] = -curvature + a_f
    task_acceleration = lu_solve(LU, pivots, rhs)                      # (3.0-11)

    force_command = -desired_force + matvec(K_fp, force_error) + matvec(K_fi, integrals[:m])
    if not in_contact:
        force_command = force_command * (1.0 - mask)
    if ints[I_COMPENSATE_TANGENTIAL] != 0 and ints[I_IMPEDANCE] == 0 and wrench_valid:
        force_command = force_command - force * (1.0 - mask)           # + F_h, F_h = -F on the held rows
    wrench_on_task = matvec(transpose(E_f), force_command)
    if mechanism:                                                      # + E_p^T F_m
        wrench_on_task = wrench_on_task + matvec(transpose(E_p), mechanism_force)
    if ints[I_COMPENSATE_TANGENTIAL] != 0 and ints[I_IMPEDANCE] == 0:  # + E_p^T F_c, F_c = -F_v
        wrench_on_task = wrench_on_task + matvec(transpose(E_p), -tangential_force)
    tau_f = matvec(transpose(J), wrench_on_task)
    task_rhs = task_acceleration - bias

    # diagnostics and the integral rates (frozen by ``finish`` while saturated)
    s = n
    out[s:s + k] = velocity_error
    out[s + k:s + k + m] = force_error
    out[s + k + m:s + k + 2 * m] = C
    out[s + k + 2 * m:s + 2 * k + 2 * m] = projected_velocity
    out[s + 2 * k + 2 * m:s + 2 * k + 3 * m] = force
    out[s + 2 * k + 3 * m:s + 3 * k + 3 * m] = tangential_force
    out[s + 3 * k + 3 * m:s + 3 * k + 4 * m] = force_error if in_contact else force_error * 0.0
    out[s + 3 * k + 4 * m:s + 4 * k + 4 * m] = velocity_error
    scalars = n + 4 * k + 4 * m
    out[scalars + S_WRENCH_VALID] = 1.0 if wrench_valid else 0.0

    threshold, bound = reals[R_SINGULARITY_THRESHOLD], reals[R_MAX_ACCELERATION]
    if n == d:
        ok, joint_acceleration, sigma_min, damping = bounded_solve(J, task_rhs, threshold, bound)
        if not ok:
            return FALLBACK, out
        out[scalars + S_SIGMA_MIN] = sigma_min
        out[scalars + S_DAMPING] = damping
        out[out.size - 2 * n:out.size - n] = joint_acceleration
        out[out.size - n:] = tau_f
        return NEEDS_INVERSE_DYNAMICS, out
    ok, Lambda, sigma_min, damping = bounded_task_inertia(J, M_inverse, mobility, task_rhs, threshold, bound)
    if not ok:
        return FALLBACK, out
    out[scalars + S_SIGMA_MIN] = sigma_min
    out[scalars + S_DAMPING] = damping
    J_T = transpose(J)
    J_bar = matmul(matmul(M_inverse, J_T), Lambda)
    null_space_transpose = np.eye(n) - matmul(J_T, transpose(J_bar))
    motion_torque = (matvec(J_T, matvec(Lambda, task_rhs))
                     - matvec(null_space_transpose, matvec(M, reals[R_NULL_SPACE_DAMPING] * v)))
    torque = base_torque + motion_torque + tau_f
    if ints[I_DAMPING] != 0:
        torque = torque + damping_compensation(matvec(M_inverse, motion_torque), reals, ints)
    return finish(out, torque, base_torque, reals, ints), out


# ------------------------------------------------------------------------------------------------
# The hand-over between the generated constraint module and the law: one scratch vector
# ------------------------------------------------------------------------------------------------
# The generated module (fast_law.py) writes x, nu, J, J-dot q-dot and the constraint terms into
# ``terms``; ``law_from_terms`` reads them. So a new constraint compiles only its own small module,
# not the law again (numba re-optimizes everything a compiled function calls).

def terms_size(ints):
    """Size of the scratch vector (Python: called at construction)."""
    n, d, m, k, configuration = ints[I_N], ints[I_D], ints[I_M], ints[I_K], ints[I_CONFIGURATION]
    return configuration + d + d * n + d + m + m * d + m + m * d + k * d + k


@compiled
def store_terms(terms, x, nu, J, bias, C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu, ints):
    n, d, m, k, configuration = ints[I_N], ints[I_D], ints[I_M], ints[I_K], ints[I_CONFIGURATION]
    s = 0
    terms[s:s + configuration] = x
    s += configuration
    terms[s:s + d] = nu
    s += d
    for i in range(d):
        for j in range(n):
            terms[s + i * n + j] = J[i, j]
    s += d * n
    terms[s:s + d] = bias
    s += d
    terms[s:s + m] = C
    s += m
    for i in range(m):
        for j in range(d):
            terms[s + i * d + j] = E_f[i, j]
    s += m * d
    terms[s:s + m] = curvature
    s += m
    if E_f_dot.shape[0] == m:
        for i in range(m):
            for j in range(d):
                terms[s + i * d + j] = E_f_dot[i, j]
    s += m * d
    if E_p.shape[0] == k:
        for i in range(k):
            for j in range(d):
                terms[s + i * d + j] = E_p[i, j]
        terms[s + k * d:s + k * d + k] = E_p_dot_nu


@compiled
def law_from_terms(terms, v, desired_velocity, desired_acceleration, desired_force, wrench, tool_axis, integrals,
                   phase, approach_reference, M, base_torque, reals, ints):
    """``law_kernel`` on the quantities ``store_terms`` wrote."""
    n, d, m, k, configuration = ints[I_N], ints[I_D], ints[I_M], ints[I_K], ints[I_CONFIGURATION]
    s = 0
    x = terms[s:s + configuration]
    s += configuration
    nu = terms[s:s + d]
    s += d
    J = terms[s:s + d * n].reshape((d, n))
    s += d * n
    bias = terms[s:s + d]
    s += d
    C = terms[s:s + m]
    s += m
    E_f = terms[s:s + m * d].reshape((m, d))
    s += m * d
    curvature = terms[s:s + m]
    s += m
    E_f_dot = terms[s:s + m * d].reshape((m, d))
    s += m * d
    E_p = terms[s:s + k * d].reshape((k, d))
    E_p_dot_nu = terms[s + k * d:s + k * d + k]
    return law_kernel(x, nu, J, bias, C, E_f, curvature, E_f_dot, E_p, E_p_dot_nu, v, desired_velocity,
                      desired_acceleration, desired_force, wrench, tool_axis, integrals, phase, approach_reference,
                      M, base_torque, reals, ints)
