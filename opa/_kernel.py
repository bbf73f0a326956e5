"""The one compiled kernel: every jitted function of the project lives in this module.

It imports nothing from the package (numba's on-disk cache bakes imported globals into
the compiled code and does not notice when another file changes, so a kernel that
imports only numpy and numba is cache-safe by construction; ``tests/opa/test_kernel.py``
enforces that no other module defines jitted code).

One integrator serves every use:

- the DMR (eq. (29)) and each Monte Carlo sample: the deterministic system, N = 0, with a
  one-node rule at xi = 0 (a register-only step for this two-dimensional case);
- the OPA equivalent system (eqs. (24)-(28)) of any order N;
- the variational equation with m tangent columns (m = 0 is the plain run) for the
  Jacobian of the flow map, Floquet multipliers and Lyapunov exponents.

Augmented state, for ``n = N + 1`` coefficients, ``D = 2 n`` and ``m`` tangent columns::

    z = [x_0 .. x_N, v_0 .. v_N,  W[0, 0..m-1], ..., W[D-1, 0..m-1]]
    y' = f(t, y),   W' = J(t, y) W          (J = df/dy)

Right-hand side (Galerkin projection on Q Gauss nodes, pseudo-spectral form)::

    x_i' = v_i
    v_i' = sum_k w_k U_i(xi_k) g(x_k, v_k; p_k) + [i = 0] (f cos(omega t) + force)
    g(x, v; p) = mu (1 - v^2) v - a x - c x^3,    x_k = sum_j x_j U_j(xi_k)

with ``p_k = (mu_k, a_k, c_k)`` the row k of the parameter table: the coefficients at
node xi_k (xi in d dimensions; the kernel sees only the table, the ``n = N + 1`` basis
values of each node and the weights, so one code serves every number of uncertain
parameters and every multi-index set). Exact for Q >= 2N + 1 nodes of the semicircle
density in one dimension; the ``paper`` truncation (eq. (27), one uncertain parameter)
adds back ``sigma/2 * Y_{N+1}`` (``X_{N+1}`` for uncertain c) to the last equation.
The basis is node-major: ``U[k, i] = U_i(xi_k)``, shape (Q, n + 1) (the last column,
U_{N+1}, is read by the paper's closure only).

Steppers: Dormand-Prince 5(4) with Shampine's quartic dense output (``METHOD_DP5``) and
Dormand-Prince 8(5,3) with its seventh-order dense output (``METHOD_DOP853``, the
default). Events: the wall x_0 = delta is found on the dense output and refined by
re-stepping exactly to it (Newton on full Runge-Kutta steps); the impact law applies
the reset to y and its saltation matrix to W; Dirac impulses and pulse switches are
breakpoints at fixed times; chatter ends in sticking, which ends at release.

An optional lower wall x_0 = delta_minus < delta (p[P_DELTA_MINUS], restitution
p[P_ETA_MINUS]; -inf: none) takes the same path mirrored: the wall functions take a
``side`` (+1.0 the upper wall, -1.0 the lower) and look at side (x_0 - wall), the
impact law's formulas hold with the signed v- < 0, sticking rests on the wall nearer
to x_0 (``resting_side``: it is held exactly there) and ends where the force turns away
from it (acc > 0 at the lower wall), a Dirac kick downwards at rest on the lower wall is
an impact at once, and lower-wall events are logged as their kind plus EV_LOWER. The
uncertain wall (C_WALL_NODES) is the upper wall's only; the gap statistic S_GAP (delta -
x_0 at free-flight maxima) has its lower wall's mirror S_GAP_LOWER (x_0 - delta_minus at
free-flight minima), inf and never looked for without a lower wall.
With delta_minus = -inf every lower-wall test (x_0 <= delta_minus, ...) is false and the
upper wall's arithmetic is unchanged (times side = 1.0): one-wall runs give the same bits.

The driver ``integrate`` is a loop over named phases, each a function of the section
"The driver's phases" (some inlined) or of the steppers and the wall scan; a behaviour
is found by its phase:

- ``start_run``: outputs blanked, times and start state checked, impulse train placed;
- at each breakpoint t (output, impulse or pulse end): ``impulses`` (pulses on and off,
  Dirac impulses by ``kick``, a kick into the wall an impact at once), ``store_outputs``
  (and Benettin's ``renormalise_tangent``), ``next_breakpoint``, then the resume:
  f(t, y) for the next step, and ``stick_or_release`` where ``contact_changes`` at t;
- each step: ``step_size``, the trial step (``register_step`` on the 2-D register path,
  chosen once per run; ``rk_step`` otherwise), the error control (``next_step_size``);
- inside an accepted step, on its dense output (``step_dense``): ``first_crossing`` (the
  scan of each wall that ``may_reach_wall``/``may_reach_floor`` leaves in by
  ``wall_crossing``), ``impact_event`` (re-step to the wall, impact law and saltation matrix,
  event log, ``chatter`` -> sticking); while sticking ``pulls_off`` and ``release_event``;
  ``free_flight_gap`` (the gap statistics); then the state advances to the step's end.

Kernels are pure functions of arrays and floats and return status codes; the Python
layer (``opa._simulate``, ``opa.dynamics._orbits``) validates input, packs the parameters and
turns codes into messages.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic

# ---------------------------------------------------------------------------
# Layout of the float parameter vector ``p`` and the integer configuration ``cfg``.
P_MU, P_A, P_C, P_F, P_OMEGA, P_ETA, P_DELTA = 0, 1, 2, 3, 4, 5, 6
P_F0, P_A1, P_OMEGA1, P_N, P_TAU, P_SIGMA = 7, 8, 9, 10, 11, 12
P_CHATTER_V, P_HMAX = 13, 14
# A polynomial force law's nominal coefficients C[j, k] of x^j v^k (j, k <= POLY_DEGREE)
# at P_POLY + (POLY_DEGREE + 1) j + k (the law of a user's model, ``FORCE_POLYNOMIAL``).
POLY_DEGREE = 3
N_POLY = (POLY_DEGREE + 1) ** 2
P_POLY = 15
# The optional lower wall x_0 = delta_minus < delta (motion in delta_minus < x_0 < delta, a
# gear pair's backlash) and its restitution. delta_minus = -inf is no lower wall: every
# check x_0 <= delta_minus is then false, so a one-wall run takes the same floating-point
# path as before the lower wall existed (bit for bit).
P_DELTA_MINUS = P_POLY + N_POLY
P_ETA_MINUS = P_DELTA_MINUS + 1
N_PARAMS = P_ETA_MINUS + 1

C_NCOEF, C_IMPULSE, C_AT_ZERO, C_TRUNC, C_LAW, C_MAXSTEPS, C_METHOD, C_FORCE = range(8)
# C_WALL_NODES = 1: the restitution eta or the wall delta is uncertain, so the impact law
# reads them at each node from the table (columns T_ETA, T_DELTA; p holds their means)
C_WALL_NODES = 8
# C_DRIVE_NODES = 1: the forcing amplitude f, its frequency omega or the impulse height F0
# is uncertain: the vector field adds each node's own f cos(omega t) (table columns T_F,
# T_OMEGA; p holds the nominal values, whose drive every node shares) and a kick adds
# each node's own F0 (T_F0) times the impulse's modulation
C_DRIVE_NODES = 9
# C_FUNCTION: the address of a compiled force function (``FORCE_FUNCTION``), a C function
# double g(double x, double v, double *theta) made in this process by
# ``opa._forcefunction`` (0 for the other laws)
C_FUNCTION = 10
N_CFG = 11
# The force law g(x, v): the paper's mu (1 - v^2) v - a x - c x^3 (from mu, a, c), a
# polynomial sum_jk C[j, k] x^j v^k (a user's model, from its coefficients), or a compiled
# function of a user's (the escape hatch for a force that is not polynomial): it reads its
# N_POLY constants theta where a polynomial law has its coefficients (P_POLY, T_POLY), and
# its Jacobian is taken by central differences (``_function_law``).
FORCE_PAPER, FORCE_POLYNOMIAL, FORCE_FUNCTION = 0, 1, 2

# Columns of the per-node parameter table ``table`` (Q, N_TABLE): the coefficients of the
# force law at each quadrature node (or sample). The kernel never learns which parameter
# is uncertain, nor how many: the Python layer (``opa._problem``) fills the table. The
# paper's law reads mu, a, c; a polynomial law its coefficients C[j, k] at T_POLY + 4 j + k.
T_MU, T_A, T_C = 0, 1, 2
T_POLY = 3
# the restitution and the wall at each node (read only with cfg[C_WALL_NODES] = 1)
T_ETA = T_POLY + N_POLY
T_DELTA = T_ETA + 1
# the forcing amplitude, frequency and impulse height at each node (C_DRIVE_NODES = 1)
T_F, T_OMEGA, T_F0 = T_DELTA + 1, T_DELTA + 2, T_DELTA + 3
N_TABLE = T_F0 + 1

IMPULSE_DIRAC, IMPULSE_PULSE = 0, 1
# The paper's closure (eq. (27)) adds back sigma/2 times the projection on U_{N+1} of the
# cube of the velocities (uncertain mu: PAPER_V) or of the positions (uncertain c: PAPER_X);
# it exists for one uncertain parameter only.
TRUNC_GALERKIN, TRUNC_PAPER_V, TRUNC_PAPER_X = 0, 1, 2
LAW_MEAN, LAW_ENSEMBLE, LAW_SALTATION = 0, 1, 2
METHOD_DP5, METHOD_DOP853 = 0, 1

# Slots of the per-interval ``stats`` output of ``integrate``.
S_IMPACTS, S_MIN_VELOCITY, S_STICKS, S_STEPS, S_STICKING, S_GAP = 0, 1, 2, 3, 4, 5
S_GAP_LOWER = 6  # the lower wall's gap x_0 - delta_minus at free-flight minima (inf: none)
N_STATS = 7

# Kinds in the event log (rows: time, velocity, kind). EV_KICK is an impact made by a
# Dirac kick into the wall while the mean rests on it (logged with the kicked velocity).
EV_IMPACT, EV_GRAZE, EV_STICK, EV_RELEASE, EV_KICK = 0, 1, 2, 3, 4
# An event at the lower wall is logged as its kind plus EV_LOWER (an impact there as
# EV_IMPACT + EV_LOWER, with its pre-impact velocity, negative); the upper wall's kinds
# are unchanged. ``opa._run.Events`` decodes the kind and the wall.
EV_LOWER = 8

# An impact whose pre-impact velocity is below this is logged as a graze (EV_GRAZE), and
# the saltation law, whose matrix divides by it, reflects every v_i instead.
EVENT_GRAZE_VELOCITY = 1e-6

# Impulse and pulse times within this relative distance before an output time belong to
# that output time (t_j = j T1 and t_k = k T are computed differently and may differ by
# an ulp where they coincide in exact arithmetic).
SNAP = 1e-10

# Escape bound: a state component |x_i| or |v_i| at or beyond
#
#     ESCAPE_FACTOR * (1 + max_j |y_j(t0)| + |delta| (+ |delta_minus| with a lower wall)
#                      + (|f| + |F0| (1 + |a1|)) (1 + 1/omega + 1/omega^2 + 1/|a|))
#
# ends the run as escaped (``escape_bound``). The bracket is the problem's own scale: the
# start, the wall, and the largest force (harmonic amplitude plus the largest impulse or
# pulse height) together with the velocity (force / omega) and displacement
# (force / omega^2) it drives over a forcing period, and the static deflection force / |a|
# of a weak spring (a = 3e-5 holds |x| near 7e3 legitimately; with a = 0 there is no
# scale and the bound is infinite: only a non-finite state ends the run). The paper's
# motions stay more than 3000 times inside the bound (|x|, |v| < 11 over 300 periods of
# every preset, against bounds of 4e3 to 3.5e4). The factor is 1e3, not larger, because
# a runaway with the van der Pol term is stiff: with c < 0 the damping mu v^3 holds |v|
# near (|c| x^3 / mu)^(1/3) ~ |x| and the stable step falls like 1/x^2, so the steps
# needed to reach |x| = X grow like X^2 (about 6e6 steps to |x| = 3e3).
ESCAPE_FACTOR = 1e3

# Status codes.
OK, MAX_STEPS, STEP_COLLAPSE, DIVERGED, ESCAPED, BAD_TIME, SKIPPED = 0, 1, 2, 3, 4, 5, 6
STATUS_MESSAGES = {
    OK: "ok",
    MAX_STEPS: "the maximum number of steps was reached",
    STEP_COLLAPSE: "the step size collapsed below round-off",
    DIVERGED: ("the trajectory diverged: the state became non-finite (NaN or inf), the "
               "vector field overflowing even at the smallest step or a jump (impact, "
               "impulse, release) giving a non-finite state"),
    ESCAPED: ("the trajectory diverged: the state escaped (|x| or |x'| beyond the escape "
              "bound 1000 (1 + max|y(t0)| + |delta| (+ |delta_minus|) + (|f| + |F0| (1 + |a1|)) "
              "(1 + 1/omega + 1/omega^2 + 1/|a|)))"),
    SKIPPED: "not integrated: another sample of the ensemble failed first",
    BAD_TIME: ("a time is not finite (NaN or inf), or too large for the impulse times to "
               "be resolved"),
}

# ---------------------------------------------------------------------------
# Dormand-Prince 5(4) (Dormand & Prince 1980) with Shampine's quartic continuous
# extension: y(t + theta h) = y + h sum_s K_s sum_j DP_P[s, j] theta^(j+1).
DP_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
DP_A = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
        [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
    ]
)
DP_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
# Error weights: 5th-order minus embedded 4th-order solution, per stage (7 with FSAL).
DP_E = np.array(
    [71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40]
)
DP_P = np.array(
    [
        [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
        [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
        [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
        [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
        [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
    ]
)

# Dormand-Prince 8(5,3) (Hairer, Norsett & Wanner, Solving ODEs I, section II.10, code
# DOP853): 12 stages, the 13th row of K is f(t + h, y_new) (first row of the next step),
# error from the 5th- and 3rd-order embedded estimates, and a 7th-order dense output
# from three more stages (rows 13-15 of D8_A). Published coefficients, to double
# precision; ``tests/opa/test_kernel.py`` checks their order conditions.
D8_C = np.array([
    0.0,
    0.05260015195876773,
    0.0789002279381516,
    0.1183503419072274,
    0.2816496580927726,
    0.3333333333333333,
    0.25,
    0.3076923076923077,
    0.6512820512820513,
    0.6,
    0.8571428571428571,
    1.0,
    1.0,
    0.1,
    0.2,
    0.7777777777777778,
])
D8_A = np.zeros((16, 16))
D8_A[1, :1] = [0.05260015195876773]
D8_A[2, :2] = [0.0197250569845379, 0.0591751709536137]
D8_A[3, :3] = [0.02958758547680685, 0.0, 0.08876275643042054]
D8_A[4, :4] = [0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792]
D8_A[5, :5] = [0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242]
D8_A[6, :6] = [0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125]
D8_A[7, :7] = [0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328,
    -0.015319437748624402, 0.008273789163814023]
D8_A[8, :8] = [0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726,
    27.59209969944671, 20.154067550477894, -43.48988418106996]
D8_A[9, :9] = [0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843,
    21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627]
D8_A[10, :10] = [-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295,
    -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523,
        -3.0467644718982196]
D8_A[11, :11] = [2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625,
    -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063,
        12.360567175794303, 0.6433927460157636]
D8_A[12, :12] = [0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003,
    -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034,
        0.04471061572777259]
D8_A[13, :13] = [0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483,
    -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469,
        0.007567897660545699, -0.008298]
D8_A[14, :14] = [0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776,
    0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932,
        0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325]
D8_A[15, :15] = [-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599,
    4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145,
        2.9475147891527724, -9.15095847217987]
D8_B = np.array([
    0.054293734116568765,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    0.3111643669578199,
    -0.1521609496625161,
    0.20136540080403034,
    0.04471061572777259,
])
D8_E3 = np.array([
    -0.18980075407240762,
    0.0,
    0.0,
    0.0,
    0.0,
    4.450312892752409,
    1.8915178993145003,
    -5.801203960010585,
    -0.4226823213237919,
    -0.1521609496625161,
    0.20136540080403034,
    0.02265179219836082,
    0.0,
])
D8_E5 = np.array([
    0.01312004499419488,
    0.0,
    0.0,
    0.0,
    0.0,
    -1.2251564463762044,
    -0.4957589496572502,
    1.6643771824549864,
    -0.35032884874997366,
    0.3341791187130175,
    0.08192320648511571,
    -0.022355307863886294,
    0.0,
])
D8_D = np.zeros((4, 16))
D8_D[0, :16] = [-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917,
    2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883,
        0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356,
            -4.436036387594894]
D8_D[1, :16] = [10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028,
    -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398,
        -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448,
            35.81684148639408]
D8_D[2, :16] = [19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758,
    527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838,
        0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716,
            11.99229113618279]
D8_D[3, :16] = [-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455,
    357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623,
        29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544,
            -149.72683625798564]

# Rows of the stage array K: DOP853's 12 stages, f(t + h, y_new) and its 3 dense stages.
K_ROWS = 16
N_SCAN = 8
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


@njit(cache=True)
def last_stage(method):
    """The row of K that holds f(t + h, y_new) (the first row of the next step)."""
    return 6 if method == METHOD_DP5 else 12


# ---------------------------------------------------------------------------
# Model
@njit(cache=True)
def impulse_strength(t, p):
    """Impulse magnitude F0 (1 + a1 sin(omega1 t / n)) at an impulse time t (eq. (1))."""
    return p[P_F0] * impulse_modulation(t, p)


@njit(cache=True, inline="always")
def impulse_modulation(t, p):
    """The impulse's modulation 1 + a1 sin(omega1 t / n) at an impulse time t."""
    return 1.0 + p[P_A1] * math.sin(p[P_OMEGA1] * t / p[P_N])


@njit(cache=True, inline="always")
def forcing(t, p, force):
    """The external force at t: f cos(omega t) plus the pulse force ``force`` (0 for
    Dirac impulses or between pulses). The steppers evaluate it at their stages with
    ``stage_forcing``."""
    return p[P_F] * math.cos(p[P_OMEGA] * t) + force


@njit(cache=True, inline="always")
def _cos_sin_small(d):
    """cos d and sin d for |d| <= 0.5 by their Taylor series to d^16 and d^17 (remainders
    below 6e-22 there): multiplications instead of a libm call."""
    u = d * d
    c = 1.0 + u * (-1.0 / 2 + u * (1.0 / 24 + u * (-1.0 / 720 + u * (1.0 / 40320 + u * (
        -1.0 / 3628800 + u * (1.0 / 479001600 + u * (-1.0 / 87178291200
                                                    + u * (1.0 / 20922789888000))))))))
    s = d * (1.0 + u * (-1.0 / 6 + u * (1.0 / 120 + u * (-1.0 / 5040 + u * (1.0 / 362880 + u * (
        -1.0 / 39916800 + u * (1.0 / 6227020800 + u * (-1.0 / 1307674368000
                                                      + u * (1.0 / 355687428096000)))))))))
    return c, s


@njit(cache=True, inline="always")
def stage_forcing(t, theta, h, f, w, cw, sw, force):
    """``forcing`` at t + theta h within a step from t: with cw = cos(omega t),
    sw = sin(omega t) computed once per step, cos(omega t + d) = cw cos d - sw sin d with
    d = theta omega h from its series (at d/4 and doubled twice for |d| up to 2); a libm
    cosine per stage for larger steps. A cosine per stage was a quarter of a DMR run.

    Inlined into the 2-D step, where a call per stage took 17% of an ensemble's profile;
    callers use ``stage_drive``. The rarer long steps go through ``_stage_forcing_long``."""
    d = theta * w * h
    if abs(d) <= 0.5:
        cd, sd = _cos_sin_small(d)
        return f * (cw * cd - sw * sd) + force
    return _stage_forcing_long(t, theta, h, f, w, cw, sw, force)


@njit(cache=True)
def stage_drive(t, theta, h, f, w, cw, sw, force):
    """``stage_forcing`` as a call (the general loops and the dense-output stages)."""
    return stage_forcing(t, theta, h, f, w, cw, sw, force)


@njit(cache=True)
def _stage_forcing_long(t, theta, h, f, w, cw, sw, force):
    """``stage_forcing`` for |theta omega h| > 0.5."""
    d = theta * w * h
    if abs(d) <= 2.0:
        cd, sd = _cos_sin_small(0.25 * d)
        cd, sd = cd * cd - sd * sd, 2.0 * sd * cd
        cd, sd = cd * cd - sd * sd, 2.0 * sd * cd
    else:
        return f * math.cos(w * (t + theta * h)) + force
    return f * (cw * cd - sw * sd) + force


@njit(cache=True, inline="always")
def force_law(p):
    """A polynomial force law's coefficients in scalars, (C[0, 0], C[0, 1], ..., C[3, 3]),
    then the highest power k of v in its cross terms (C[j, k] != 0 with j, k >= 1; 0.0
    when it has none), for its 2-D register path (a tuple is passed by value: no
    reference counts). That power is found here, once per run, not in each stage: a test
    of the nine coefficients in each stage cost a DMR run 8 %. Not for the general vector
    field (``_poly_of_p``)."""
    q = P_POLY
    cross = 0.0
    for j in range(1, POLY_DEGREE + 1):
        for k in range(1, POLY_DEGREE + 1):
            if p[q + (POLY_DEGREE + 1) * j + k] != 0.0:
                cross = max(cross, float(k))
    return (p[q], p[q + 1], p[q + 2], p[q + 3], p[q + 4], p[q + 5], p[q + 6], p[q + 7],
            p[q + 8], p[q + 9], p[q + 10], p[q + 11], p[q + 12], p[q + 13], p[q + 14],
            p[q + 15], cross)


@njit(cache=True, inline="always")
def _poly_horner(x, v, c00, c10, c20, c30, c01, c11, c21, c31, c02, c12, c22, c32, c03, c13,
                 c23, c33):
    """g = sum_jk C[j, k] x^j v^k and its partial derivatives (g, dg/dx, dg/dv), by
    Horner in x for each power of v, then in v; g summed as ``_poly_value`` sums it
    (its cross terms added even when zero, which leaves g's bits as they are), so the
    general loop and the 2-D register path agree bit for bit."""
    p0 = c00 + x * (c10 + x * (c20 + x * c30))
    p1 = c01 + x * (c11 + x * (c21 + x * c31))
    p2 = c02 + x * (c12 + x * (c22 + x * c32))
    p3 = c03 + x * (c13 + x * (c23 + x * c33))
    d0 = c10 + x * (2.0 * c20 + x * 3.0 * c30)
    d1 = c11 + x * (2.0 * c21 + x * 3.0 * c31)
    d2 = c12 + x * (2.0 * c22 + x * 3.0 * c32)
    d3 = c13 + x * (2.0 * c23 + x * 3.0 * c33)
    g = p0 + v * (c01 + v * (c02 + v * c03))
    g += x * v * ((c11 + x * (c21 + x * c31)) + v * ((c12 + x * (c22 + x * c32))
                                                      + v * (c13 + x * (c23 + x * c33))))
    gx = d0 + v * (d1 + v * (d2 + v * d3))
    gv = p1 + v * (2.0 * p2 + v * 3.0 * p3)
    return g, gx, gv


@njit(cache=True, inline="always")
def _poly_value(x, v, law):
    """g = sum_jk C[j, k] x^j v^k of a ``force_law`` tuple, without its derivatives:
    the x-only and v-only terms by Horner, and the cross terms x v sum C[j, k]
    x^(j-1) v^(k-1) (j, k >= 1) only up to the highest power of v ``force_law`` found
    in them. Most laws (the paper's, Duffing's, Shaw and Holmes's) have none and cost
    about what the built-in law does; van der Pol's x^2 v takes one row."""
    g = (law[0] + x * (law[4] + x * (law[8] + x * law[12]))
         + v * (law[1] + v * (law[2] + v * law[3])))
    top = law[N_POLY]  # the highest power of v in the cross terms (``force_law``)
    if top != 0.0:  # the rows above ``top`` are exactly 0: skipping them changes no bit
        cross = law[5] + x * (law[9] + x * law[13])
        if top == 2.0:
            cross += v * (law[6] + x * (law[10] + x * law[14]))
        elif top == 3.0:
            cross += v * ((law[6] + x * (law[10] + x * law[14]))
                          + v * (law[7] + x * (law[11] + x * law[15])))
        g += x * v * cross
    return g


@njit(cache=True, inline="always")
def _poly_of_p(x, v, p):
    """g of the parameter vector's own polynomial law, every term summed (the same bits
    as ``_poly_value``: the rows it skips are exactly 0). For ``vector_field``, which
    reads p directly: ``force_law``'s search of the cross terms, inlined there, made the
    built-in law's OPA 20 % slower."""
    q = P_POLY
    g, _, _ = _poly_horner(x, v, p[q], p[q + 4], p[q + 8], p[q + 12], p[q + 1], p[q + 5],
                           p[q + 9], p[q + 13], p[q + 2], p[q + 6], p[q + 10], p[q + 14],
                           p[q + 3], p[q + 7], p[q + 11], p[q + 15])
    return g


@njit(cache=True, inline="always")
def _poly_row(table, k, x, v):
    """``_poly_horner`` of the polynomial coefficients in row k of the table."""
    q = T_POLY
    return _poly_horner(x, v, table[k, q], table[k, q + 4], table[k, q + 8], table[k, q + 12],
                        table[k, q + 1], table[k, q + 5], table[k, q + 9], table[k, q + 13],
                        table[k, q + 2], table[k, q + 6], table[k, q + 10], table[k, q + 14],
                        table[k, q + 3], table[k, q + 7], table[k, q + 11], table[k, q + 15])


def _on_gpu(context) -> bool:
    """Whether code is generated for a CUDA device (numba-cuda's target context), where a
    host function pointer means nothing: a compiled force function is refused there
    before any launch (``opa._run``), and its two intrinsics below compile to constants."""
    return type(context).__name__.startswith("CUDA")


@intrinsic
def _call_function(typingctx, address, x, v, theta):
    """g(x, v, theta) of the C function at ``address`` (an int64), with ``theta`` the
    address of its constants (an int64): a call through a pointer, so one compiled kernel
    serves every user's function (and its on-disk cache stays valid). NaN on a GPU."""
    sig = types.float64(types.int64, types.float64, types.float64, types.int64)

    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        if _on_gpu(context):
            return ir.Constant(double, math.nan)
        fnty = ir.FunctionType(double, [double, double, double.as_pointer()])
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, [args[1], args[2], builder.inttoptr(args[3],
                                                                    double.as_pointer())])
    return sig, codegen


@intrinsic
def _element_address(typingctx, array, offset):
    """The address (an int64) of element ``offset`` of a C-contiguous float64 array,
    counted in its flat layout; 0 on a GPU (``_call_function``)."""
    if not (isinstance(array, types.Array) and array.dtype == types.float64
            and array.layout == "C"):
        return None
    sig = types.int64(array, types.int64)

    def codegen(context, builder, signature, args):
        if _on_gpu(context):
            return ir.Constant(ir.IntType(64), 0)
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.ptrtoint(builder.gep(data, [args[1]]), ir.IntType(64))
    return sig, codegen


#: relative step of the central differences of a compiled force function's Jacobian
FUNCTION_STEP = 1e-6


@njit(cache=True, inline="always")
def _function_law(address, x, v, theta, derivatives):
    """(g, dg/dx, dg/dv) of a compiled force function (``FORCE_FUNCTION``) with its
    constants at the address ``theta``; the derivatives by central differences of step
    FUNCTION_STEP (1 + |x|), only when ``derivatives`` (else 0)."""
    g = _call_function(address, x, v, theta)
    if not derivatives:
        return g, 0.0, 0.0
    hx = FUNCTION_STEP * (1.0 + abs(x))
    hv = FUNCTION_STEP * (1.0 + abs(v))
    gx = (_call_function(address, x + hx, v, theta)
          - _call_function(address, x - hx, v, theta)) / (2.0 * hx)
    gv = (_call_function(address, x, v + hv, theta)
          - _call_function(address, x, v - hv, theta)) / (2.0 * hv)
    return g, gx, gv


@njit(cache=True, inline="always")
def _theta_of_p(p):
    """The address of a compiled force function's constants in the parameter vector."""
    return _element_address(p, np.int64(P_POLY))


@njit(cache=True, inline="always")
def _theta_of_row(table, k):
    """The address of a compiled force function's constants in row k of the table."""
    return _element_address(table, k * table.shape[1] + T_POLY)


@njit(cache=True, inline="always")
def _f2(x, v, mu, a, c, drive, sticking):
    """Deterministic right-hand side on scalars, (x', v') of eq. (29), with the external
    force ``drive`` at that time."""
    if sticking:
        return 0.0, 0.0
    return v, mu * (1.0 - v * v) * v - a * x - c * x * x * x + drive


@njit(cache=True, inline="always")
def _f2_poly(x, v, law, drive, sticking):
    """``_f2`` of a polynomial force law (``force_law``'s tuple)."""
    if sticking:
        return 0.0, 0.0
    return v, _poly_value(x, v, law) + drive


@njit(cache=True, inline="always")
def _f2_fn(x, v, address, theta, drive, sticking):
    """``_f2`` of a compiled force function (its address, its constants' address)."""
    if sticking:
        return 0.0, 0.0
    return v, _call_function(address, x, v, theta) + drive


@njit(cache=True, inline="always")
def _own_law(cfg, table, p):
    """Row 0 of the table holds the parameter vector's own force law."""
    if cfg[C_FORCE] == FORCE_PAPER:
        return (table[0, T_MU] == p[P_MU] and table[0, T_A] == p[P_A]
                and table[0, T_C] == p[P_C])
    for i in range(N_POLY):
        if table[0, T_POLY + i] != p[P_POLY + i]:
            return False
    return True


@njit(cache=True)
def is_deterministic(m, cfg, table, p):
    """The plain two-dimensional system (the DMR or one sample): N = 0, no tangents and
    a one-node table holding the parameter vector's own coefficients."""
    return (m == 0 and cfg[C_NCOEF] == 1 and table.shape[0] == 1
            and _own_law(cfg, table, p))


@njit(cache=True)
def vector_field(z, m, p, cfg, table, weights, U, t, drive, sticking, out, work):
    """Write f(t, y) and, for m > 0, J(t, y) W into ``out`` (layout of ``z``).

    ``drive`` is the external force at t (``forcing``: harmonic plus pulse); with
    ``cfg[C_DRIVE_NODES]`` each node's own harmonic f_k cos(omega_k t) replaces it. With
    ``sticking`` the mean coordinate is held at rest at the wall (and its rows of W).
    ``work`` is a (6, Q) scratch array. Returns the unconstrained acceleration of x_0
    (the release function of sticking).
    """
    n = cfg[C_NCOEF]
    # is_deterministic written out: a call would count references of three arrays
    poly = cfg[C_FORCE] == FORCE_POLYNOMIAL
    function = cfg[C_FORCE] == FORCE_FUNCTION
    if m == 0 and n == 1 and table.shape[0] == 1 and (
            (not poly and not function and table[0, T_MU] == p[P_MU] and table[0, T_A] == p[P_A]
             and table[0, T_C] == p[P_C]) or ((poly or function) and _own_law(cfg, table, p))):
        if function:
            dx = z[1]
            dv = _call_function(cfg[C_FUNCTION], z[0], z[1], _theta_of_p(p)) + drive
        elif poly:
            dx = z[1]
            dv = _poly_of_p(z[0], z[1], p) + drive
        else:
            dx, dv = _f2(z[0], z[1], p[P_MU], p[P_A], p[P_C], drive, False)
        out[0] = 0.0 if sticking else dx
        out[1] = 0.0 if sticking else dv
        return dv
    dim = 2 * n
    q = table.shape[0]
    closure = cfg[C_TRUNC]
    sigma = p[P_SIGMA]
    # work rows 0-5: x and v at the nodes, the Jacobian weights (of x and of v), and one
    # tangent column's x and v at the nodes, indexed in place (a row view counts references)
    for k in range(q):
        xs = 0.0
        vs = 0.0
        for i in range(n):
            xs += z[i] * U[k, i]
            vs += z[n + i] * U[k, i]
        work[0, k] = xs
        work[1, k] = vs
    # Project the deviation g_k - g_0 from the force at the mean state; the constant g_0
    # goes to U_0 alone. Mathematically the same projection (sum_k w_k U_i(xi_k) = [i = 0]),
    # but with sigma = 0 and zero higher coefficients every g_k equals g_0 bit for bit, so
    # the higher modes stay exactly zero and EMR_0 is the DMR (the ~1e-17 round-off of
    # that sum would otherwise be amplified by the transverse instability).
    x0 = z[0]
    v0 = z[n]
    if function:
        g0 = _call_function(cfg[C_FUNCTION], x0, v0, _theta_of_p(p))
    elif poly:
        g0 = _poly_of_p(x0, v0, p)
    else:
        g0 = p[P_MU] * (1.0 - v0 * v0) * v0 - p[P_A] * x0 - p[P_C] * x0 * x0 * x0
    for i in range(n):
        out[i] = z[n + i]
        out[n + i] = 0.0
    out[n] = g0
    drive_nodes = cfg[C_DRIVE_NODES] != 0
    shared = p[P_F] * math.cos(p[P_OMEGA] * t) if drive_nodes else 0.0
    for k in range(q):
        x = work[0, k]
        v = work[1, k]
        w = weights[k]
        if poly or function:
            if function:
                gk, gx, gv = _function_law(cfg[C_FUNCTION], x, v, _theta_of_row(table, k),
                                           m > 0)
            else:
                gk, gx, gv = _poly_row(table, k, x, v)
            g = w * (gk - g0)
            if m > 0:
                work[2, k] = w * gx
                work[3, k] = w * gv
        else:
            mu_k = table[k, T_MU]
            a_k = table[k, T_A]
            c_k = table[k, T_C]
            g = w * (mu_k * (1.0 - v * v) * v - a_k * x - c_k * x * x * x - g0)
            if m > 0:
                work[2, k] = w * (-a_k - 3.0 * c_k * x * x)
                work[3, k] = w * mu_k * (1.0 - 3.0 * v * v)
        if drive_nodes:  # this node's own harmonic drive, less the shared one in ``drive``
            g += w * (table[k, T_F] * math.cos(table[k, T_OMEGA] * t) - shared)
        if g != 0.0:
            for i in range(n):
                out[n + i] += g * U[k, i]
    paper = closure != TRUNC_GALERKIN and sigma != 0.0
    if paper:
        # eq. (27) drops the projection of the xi * cubic term on U_{N+1}: add it back
        extra = 0.0
        for k in range(q):
            if closure == TRUNC_PAPER_V:
                extra += weights[k] * U[k, n] * work[1, k] ** 3
            else:
                extra += weights[k] * U[k, n] * work[0, k] ** 3
        out[dim - 1] += 0.5 * sigma * extra
    out[n] += drive
    release = out[n]
    if sticking:
        out[0] = 0.0
        out[n] = 0.0
    for c in range(m):
        for k in range(q):
            dx = 0.0
            dv = 0.0
            for j in range(n):
                dx += U[k, j] * z[dim + j * m + c]
                dv += U[k, j] * z[dim + (n + j) * m + c]
            work[4, k] = dx
            work[5, k] = dv
        for i in range(n):
            out[dim + i * m + c] = z[dim + (n + i) * m + c]
            acc = 0.0
            for k in range(q):
                acc += U[k, i] * (work[2, k] * work[4, k] + work[3, k] * work[5, k])
            out[dim + (n + i) * m + c] = acc
        if paper:
            extra = 0.0
            for k in range(q):
                if closure == TRUNC_PAPER_V:
                    extra += weights[k] * U[k, n] * 3.0 * work[1, k] ** 2 * work[5, k]
                else:
                    extra += weights[k] * U[k, n] * 3.0 * work[0, k] ** 2 * work[4, k]
            out[dim + (dim - 1) * m + c] += 0.5 * sigma * extra
        if sticking:
            out[dim + c] = 0.0
            out[dim + n * m + c] = 0.0
    return release


# ---------------------------------------------------------------------------
# Runge-Kutta steps
# The two-dimensional system (the DMR, a Monte Carlo sample) has its own step, with every
# stage in a scalar: the two functions below are generated from the tableaux by
# ``tests/opa/test_kernel.py::unrolled_step`` (which checks that they still match) and sum
# in the order of the general loops, so both paths give the same bits. Scalars also keep
# arrays out of the calls: numba increments and decrements the reference count of every
# array argument atomically, which cost 44% of a DMR run with the general argument list.
@njit(cache=True)
def _stages2_dop853(t, x, v, h, k0x, k0v, mu, a, c, f, w, cw, sw, force, sticking):
    """One step of the 2-D system, generated from the tableau (see ``step2``)."""
    x1 = x + h * (0.05260015195876773 * k0x)
    v1 = v + h * (0.05260015195876773 * k0v)
    drive = stage_forcing(t, 0.05260015195876773, h, f, w, cw, sw, force)
    k1x, k1v = _f2(x1, v1, mu, a, c, drive, sticking)
    x2 = x + h * (0.0197250569845379 * k0x + 0.0591751709536137 * k1x)
    v2 = v + h * (0.0197250569845379 * k0v + 0.0591751709536137 * k1v)
    drive = stage_forcing(t, 0.0789002279381516, h, f, w, cw, sw, force)
    k2x, k2v = _f2(x2, v2, mu, a, c, drive, sticking)
    x3 = x + h * (0.02958758547680685 * k0x + 0.08876275643042054 * k2x)
    v3 = v + h * (0.02958758547680685 * k0v + 0.08876275643042054 * k2v)
    drive = stage_forcing(t, 0.1183503419072274, h, f, w, cw, sw, force)
    k3x, k3v = _f2(x3, v3, mu, a, c, drive, sticking)
    x4 = x + h * (0.2413651341592667 * k0x + -0.8845494793282861 * k2x + 0.924834003261792 * k3x)
    v4 = v + h * (0.2413651341592667 * k0v + -0.8845494793282861 * k2v + 0.924834003261792 * k3v)
    drive = stage_forcing(t, 0.2816496580927726, h, f, w, cw, sw, force)
    k4x, k4v = _f2(x4, v4, mu, a, c, drive, sticking)
    x5 = x + h * (0.037037037037037035 * k0x + 0.17082860872947386 * k3x +
                  0.12546768756682242 * k4x)
    v5 = v + h * (0.037037037037037035 * k0v + 0.17082860872947386 * k3v +
                  0.12546768756682242 * k4v)
    drive = stage_forcing(t, 0.3333333333333333, h, f, w, cw, sw, force)
    k5x, k5v = _f2(x5, v5, mu, a, c, drive, sticking)
    x6 = x + h * (0.037109375 * k0x + 0.17025221101954405 * k3x + 0.06021653898045596 * k4x +
                  -0.017578125 * k5x)
    v6 = v + h * (0.037109375 * k0v + 0.17025221101954405 * k3v + 0.06021653898045596 * k4v +
                  -0.017578125 * k5v)
    drive = stage_forcing(t, 0.25, h, f, w, cw, sw, force)
    k6x, k6v = _f2(x6, v6, mu, a, c, drive, sticking)
    x7 = x + h * (0.03709200011850479 * k0x + 0.17038392571223998 * k3x +
                  0.10726203044637328 * k4x + -0.015319437748624402 * k5x +
                  0.008273789163814023 * k6x)
    v7 = v + h * (0.03709200011850479 * k0v + 0.17038392571223998 * k3v +
                  0.10726203044637328 * k4v + -0.015319437748624402 * k5v +
                  0.008273789163814023 * k6v)
    drive = stage_forcing(t, 0.3076923076923077, h, f, w, cw, sw, force)
    k7x, k7v = _f2(x7, v7, mu, a, c, drive, sticking)
    x8 = x + h * (0.6241109587160757 * k0x + -3.3608926294469414 * k3x + -0.868219346841726 * k4x +
                  27.59209969944671 * k5x + 20.154067550477894 * k6x + -43.48988418106996 * k7x)
    v8 = v + h * (0.6241109587160757 * k0v + -3.3608926294469414 * k3v + -0.868219346841726 * k4v +
                  27.59209969944671 * k5v + 20.154067550477894 * k6v + -43.48988418106996 * k7v)
    drive = stage_forcing(t, 0.6512820512820513, h, f, w, cw, sw, force)
    k8x, k8v = _f2(x8, v8, mu, a, c, drive, sticking)
    x9 = x + h * (0.47766253643826434 * k0x + -2.4881146199716677 * k3x +
                  -0.590290826836843 * k4x + 21.230051448181193 * k5x + 15.279233632882423 * k6x +
                  -33.28821096898486 * k7x + -0.020331201708508627 * k8x)
    v9 = v + h * (0.47766253643826434 * k0v + -2.4881146199716677 * k3v +
                  -0.590290826836843 * k4v + 21.230051448181193 * k5v + 15.279233632882423 * k6v +
                  -33.28821096898486 * k7v + -0.020331201708508627 * k8v)
    drive = stage_forcing(t, 0.6, h, f, w, cw, sw, force)
    k9x, k9v = _f2(x9, v9, mu, a, c, drive, sticking)
    x10 = x + h * (-0.9371424300859873 * k0x + 5.186372428844064 * k3x + 1.0914373489967295 * k4x +
                   -8.149787010746927 * k5x + -18.52006565999696 * k6x + 22.739487099350505 * k7x +
                   2.4936055526796523 * k8x + -3.0467644718982196 * k9x)
    v10 = v + h * (-0.9371424300859873 * k0v + 5.186372428844064 * k3v + 1.0914373489967295 * k4v +
                   -8.149787010746927 * k5v + -18.52006565999696 * k6v + 22.739487099350505 * k7v +
                   2.4936055526796523 * k8v + -3.0467644718982196 * k9v)
    drive = stage_forcing(t, 0.8571428571428571, h, f, w, cw, sw, force)
    k10x, k10v = _f2(x10, v10, mu, a, c, drive, sticking)
    x11 = x + h * (2.273310147516538 * k0x + -10.53449546673725 * k3x + -2.0008720582248625 * k4x +
                   -17.9589318631188 * k5x + 27.94888452941996 * k6x + -2.8589982771350235 * k7x +
                   -8.87285693353063 * k8x + 12.360567175794303 * k9x + 0.6433927460157636 * k10x)
    v11 = v + h * (2.273310147516538 * k0v + -10.53449546673725 * k3v + -2.0008720582248625 * k4v +
                   -17.9589318631188 * k5v + 27.94888452941996 * k6v + -2.8589982771350235 * k7v +
                   -8.87285693353063 * k8v + 12.360567175794303 * k9v + 0.6433927460157636 * k10v)
    drive = stage_forcing(t, 1.0, h, f, w, cw, sw, force)
    k11x, k11v = _f2(x11, v11, mu, a, c, drive, sticking)
    xn = x + h * (0.054293734116568765 * k0x + 4.450312892752409 * k5x + 1.8915178993145003 * k6x +
                  -5.801203960010585 * k7x + 0.3111643669578199 * k8x + -0.1521609496625161 * k9x +
                  0.20136540080403034 * k10x + 0.04471061572777259 * k11x)
    vn = v + h * (0.054293734116568765 * k0v + 4.450312892752409 * k5v + 1.8915178993145003 * k6v +
                  -5.801203960010585 * k7v + 0.3111643669578199 * k8v + -0.1521609496625161 * k9v +
                  0.20136540080403034 * k10v + 0.04471061572777259 * k11v)
    k12x, k12v = _f2(xn, vn, mu, a, c, drive, sticking)
    kx = (k1x, k2x, k3x, k4x, k5x, k6x, k7x, k8x, k9x, k10x, k11x, k12x)
    kv = (k1v, k2v, k3v, k4v, k5v, k6v, k7v, k8v, k9v, k10v, k11v, k12v)
    return xn, vn, kx, kv


@njit(cache=True)
def _dense_stages2_dop853(t, h, K, x, v, mu, a, c, f, w, cw, sw, force, sticking):
    """Rows 13-15 of K (the dense-output stages) of the 2-D system, generated from
    the tableau (see ``step2``)."""
    x13 = x + h * (0.056167502283047954 * K[0, 0] + 0.25350021021662483 * K[6, 0] +
                   -0.2462390374708025 * K[7, 0] + -0.12419142326381637 * K[8, 0] +
                   0.15329179827876568 * K[9, 0] + 0.00820105229563469 * K[10, 0] +
                   0.007567897660545699 * K[11, 0] + -0.008298 * K[12, 0])
    v13 = v + h * (0.056167502283047954 * K[0, 1] + 0.25350021021662483 * K[6, 1] +
                   -0.2462390374708025 * K[7, 1] + -0.12419142326381637 * K[8, 1] +
                   0.15329179827876568 * K[9, 1] + 0.00820105229563469 * K[10, 1] +
                   0.007567897660545699 * K[11, 1] + -0.008298 * K[12, 1])
    drive = stage_drive(t, 0.1, h, f, w, cw, sw, force)
    k13x, k13v = _f2(x13, v13, mu, a, c, drive, sticking)
    K[13, 0] = k13x
    K[13, 1] = k13v
    x14 = x + h * (0.03183464816350214 * K[0, 0] + 0.028300909672366776 * K[5, 0] +
                   0.053541988307438566 * K[6, 0] + -0.05492374857139099 * K[7, 0] +
                   -0.00010834732869724932 * K[10, 0] + 0.0003825710908356584 * K[11, 0] +
                   -0.00034046500868740456 * K[12, 0] + 0.1413124436746325 * k13x)
    v14 = v + h * (0.03183464816350214 * K[0, 1] + 0.028300909672366776 * K[5, 1] +
                   0.053541988307438566 * K[6, 1] + -0.05492374857139099 * K[7, 1] +
                   -0.00010834732869724932 * K[10, 1] + 0.0003825710908356584 * K[11, 1] +
                   -0.00034046500868740456 * K[12, 1] + 0.1413124436746325 * k13v)
    drive = stage_drive(t, 0.2, h, f, w, cw, sw, force)
    k14x, k14v = _f2(x14, v14, mu, a, c, drive, sticking)
    K[14, 0] = k14x
    K[14, 1] = k14v
    x15 = x + h * (-0.42889630158379194 * K[0, 0] + -4.697621415361164 * K[5, 0] +
                   7.683421196062599 * K[6, 0] + 4.06898981839711 * K[7, 0] +
                   0.3567271874552811 * K[8, 0] + -0.0013990241651590145 * K[12, 0] +
                   2.9475147891527724 * k13x + -9.15095847217987 * k14x)
    v15 = v + h * (-0.42889630158379194 * K[0, 1] + -4.697621415361164 * K[5, 1] +
                   7.683421196062599 * K[6, 1] + 4.06898981839711 * K[7, 1] +
                   0.3567271874552811 * K[8, 1] + -0.0013990241651590145 * K[12, 1] +
                   2.9475147891527724 * k13v + -9.15095847217987 * k14v)
    drive = stage_drive(t, 0.7777777777777778, h, f, w, cw, sw, force)
    k15x, k15v = _f2(x15, v15, mu, a, c, drive, sticking)
    K[15, 0] = k15x
    K[15, 1] = k15v


@njit(cache=True)
def _stages2_dop853_poly(t, x, v, h, k0x, k0v, law, f, w, cw, sw, force, sticking):
    """One step of the 2-D system, generated from the tableau (see ``step2``)."""
    x1 = x + h * (0.05260015195876773 * k0x)
    v1 = v + h * (0.05260015195876773 * k0v)
    drive = stage_forcing(t, 0.05260015195876773, h, f, w, cw, sw, force)
    k1x, k1v = _f2_poly(x1, v1, law, drive, sticking)
    x2 = x + h * (0.0197250569845379 * k0x + 0.0591751709536137 * k1x)
    v2 = v + h * (0.0197250569845379 * k0v + 0.0591751709536137 * k1v)
    drive = stage_forcing(t, 0.0789002279381516, h, f, w, cw, sw, force)
    k2x, k2v = _f2_poly(x2, v2, law, drive, sticking)
    x3 = x + h * (0.02958758547680685 * k0x + 0.08876275643042054 * k2x)
    v3 = v + h * (0.02958758547680685 * k0v + 0.08876275643042054 * k2v)
    drive = stage_forcing(t, 0.1183503419072274, h, f, w, cw, sw, force)
    k3x, k3v = _f2_poly(x3, v3, law, drive, sticking)
    x4 = x + h * (0.2413651341592667 * k0x + -0.8845494793282861 * k2x + 0.924834003261792 * k3x)
    v4 = v + h * (0.2413651341592667 * k0v + -0.8845494793282861 * k2v + 0.924834003261792 * k3v)
    drive = stage_forcing(t, 0.2816496580927726, h, f, w, cw, sw, force)
    k4x, k4v = _f2_poly(x4, v4, law, drive, sticking)
    x5 = x + h * (0.037037037037037035 * k0x + 0.17082860872947386 * k3x +
                  0.12546768756682242 * k4x)
    v5 = v + h * (0.037037037037037035 * k0v + 0.17082860872947386 * k3v +
                  0.12546768756682242 * k4v)
    drive = stage_forcing(t, 0.3333333333333333, h, f, w, cw, sw, force)
    k5x, k5v = _f2_poly(x5, v5, law, drive, sticking)
    x6 = x + h * (0.037109375 * k0x + 0.17025221101954405 * k3x + 0.06021653898045596 * k4x +
                  -0.017578125 * k5x)
    v6 = v + h * (0.037109375 * k0v + 0.17025221101954405 * k3v + 0.06021653898045596 * k4v +
                  -0.017578125 * k5v)
    drive = stage_forcing(t, 0.25, h, f, w, cw, sw, force)
    k6x, k6v = _f2_poly(x6, v6, law, drive, sticking)
    x7 = x + h * (0.03709200011850479 * k0x + 0.17038392571223998 * k3x +
                  0.10726203044637328 * k4x + -0.015319437748624402 * k5x +
                  0.008273789163814023 * k6x)
    v7 = v + h * (0.03709200011850479 * k0v + 0.17038392571223998 * k3v +
                  0.10726203044637328 * k4v + -0.015319437748624402 * k5v +
                  0.008273789163814023 * k6v)
    drive = stage_forcing(t, 0.3076923076923077, h, f, w, cw, sw, force)
    k7x, k7v = _f2_poly(x7, v7, law, drive, sticking)
    x8 = x + h * (0.6241109587160757 * k0x + -3.3608926294469414 * k3x + -0.868219346841726 * k4x +
                  27.59209969944671 * k5x + 20.154067550477894 * k6x + -43.48988418106996 * k7x)
    v8 = v + h * (0.6241109587160757 * k0v + -3.3608926294469414 * k3v + -0.868219346841726 * k4v +
                  27.59209969944671 * k5v + 20.154067550477894 * k6v + -43.48988418106996 * k7v)
    drive = stage_forcing(t, 0.6512820512820513, h, f, w, cw, sw, force)
    k8x, k8v = _f2_poly(x8, v8, law, drive, sticking)
    x9 = x + h * (0.47766253643826434 * k0x + -2.4881146199716677 * k3x +
                  -0.590290826836843 * k4x + 21.230051448181193 * k5x + 15.279233632882423 * k6x +
                  -33.28821096898486 * k7x + -0.020331201708508627 * k8x)
    v9 = v + h * (0.47766253643826434 * k0v + -2.4881146199716677 * k3v +
                  -0.590290826836843 * k4v + 21.230051448181193 * k5v + 15.279233632882423 * k6v +
                  -33.28821096898486 * k7v + -0.020331201708508627 * k8v)
    drive = stage_forcing(t, 0.6, h, f, w, cw, sw, force)
    k9x, k9v = _f2_poly(x9, v9, law, drive, sticking)
    x10 = x + h * (-0.9371424300859873 * k0x + 5.186372428844064 * k3x + 1.0914373489967295 * k4x +
                   -8.149787010746927 * k5x + -18.52006565999696 * k6x + 22.739487099350505 * k7x +
                   2.4936055526796523 * k8x + -3.0467644718982196 * k9x)
    v10 = v + h * (-0.9371424300859873 * k0v + 5.186372428844064 * k3v + 1.0914373489967295 * k4v +
                   -8.149787010746927 * k5v + -18.52006565999696 * k6v + 22.739487099350505 * k7v +
                   2.4936055526796523 * k8v + -3.0467644718982196 * k9v)
    drive = stage_forcing(t, 0.8571428571428571, h, f, w, cw, sw, force)
    k10x, k10v = _f2_poly(x10, v10, law, drive, sticking)
    x11 = x + h * (2.273310147516538 * k0x + -10.53449546673725 * k3x + -2.0008720582248625 * k4x +
                   -17.9589318631188 * k5x + 27.94888452941996 * k6x + -2.8589982771350235 * k7x +
                   -8.87285693353063 * k8x + 12.360567175794303 * k9x + 0.6433927460157636 * k10x)
    v11 = v + h * (2.273310147516538 * k0v + -10.53449546673725 * k3v + -2.0008720582248625 * k4v +
                   -17.9589318631188 * k5v + 27.94888452941996 * k6v + -2.8589982771350235 * k7v +
                   -8.87285693353063 * k8v + 12.360567175794303 * k9v + 0.6433927460157636 * k10v)
    drive = stage_forcing(t, 1.0, h, f, w, cw, sw, force)
    k11x, k11v = _f2_poly(x11, v11, law, drive, sticking)
    xn = x + h * (0.054293734116568765 * k0x + 4.450312892752409 * k5x + 1.8915178993145003 * k6x +
                  -5.801203960010585 * k7x + 0.3111643669578199 * k8x + -0.1521609496625161 * k9x +
                  0.20136540080403034 * k10x + 0.04471061572777259 * k11x)
    vn = v + h * (0.054293734116568765 * k0v + 4.450312892752409 * k5v + 1.8915178993145003 * k6v +
                  -5.801203960010585 * k7v + 0.3111643669578199 * k8v + -0.1521609496625161 * k9v +
                  0.20136540080403034 * k10v + 0.04471061572777259 * k11v)
    k12x, k12v = _f2_poly(xn, vn, law, drive, sticking)
    kx = (k1x, k2x, k3x, k4x, k5x, k6x, k7x, k8x, k9x, k10x, k11x, k12x)
    kv = (k1v, k2v, k3v, k4v, k5v, k6v, k7v, k8v, k9v, k10v, k11v, k12v)
    return xn, vn, kx, kv


@njit(cache=True)
def _dense_stages2_dop853_poly(t, h, K, x, v, law, f, w, cw, sw, force, sticking):
    """Rows 13-15 of K (the dense-output stages) of the 2-D system, generated from
    the tableau (see ``step2``)."""
    x13 = x + h * (0.056167502283047954 * K[0, 0] + 0.25350021021662483 * K[6, 0] +
                   -0.2462390374708025 * K[7, 0] + -0.12419142326381637 * K[8, 0] +
                   0.15329179827876568 * K[9, 0] + 0.00820105229563469 * K[10, 0] +
                   0.007567897660545699 * K[11, 0] + -0.008298 * K[12, 0])
    v13 = v + h * (0.056167502283047954 * K[0, 1] + 0.25350021021662483 * K[6, 1] +
                   -0.2462390374708025 * K[7, 1] + -0.12419142326381637 * K[8, 1] +
                   0.15329179827876568 * K[9, 1] + 0.00820105229563469 * K[10, 1] +
                   0.007567897660545699 * K[11, 1] + -0.008298 * K[12, 1])
    drive = stage_drive(t, 0.1, h, f, w, cw, sw, force)
    k13x, k13v = _f2_poly(x13, v13, law, drive, sticking)
    K[13, 0] = k13x
    K[13, 1] = k13v
    x14 = x + h * (0.03183464816350214 * K[0, 0] + 0.028300909672366776 * K[5, 0] +
                   0.053541988307438566 * K[6, 0] + -0.05492374857139099 * K[7, 0] +
                   -0.00010834732869724932 * K[10, 0] + 0.0003825710908356584 * K[11, 0] +
                   -0.00034046500868740456 * K[12, 0] + 0.1413124436746325 * k13x)
    v14 = v + h * (0.03183464816350214 * K[0, 1] + 0.028300909672366776 * K[5, 1] +
                   0.053541988307438566 * K[6, 1] + -0.05492374857139099 * K[7, 1] +
                   -0.00010834732869724932 * K[10, 1] + 0.0003825710908356584 * K[11, 1] +
                   -0.00034046500868740456 * K[12, 1] + 0.1413124436746325 * k13v)
    drive = stage_drive(t, 0.2, h, f, w, cw, sw, force)
    k14x, k14v = _f2_poly(x14, v14, law, drive, sticking)
    K[14, 0] = k14x
    K[14, 1] = k14v
    x15 = x + h * (-0.42889630158379194 * K[0, 0] + -4.697621415361164 * K[5, 0] +
                   7.683421196062599 * K[6, 0] + 4.06898981839711 * K[7, 0] +
                   0.3567271874552811 * K[8, 0] + -0.0013990241651590145 * K[12, 0] +
                   2.9475147891527724 * k13x + -9.15095847217987 * k14x)
    v15 = v + h * (-0.42889630158379194 * K[0, 1] + -4.697621415361164 * K[5, 1] +
                   7.683421196062599 * K[6, 1] + 4.06898981839711 * K[7, 1] +
                   0.3567271874552811 * K[8, 1] + -0.0013990241651590145 * K[12, 1] +
                   2.9475147891527724 * k13v + -9.15095847217987 * k14v)
    drive = stage_drive(t, 0.7777777777777778, h, f, w, cw, sw, force)
    k15x, k15v = _f2_poly(x15, v15, law, drive, sticking)
    K[15, 0] = k15x
    K[15, 1] = k15v


@njit(cache=True)
def _stages2_dop853_fn(t, x, v, h, k0x, k0v, address, theta, f, w, cw, sw, force, sticking):
    """One step of the 2-D system, generated from the tableau (see ``step2``)."""
    x1 = x + h * (0.05260015195876773 * k0x)
    v1 = v + h * (0.05260015195876773 * k0v)
    drive = stage_forcing(t, 0.05260015195876773, h, f, w, cw, sw, force)
    k1x, k1v = _f2_fn(x1, v1, address, theta, drive, sticking)
    x2 = x + h * (0.0197250569845379 * k0x + 0.0591751709536137 * k1x)
    v2 = v + h * (0.0197250569845379 * k0v + 0.0591751709536137 * k1v)
    drive = stage_forcing(t, 0.0789002279381516, h, f, w, cw, sw, force)
    k2x, k2v = _f2_fn(x2, v2, address, theta, drive, sticking)
    x3 = x + h * (0.02958758547680685 * k0x + 0.08876275643042054 * k2x)
    v3 = v + h * (0.02958758547680685 * k0v + 0.08876275643042054 * k2v)
    drive = stage_forcing(t, 0.1183503419072274, h, f, w, cw, sw, force)
    k3x, k3v = _f2_fn(x3, v3, address, theta, drive, sticking)
    x4 = x + h * (0.2413651341592667 * k0x + -0.8845494793282861 * k2x + 0.924834003261792 * k3x)
    v4 = v + h * (0.2413651341592667 * k0v + -0.8845494793282861 * k2v + 0.924834003261792 * k3v)
    drive = stage_forcing(t, 0.2816496580927726, h, f, w, cw, sw, force)
    k4x, k4v = _f2_fn(x4, v4, address, theta, drive, sticking)
    x5 = x + h * (0.037037037037037035 * k0x + 0.17082860872947386 * k3x +
                  0.12546768756682242 * k4x)
    v5 = v + h * (0.037037037037037035 * k0v + 0.17082860872947386 * k3v +
                  0.12546768756682242 * k4v)
    drive = stage_forcing(t, 0.3333333333333333, h, f, w, cw, sw, force)
    k5x, k5v = _f2_fn(x5, v5, address, theta, drive, sticking)
    x6 = x + h * (0.037109375 * k0x + 0.17025221101954405 * k3x + 0.06021653898045596 * k4x +
                  -0.017578125 * k5x)
    v6 = v + h * (0.037109375 * k0v + 0.17025221101954405 * k3v + 0.06021653898045596 * k4v +
                  -0.017578125 * k5v)
    drive = stage_forcing(t, 0.25, h, f, w, cw, sw, force)
    k6x, k6v = _f2_fn(x6, v6, address, theta, drive, sticking)
    x7 = x + h * (0.03709200011850479 * k0x + 0.17038392571223998 * k3x +
                  0.10726203044637328 * k4x + -0.015319437748624402 * k5x +
                  0.008273789163814023 * k6x)
    v7 = v + h * (0.03709200011850479 * k0v + 0.17038392571223998 * k3v +
                  0.10726203044637328 * k4v + -0.015319437748624402 * k5v +
                  0.008273789163814023 * k6v)
    drive = stage_forcing(t, 0.3076923076923077, h, f, w, cw, sw, force)
    k7x, k7v = _f2_fn(x7, v7, address, theta, drive, sticking)
    x8 = x + h * (0.6241109587160757 * k0x + -3.3608926294469414 * k3x + -0.868219346841726 * k4x +
                  27.59209969944671 * k5x + 20.154067550477894 * k6x + -43.48988418106996 * k7x)
    v8 = v + h * (0.6241109587160757 * k0v + -3.3608926294469414 * k3v + -0.868219346841726 * k4v +
                  27.59209969944671 * k5v + 20.154067550477894 * k6v + -43.48988418106996 * k7v)
    drive = stage_forcing(t, 0.6512820512820513, h, f, w, cw, sw, force)
    k8x, k8v = _f2_fn(x8, v8, address, theta, drive, sticking)
    x9 = x + h * (0.47766253643826434 * k0x + -2.4881146199716677 * k3x +
                  -0.590290826836843 * k4x + 21.230051448181193 * k5x + 15.279233632882423 * k6x +
                  -33.28821096898486 * k7x + -0.020331201708508627 * k8x)
    v9 = v + h * (0.47766253643826434 * k0v + -2.4881146199716677 * k3v +
                  -0.590290826836843 * k4v + 21.230051448181193 * k5v + 15.279233632882423 * k6v +
                  -33.28821096898486 * k7v + -0.020331201708508627 * k8v)
    drive = stage_forcing(t, 0.6, h, f, w, cw, sw, force)
    k9x, k9v = _f2_fn(x9, v9, address, theta, drive, sticking)
    x10 = x + h * (-0.9371424300859873 * k0x + 5.186372428844064 * k3x + 1.0914373489967295 * k4x +
                   -8.149787010746927 * k5x + -18.52006565999696 * k6x + 22.739487099350505 * k7x +
                   2.4936055526796523 * k8x + -3.0467644718982196 * k9x)
    v10 = v + h * (-0.9371424300859873 * k0v + 5.186372428844064 * k3v + 1.0914373489967295 * k4v +
                   -8.149787010746927 * k5v + -18.52006565999696 * k6v + 22.739487099350505 * k7v +
                   2.4936055526796523 * k8v + -3.0467644718982196 * k9v)
    drive = stage_forcing(t, 0.8571428571428571, h, f, w, cw, sw, force)
    k10x, k10v = _f2_fn(x10, v10, address, theta, drive, sticking)
    x11 = x + h * (2.273310147516538 * k0x + -10.53449546673725 * k3x + -2.0008720582248625 * k4x +
                   -17.9589318631188 * k5x + 27.94888452941996 * k6x + -2.8589982771350235 * k7x +
                   -8.87285693353063 * k8x + 12.360567175794303 * k9x + 0.6433927460157636 * k10x)
    v11 = v + h * (2.273310147516538 * k0v + -10.53449546673725 * k3v + -2.0008720582248625 * k4v +
                   -17.9589318631188 * k5v + 27.94888452941996 * k6v + -2.8589982771350235 * k7v +
                   -8.87285693353063 * k8v + 12.360567175794303 * k9v + 0.6433927460157636 * k10v)
    drive = stage_forcing(t, 1.0, h, f, w, cw, sw, force)
    k11x, k11v = _f2_fn(x11, v11, address, theta, drive, sticking)
    xn = x + h * (0.054293734116568765 * k0x + 4.450312892752409 * k5x + 1.8915178993145003 * k6x +
                  -5.801203960010585 * k7x + 0.3111643669578199 * k8x + -0.1521609496625161 * k9x +
                  0.20136540080403034 * k10x + 0.04471061572777259 * k11x)
    vn = v + h * (0.054293734116568765 * k0v + 4.450312892752409 * k5v + 1.8915178993145003 * k6v +
                  -5.801203960010585 * k7v + 0.3111643669578199 * k8v + -0.1521609496625161 * k9v +
                  0.20136540080403034 * k10v + 0.04471061572777259 * k11v)
    k12x, k12v = _f2_fn(xn, vn, address, theta, drive, sticking)
    kx = (k1x, k2x, k3x, k4x, k5x, k6x, k7x, k8x, k9x, k10x, k11x, k12x)
    kv = (k1v, k2v, k3v, k4v, k5v, k6v, k7v, k8v, k9v, k10v, k11v, k12v)
    return xn, vn, kx, kv


@njit(cache=True)
def _dense_stages2_dop853_fn(t, h, K, x, v, address, theta, f, w, cw, sw, force, sticking):
    """Rows 13-15 of K (the dense-output stages) of the 2-D system, generated from
    the tableau (see ``step2``)."""
    x13 = x + h * (0.056167502283047954 * K[0, 0] + 0.25350021021662483 * K[6, 0] +
                   -0.2462390374708025 * K[7, 0] + -0.12419142326381637 * K[8, 0] +
                   0.15329179827876568 * K[9, 0] + 0.00820105229563469 * K[10, 0] +
                   0.007567897660545699 * K[11, 0] + -0.008298 * K[12, 0])
    v13 = v + h * (0.056167502283047954 * K[0, 1] + 0.25350021021662483 * K[6, 1] +
                   -0.2462390374708025 * K[7, 1] + -0.12419142326381637 * K[8, 1] +
                   0.15329179827876568 * K[9, 1] + 0.00820105229563469 * K[10, 1] +
                   0.007567897660545699 * K[11, 1] + -0.008298 * K[12, 1])
    drive = stage_drive(t, 0.1, h, f, w, cw, sw, force)
    k13x, k13v = _f2_fn(x13, v13, address, theta, drive, sticking)
    K[13, 0] = k13x
    K[13, 1] = k13v
    x14 = x + h * (0.03183464816350214 * K[0, 0] + 0.028300909672366776 * K[5, 0] +
                   0.053541988307438566 * K[6, 0] + -0.05492374857139099 * K[7, 0] +
                   -0.00010834732869724932 * K[10, 0] + 0.0003825710908356584 * K[11, 0] +
                   -0.00034046500868740456 * K[12, 0] + 0.1413124436746325 * k13x)
    v14 = v + h * (0.03183464816350214 * K[0, 1] + 0.028300909672366776 * K[5, 1] +
                   0.053541988307438566 * K[6, 1] + -0.05492374857139099 * K[7, 1] +
                   -0.00010834732869724932 * K[10, 1] + 0.0003825710908356584 * K[11, 1] +
                   -0.00034046500868740456 * K[12, 1] + 0.1413124436746325 * k13v)
    drive = stage_drive(t, 0.2, h, f, w, cw, sw, force)
    k14x, k14v = _f2_fn(x14, v14, address, theta, drive, sticking)
    K[14, 0] = k14x
    K[14, 1] = k14v
    x15 = x + h * (-0.42889630158379194 * K[0, 0] + -4.697621415361164 * K[5, 0] +
                   7.683421196062599 * K[6, 0] + 4.06898981839711 * K[7, 0] +
                   0.3567271874552811 * K[8, 0] + -0.0013990241651590145 * K[12, 0] +
                   2.9475147891527724 * k13x + -9.15095847217987 * k14x)
    v15 = v + h * (-0.42889630158379194 * K[0, 1] + -4.697621415361164 * K[5, 1] +
                   7.683421196062599 * K[6, 1] + 4.06898981839711 * K[7, 1] +
                   0.3567271874552811 * K[8, 1] + -0.0013990241651590145 * K[12, 1] +
                   2.9475147891527724 * k13v + -9.15095847217987 * k14v)
    drive = stage_drive(t, 0.7777777777777778, h, f, w, cw, sw, force)
    k15x, k15v = _f2_fn(x15, v15, address, theta, drive, sticking)
    K[15, 0] = k15x
    K[15, 1] = k15v


@njit(cache=True)
def _error2(h, x, v, xn, vn, k0x, k0v, kx, kv, rtol, atol):
    """``error_norm`` and ``wall_margin`` of a DOP853 step of the 2-D system, from its
    scalar stages (no array argument)."""
    e5x = D8_E5[0] * k0x
    e3x = D8_E3[0] * k0x
    e5v = D8_E5[0] * k0v
    e3v = D8_E3[0] * k0v
    vmax = abs(k0x)
    amax = abs(k0v)
    for r in range(12):
        e5x += D8_E5[r + 1] * kx[r]
        e3x += D8_E3[r + 1] * kx[r]
        e5v += D8_E5[r + 1] * kv[r]
        e3v += D8_E3[r + 1] * kv[r]
        vmax = max(vmax, abs(kx[r]))
        amax = max(amax, abs(kv[r]))
    sx = atol + rtol * max(abs(x), abs(xn))
    sv = atol + rtol * max(abs(v), abs(vn))
    r5 = max(abs(e5x) / sx, abs(e5v) / sv)
    r3 = max(abs(e3x) / sx, abs(e3v) / sv)
    if not (abs(e5x) / sx < np.inf and abs(e5v) / sv < np.inf and abs(e3x) / sx < np.inf
            and abs(e3v) / sv < np.inf and abs(xn) < np.inf and abs(vn) < np.inf):
        err = np.inf
    else:
        err = _combine_errors(METHOD_DOP853, h, r5, r3)
    return err, min(2.0 * abs(h) * vmax, 0.25 * h * h * amax)


@njit(cache=True, inline="always")
def step2(t, z, h, K, z_new, p, cfg, force, sticking, rtol, atol):
    """DOP853's ``rk_step`` for the two-dimensional system: fills the stage rows of K and
    z_new and returns (error, wall margin) as ``error_norm`` and ``wall_margin`` would
    (DP5, the slower choice, keeps the general loop: one unrolled step compiles in about
    2 s)."""
    w = p[P_OMEGA]
    cw = math.cos(w * t)
    sw = math.sin(w * t)
    x = z[0]
    v = z[1]
    k0x = K[0, 0]
    k0v = K[0, 1]
    if cfg[C_FORCE] == FORCE_POLYNOMIAL:
        xn, vn, kx, kv = _stages2_dop853_poly(t, x, v, h, k0x, k0v, force_law(p), p[P_F], w,
                                              cw, sw, force, sticking)
    elif cfg[C_FORCE] == FORCE_FUNCTION:
        xn, vn, kx, kv = _stages2_dop853_fn(t, x, v, h, k0x, k0v, cfg[C_FUNCTION],
                                            _theta_of_p(p), p[P_F], w, cw, sw, force, sticking)
    else:
        xn, vn, kx, kv = _stages2_dop853(t, x, v, h, k0x, k0v, p[P_MU], p[P_A], p[P_C], p[P_F],
                                         w, cw, sw, force, sticking)
    store_stages2(K, kx, kv)
    z_new[0] = xn
    z_new[1] = vn
    return _error2(h, x, v, xn, vn, k0x, k0v, kx, kv, rtol, atol)


@njit(cache=True)
def store_stages2(K, kx, kv):
    """Rows 1-12 of K from the scalar stages of ``_stages2_dop853`` (the driver's 2-D
    loop keeps them in registers and stores them only for the dense output)."""
    # tuple items by constant index: a runtime index compiles to a 12-way switch
    K[1, 0], K[2, 0], K[3, 0], K[4, 0], K[5, 0], K[6, 0] = kx[0], kx[1], kx[2], kx[3], kx[4], kx[5]
    K[7, 0], K[8, 0], K[9, 0], K[10, 0], K[11, 0], K[12, 0] = (kx[6], kx[7], kx[8], kx[9],
                                                                kx[10], kx[11])
    K[1, 1], K[2, 1], K[3, 1], K[4, 1], K[5, 1], K[6, 1] = kv[0], kv[1], kv[2], kv[3], kv[4], kv[5]
    K[7, 1], K[8, 1], K[9, 1], K[10, 1], K[11, 1], K[12, 1] = (kv[6], kv[7], kv[8], kv[9],
                                                                kv[10], kv[11])


@njit(cache=True)
def _stage_rows(t, z, h, K, ztmp, A, C, first, stop, m, p, cfg, table, weights, U, force,
                sticking, work):
    """Rows first..stop-1 of K: the stages z + h sum_r A[s, r] K[r] at t + C[s] h.
    Returns (cos(omega t), sin(omega t)) for ``stage_forcing`` at the step's end."""
    size = z.shape[0]
    cw = math.cos(p[P_OMEGA] * t)
    sw = math.sin(p[P_OMEGA] * t)
    for s in range(first, stop):
        for j in range(size):
            acc = 0.0
            for r in range(s):
                acc += A[s, r] * K[r, j]
            ztmp[j] = z[j] + h * acc
        drive = stage_drive(t, C[s], h, p[P_F], p[P_OMEGA], cw, sw, force)
        vector_field(ztmp, m, p, cfg, table, weights, U, t + C[s] * h, drive, sticking,
                     K[s], work)
    return cw, sw


@njit(cache=True)
def rk_step(method, t, z, h, K, z_new, ztmp, m, p, cfg, table, weights, U, force, sticking,
            work):
    """One step of size h from (t, z); K[0] must hold f(t, z).

    Fills the stage rows of K (the last, ``last_stage(method)``, with
    f(t + h, z_new)) and ``z_new``. Returns the number of vector-field evaluations.
    """
    size = z.shape[0]
    last = last_stage(method)
    A = DP_A if method == METHOD_DP5 else D8_A
    C = DP_C if method == METHOD_DP5 else D8_C
    B = DP_B if method == METHOD_DP5 else D8_B
    if method == METHOD_DOP853 and size == 2 and is_deterministic(m, cfg, table, p):
        step2(t, z, h, K, z_new, p, cfg, force, sticking, 1.0, 1.0)
        return last
    cw, sw = _stage_rows(t, z, h, K, ztmp, A, C, np.int64(1), last, m, p, cfg, table,
                         weights, U, force, sticking, work)
    for j in range(size):
        acc = 0.0
        for r in range(last):
            acc += B[r] * K[r, j]
        z_new[j] = z[j] + h * acc
    drive = stage_drive(t, 1.0, h, p[P_F], p[P_OMEGA], cw, sw, force)
    vector_field(z_new, m, p, cfg, table, weights, U, t + h, drive, sticking, K[last], work)
    return last


@njit(cache=True, inline="always")
def _component_error(method, K, j, h, old, new, rtol, atol):
    """Scaled local error estimates of component j: (5th-order or DP5 estimate, 3rd-order
    estimate, 0 for DP5); non-finite when a stage is (the caller checks the state)."""
    scale = atol + rtol * max(abs(old), abs(new))
    if method == METHOD_DP5:
        e = 0.0
        for r in range(7):
            e += DP_E[r] * K[r, j]
        return abs(h * e) / scale, 0.0
    e5 = 0.0
    e3 = 0.0
    for r in range(13):
        e5 += D8_E5[r] * K[r, j]
        e3 += D8_E3[r] * K[r, j]
    return abs(e5) / scale, abs(e3) / scale


@njit(cache=True, inline="always")
def step_factor(method, err):
    """err^(-1/q), q the order of the error estimate: 5 (DP5), 8 (DOP853, as three square
    roots: a libm pow took 3% of a DMR run)."""
    if method == METHOD_DP5:
        return err ** (-1.0 / 5.0)
    return 1.0 / math.sqrt(math.sqrt(math.sqrt(err)))


@njit(cache=True, inline="always")
def _combine_errors(method, h, worst, worst3):
    if method == METHOD_DP5 or worst == 0.0:
        return worst
    return abs(h) * worst * worst / math.sqrt(worst * worst + 0.01 * worst3 * worst3)


@njit(cache=True)
def error_norm(method, z, z_new, K, h, rtol, atol):
    """Scaled local error estimate in the max-norm over all components.

    The max-norm (rather than RMS) makes the step sequence independent of components
    that stay at zero, so EMR_0 (sigma = 0, N > 0) takes the DMR's steps exactly. For
    DOP853 the 5th- and 3rd-order estimates combine as in Hairer's code,
    |h| E5^2 / sqrt(E5^2 + 0.01 E3^2), with max-norms in place of RMS norms. A
    non-finite trial state or stage is an infinite error (written with comparisons
    that fail for NaN: numba's max drops a NaN argument).
    """
    worst = 0.0
    worst3 = 0.0
    for j in range(z.shape[0]):
        r5, r3 = _component_error(method, K, j, h, z[j], z_new[j], rtol, atol)
        if not (r5 < np.inf and r3 < np.inf and abs(z_new[j]) < np.inf):
            return np.inf
        if r5 > worst:
            worst = r5
        if r3 > worst3:
            worst3 = r3
    return _combine_errors(method, h, worst, worst3)


# ---------------------------------------------------------------------------
# Dense output
@njit(cache=True)
def dense_prepare(method, t, z, z_new, h, K, F, ztmp, m, p, cfg, table, weights, U, force,
                  sticking, work):
    """Fill F with the dense-output coefficients of the step (t, z) -> (t + h, z_new).

    DP5: the quartic in power form, y(theta) = y + theta (F0 + theta (F1 + ...)). DOP853:
    three more stages (rows 13-15 of K), then Hairer's form
    y(theta) = y + theta (F0 + (1 - theta) (F1 + theta (F2 + (1 - theta) (F3 + ...)))).
    Returns the number of vector-field evaluations (0 or 3).
    """
    size = z.shape[0]
    if method == METHOD_DP5:
        for j in range(size):
            for d in range(4):
                acc = 0.0
                for s in range(7):
                    acc += K[s, j] * DP_P[s, d]
                F[d, j] = h * acc
        return 0
    if size == 2 and is_deterministic(m, cfg, table, p):
        return dense_prepare2(t, z, z_new, h, K, F, p, cfg, force, sticking)
    _stage_rows(t, z, h, K, ztmp, D8_A, D8_C, np.int64(13), np.int64(16), m, p, cfg, table,
                weights, U, force, sticking, work)
    _dop853_coefficients(z, z_new, h, K, F)
    return 3


@njit(cache=True)
def dense_prepare2(t, z, z_new, h, K, F, p, cfg, force, sticking):
    """``dense_prepare`` for DOP853 and the two-dimensional system: the three extra
    stages in scalars (``_dense_stages2_dop853``), the same bits as the general loop."""
    w = p[P_OMEGA]
    if cfg[C_FORCE] == FORCE_POLYNOMIAL:
        _dense_stages2_dop853_poly(t, h, K, z[0], z[1], force_law(p), p[P_F], w,
                                   math.cos(w * t), math.sin(w * t), force, sticking)
    elif cfg[C_FORCE] == FORCE_FUNCTION:
        _dense_stages2_dop853_fn(t, h, K, z[0], z[1], cfg[C_FUNCTION], _theta_of_p(p), p[P_F],
                                 w, math.cos(w * t), math.sin(w * t), force, sticking)
    else:
        _dense_stages2_dop853(t, h, K, z[0], z[1], p[P_MU], p[P_A], p[P_C], p[P_F], w,
                              math.cos(w * t), math.sin(w * t), force, sticking)
    _dop853_coefficients(z, z_new, h, K, F)
    return 3


@njit(cache=True)
def step_dense(two_d, kx, kv, method, t, z, z_new, h, K, F, ztmp, m, p, cfg, table, weights, U,
               force, sticking, work):
    """``dense_prepare`` for the step the driver just took (once per step at most): on the
    2-D register path (``two_d``) the stages kx, kv, until now only in registers, are
    stored in K first; ``dense_prepare`` itself picks the 2-D path."""
    if two_d:  # the 2-D system's dense output, without asking again what the run is
        store_stages2(K, kx, kv)
        return dense_prepare2(t, z, z_new, h, K, F, p, cfg, force, sticking)
    return dense_prepare(method, t, z, z_new, h, K, F, ztmp, m, p, cfg, table, weights, U,
                         force, sticking, work)


@njit(cache=True)
def _dop853_coefficients(z, z_new, h, K, F):
    """Hairer's dense-output coefficients F of a DOP853 step from its 16 stage rows."""
    for j in range(z.shape[0]):
        dy = z_new[j] - z[j]
        F[0, j] = dy
        F[1, j] = h * K[0, j] - dy
        F[2, j] = 2.0 * dy - h * (K[12, j] + K[0, j])
        for i in range(4):
            acc = 0.0
            for s in range(16):
                acc += D8_D[i, s] * K[s, j]
            F[3 + i, j] = h * acc


@njit(cache=True)
def dense_x(method, theta, y_old, c):
    """Dense output of one component at t_old + theta h, from its value y_old at t_old
    and its coefficients c = F[:, j] (a 7-tuple: scalars, so the wall scans pass no
    array and update no reference count per evaluation)."""
    if method == METHOD_DP5:
        return y_old + theta * (c[0] + theta * (c[1] + theta * (c[2] + theta * c[3])))
    u = 1.0 - theta
    q5 = c[5] + theta * c[6]
    q4 = c[4] + u * q5
    q3 = c[3] + theta * q4
    q2 = c[2] + u * q3
    q1 = c[1] + theta * q2
    q0 = c[0] + u * q1
    return y_old + theta * q0


@njit(cache=True)
def dense_dx(method, theta, c):
    """d/dtheta of ``dense_x``."""
    if method == METHOD_DP5:
        return c[0] + theta * (2.0 * c[1] + theta * (3.0 * c[2] + theta * 4.0 * c[3]))
    u = 1.0 - theta
    q5 = c[5] + theta * c[6]
    q4 = c[4] + u * q5
    q3 = c[3] + theta * q4
    q2 = c[2] + u * q3
    q1 = c[1] + theta * q2
    d5 = c[6]
    d4 = -q5 + u * d5
    d3 = q4 + theta * d4
    d2 = -q3 + u * d3
    d1 = q2 + theta * d2
    d0 = -q1 + u * d1
    return c[0] + u * q1 + theta * d0


@njit(cache=True, inline="always")
def dense_column(F, j):
    """Component j's dense-output coefficients as the 7-tuple ``dense_x`` takes."""
    return F[0, j], F[1, j], F[2, j], F[3, j], F[4, j], F[5, j], F[6, j]


@njit(cache=True)
def dense_value(method, theta, z_old, F, j):
    """Dense output of component j at t_old + theta h."""
    return dense_x(method, theta, z_old[j], dense_column(F, j))


@njit(cache=True)
def dense_state(method, theta, z_old, F, out):
    for j in range(z_old.shape[0]):
        out[j] = dense_value(method, theta, z_old, F, j)


# ---------------------------------------------------------------------------
# The walls x_0 = delta (upper, side +1) and x_0 = delta_minus (lower, side -1) on the
# dense output. The functions below serve both through ``side``: they look at
# side (x_0 - wall), which is positive beyond the wall on either side (for the upper wall
# side = 1.0, a multiplication that changes no bit).
@njit(cache=True)
def wall_margin(K, last, n, h):
    """How far x_0 may rise inside a step above the higher of its end values: the
    smaller of 2 |h| max|x_0'| and 2 h^2 max|x_0''| / 8 over the stages. A function with
    |x''| <= A on a step of length h exceeds the chord between its end values by at most
    A h^2 / 8; the stages sample x_0' = K[., 0] and x_0'' = K[., n] across the step, and
    the factor 2 covers what they miss and the interpolant's overshoot. The second bound
    is the tighter one for long steps, so fewer steps need the dense output (a DMR run
    1.24 times faster in this session's measurement)."""
    vmax = 0.0
    amax = 0.0
    for s in range(last + 1):
        v = abs(K[s, 0])
        a = abs(K[s, n])
        if v > vmax:
            vmax = v
        if a > amax:
            amax = a
    return min(2.0 * abs(h) * vmax, 0.25 * h * h * amax)


@njit(cache=True, inline="always")
def may_reach_wall(x_old, x_new, margin, delta):
    """Cheap exclusion before the scan of the dense output (``wall_margin``)."""
    return max(x_old, x_new) + margin >= delta


@njit(cache=True, inline="always")
def may_reach_floor(x_old, x_new, margin, delta_minus):
    """``may_reach_wall`` for the lower wall (never true without one: delta_minus = -inf)."""
    return min(x_old, x_new) - margin <= delta_minus


@njit(cache=True, inline="always")
def resting_side(x0, delta, delta_minus):
    """The wall the mean rests on while sticking (held exactly on it): -1.0 the lower when
    x_0 is nearer to it, else +1.0 (always without a lower wall: x_0 - (-inf) = inf)."""
    return -1.0 if x0 - delta_minus < delta - x0 else 1.0


@njit(cache=True, inline="always")
def wall_of(side, p):
    """(position, restitution) of the wall on ``side``: (delta, eta) for +1, (delta_minus,
    eta_minus) for -1."""
    if side > 0.0:
        return p[P_DELTA], p[P_ETA]
    return p[P_DELTA_MINUS], p[P_ETA_MINUS]


@njit(cache=True)
def _bisect_wall(method, lo, hi, x_old, c, h, delta, side=1.0):
    """Root of x_0(theta) = delta in [lo, hi] with g(lo) <= 0 < g(hi),
    g = side (x_0 - delta)."""
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if side * (dense_x(method, mid, x_old, c) - delta) > 0.0:
            hi = mid
        else:
            lo = mid
        if (hi - lo) * abs(h) < 1e-15:
            break
    return hi


@njit(cache=True)
def _bisect_maximum(method, lo, hi, c, side=1.0):
    """Location of a maximum of side x_0(theta) in [lo, hi] where its slope goes + to -
    (a minimum of x_0 for side = -1)."""
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if side * dense_dx(method, mid, c) > 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-13:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def wall_crossing(method, x_old, c, h, delta, side=1.0):
    """First theta in (0, 1] where the dense x_0 reaches the wall delta on ``side`` (+1:
    from below, the upper wall; -1: from above, the lower wall), or -1.

    The interpolant is scanned on N_SCAN sub-intervals and every interior maximum (of
    side x_0) is inspected, so a step whose interpolant touches the wall and comes back
    is caught.
    """
    prev_t = 0.0
    prev_g = side * (dense_x(method, 0.0, x_old, c) - delta)
    prev_s = side * dense_dx(method, 0.0, c)
    for i in range(1, N_SCAN + 1):
        th = i / N_SCAN
        g = side * (dense_x(method, th, x_old, c) - delta)
        s = side * dense_dx(method, th, c)
        hit = g > 0.0
        hi_t = th
        if not hit and prev_s > 0.0 and s < 0.0:
            tm = _bisect_maximum(method, prev_t, th, c, side)
            if side * (dense_x(method, tm, x_old, c) - delta) > 0.0:
                hit = True
                hi_t = tm
        if hit:
            lo_t = prev_t
            if prev_g >= 0.0:
                # leaving the wall just after an impact: find a point strictly inside
                found = False
                tt = hi_t
                for _ in range(60):
                    tt *= 0.5
                    if tt <= lo_t:
                        break
                    if side * (dense_x(method, tt, x_old, c) - delta) < 0.0:
                        found = True
                        break
                if not found:
                    return -1.0
                lo_t = tt
            return _bisect_wall(method, lo_t, hi_t, x_old, c, h, delta, side)
        prev_t = th
        prev_g = g
        prev_s = s
    return -1.0


@njit(cache=True, inline="always")
def first_crossing(method, x_old, c, h, delta, delta_minus, near_wall, near_floor):
    """The first wall crossing in a step (``wall_crossing`` of each wall that
    ``may_reach_wall``/``may_reach_floor`` left in): (theta, side), side +1.0 the upper
    wall, -1.0 the lower; theta -1 when neither wall is reached."""
    theta = wall_crossing(method, x_old, c, h, delta, 1.0) if near_wall else -1.0
    side = 1.0
    if near_floor:
        low = wall_crossing(method, x_old, c, h, delta_minus, -1.0)
        if low > 0.0 and (theta <= 0.0 or low < theta):
            theta = low
            side = -1.0
    return theta, side


@njit(cache=True)
def free_flight_maximum(method, x_old, c, delta, side):
    """The highest interior maximum of the dense x_0 in a step (the signature of a
    grazing bifurcation when it approaches the wall): (gap delta - x_0, theta), or
    (inf, -1) when x_0 has no interior maximum. side = -1.0: the lowest interior minimum
    and its gap x_0 - delta to the lower wall delta (the maximum of side x_0)."""
    gap = np.inf
    where = -1.0
    prev_t = 0.0
    prev_s = side * dense_dx(method, 0.0, c)
    for i in range(1, N_SCAN + 1):
        th = i / N_SCAN
        s = side * dense_dx(method, th, c)
        if prev_s > 0.0 and s <= 0.0:
            tm = _bisect_maximum(method, prev_t, th, c, side)
            g = side * (delta - dense_x(method, tm, x_old, c))
            if g < gap:
                gap = g
                where = tm
        prev_t = th
        prev_s = s
    return gap, where


# the events ``restep_to`` refines: an impact on the upper wall, a free-flight maximum,
# an impact on the lower wall, a free-flight minimum
IMPACT_ROOT, MAXIMUM_ROOT, IMPACT_LOWER_ROOT, MINIMUM_ROOT = 0, 1, 2, 3


@njit(cache=True)
def restep_to(method, kind, t, z, h, theta, K, K2, z_new, ztmp, m, p, cfg, table, weights, U,
              force, work):
    """Refine an event found on the dense output by re-stepping exactly to it: Newton on
    g(t + hh) = 0 from hh = theta h, each iterate a fresh Runge-Kutta step from (t, z), so
    the state there is a full-order step result, not an interpolant.

    kind IMPACT_ROOT: g = x_0 - delta, g' = v_0 > 0 (the impact time); IMPACT_LOWER_ROOT:
    g = x_0 - delta_minus, g' = v_0 < 0 (the impact on the lower wall). MAXIMUM_ROOT:
    g = v_0, g' = v_0' < 0 (a free-flight maximum of x_0, whose gap to the wall then
    varies smoothly with the parameters; the interpolant's error changes with the step
    sequence); MINIMUM_ROOT: g = v_0, g' = v_0' > 0 (a minimum, the lower wall's).
    Leaves the state at t + hh in ``z_new``; returns (hh, evaluations).
    """
    n = cfg[C_NCOEF]
    last = last_stage(method)
    side = -1.0 if kind == IMPACT_LOWER_ROOT else 1.0
    delta = p[P_DELTA_MINUS] if kind == IMPACT_LOWER_ROOT else p[P_DELTA]
    off = np.bool_(False)
    for j in range(z.shape[0]):
        K2[0, j] = K[0, j]
    hh = theta * h
    evals = 0
    for _ in range(4):
        evals += rk_step(method, t, z, hh, K2, z_new, ztmp, m, p, cfg, table, weights, U, force,
                         off, work)
        if kind == IMPACT_ROOT or kind == IMPACT_LOWER_ROOT:
            g = z_new[0] - delta
            slope = z_new[n]
            done = side * slope <= 0.0 or abs(g) <= 1e-14 * (1.0 + abs(delta))
        else:
            g = z_new[n]
            slope = K2[last, n]
            done = (slope >= 0.0 if kind == MAXIMUM_ROOT else slope <= 0.0) \
                or abs(g) <= 1e-15 * (1.0 + abs(g))
        if done:
            break
        dh = -g / slope
        if hh + dh <= 0.0 or hh + dh > h:
            break
        hh += dh
    return hh, evals


# ---------------------------------------------------------------------------
# Jumps
@njit(cache=True)
def _reflect(z, m, n, eta, all_velocities):
    """The impact law on y (v_0, or every v_i, times -eta) and its constant Jacobian
    diag(1, -eta) on the velocity rows of W (the whole of a kick into the wall, which
    happens at a fixed time and so has no time-shift term)."""
    dim = 2 * n
    top = n if all_velocities else 1
    for i in range(top):
        z[n + i] = -eta * z[n + i]
        for c in range(m):
            z[dim + (n + i) * m + c] *= -eta


@njit(cache=True, inline="always")
def _saltation_gain(t, z, p, cfg, table, weights, U, force, f_minus, f_plus, work, eta):
    """Reflect the mean's velocity v_0 -> -eta v_0 (z at the wall) and return the
    saltation gain k = (a+ + eta a-) / v-, a-, a+ the mean's accelerations before and
    after (two right-hand sides). The same at either wall: the signed v- (< 0 at the
    lower wall) is e_0^T f- of the saltation matrix, whatever the wall's side."""
    n = cfg[C_NCOEF]
    m0 = np.int64(0)  # typed, not literal: one compiled vector_field for every call
    off = np.bool_(False)
    v_minus = z[n]
    a_minus = vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off,
                           f_minus, work)
    z[n] = -eta * z[n]
    a_plus = vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off,
                          f_plus, work)
    return (a_plus + eta * a_minus) / v_minus


@njit(cache=True)
def _impact(t, z, m, p, cfg, table, weights, U, force, f_minus, f_plus, work, side=1.0):
    """Apply the impact law at the wall of ``side`` (+1: x_0 = delta with eta; -1: the
    lower wall x_0 = delta_minus with eta_minus) to y and its saltation matrix to W.

    Laws: ``mean`` reflects v_0 (eq. (28)); ``ensemble`` every v_i; ``saltation`` applies
    to the deviation coefficients the saltation matrix of the sampled systems' impact
    (x_i -> -eta x_i, v_i -> -eta v_i + (a+ + eta a-) / v- x_i for i >= 1, a-, a+ the
    mean's accelerations before and after, v- its impact speed), and reflects every v_i
    at a graze, where that matrix does not exist.

    For W the event surface is h(y) = x_0 - delta with normal e_0, and the jump is
    ``S = dR + (f(t*, R y-) - dR f(t*, y-)) e_0^T / v_0-`` (Aizerman-Gantmacher), with
    dR the Jacobian of the reset (mean and ensemble laws only: the Python layer refuses
    tangents with the saltation law). Returns (v_minus, evaluations). Every formula holds
    at the lower wall with its signed v- < 0 (the surface x_0 - delta_minus has the same
    normal e_0); only the graze test looks at the speed side v-.

    With an uncertain restitution or wall (``cfg[C_WALL_NODES]``; p holds their means
    eta_bar, delta_bar over the rule, the table their values at each node): the mean
    reaches the mean wall, x_0 = delta_bar; ``mean`` reflects v_0 with eta_bar;
    ``ensemble`` projects each node's own reflection, v_i -> -sum_k w_k U_i(xi_k)
    eta(xi_k) v(xi_k); ``saltation`` takes the deviations from the wall, y_i = x_i -
    delta_i, to -eta_bar y_i and the velocities to -eta_bar v_i + k y_i - eta_i v_0-
    (the first-order effect of each node's own restitution), with delta_i, eta_i the
    coefficients of delta(xi) and eta(xi). Tangents: under ``mean`` and ``ensemble``
    (the reset is linear in the velocities: dR = -A on them, A_ij = sum_k w_k eta(xi_k)
    U_i(xi_k) U_j(xi_k)); the Python layer refuses them under ``saltation``, and an
    uncertain wall together with a lower wall.
    """
    n = cfg[C_NCOEF]
    dim = 2 * n
    delta, eta = wall_of(side, p)
    law = cfg[C_LAW]
    # (the mean law at nodes is this function's own: v_0 with eta_bar at delta_bar)
    if cfg[C_WALL_NODES] != 0 and n > 1 and side > 0.0 and law != LAW_MEAN:
        return _impact_at_nodes(t, z, m, p, cfg, table, weights, U, force, f_minus, f_plus,
                                work)
    m0 = np.int64(0)  # typed, not literal: one compiled vector_field for every call
    off = np.bool_(False)
    z[0] = delta
    v_minus = z[n]
    evals = 0
    if law == LAW_SALTATION and side * v_minus > EVENT_GRAZE_VELOCITY:
        k = _saltation_gain(t, z, p, cfg, table, weights, U, force, f_minus, f_plus, work,
                            eta)
        evals += 2
        for i in range(1, n):
            xi_ = z[i]
            z[i] = -eta * xi_
            z[n + i] = -eta * z[n + i] + k * xi_
        return v_minus, evals
    ensemble = law != LAW_MEAN
    if m > 0:
        vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off, f_minus, work)
        evals += 1
    top = n if ensemble else 1
    for i in range(top):
        z[n + i] = -eta * z[n + i]
    if m > 0:
        vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off, f_plus, work)
        evals += 1
        for c in range(m):
            w0 = z[dim + c] / v_minus  # e_0^T W / (e_0^T f-)
            for r in range(dim):
                d = -eta if (r >= n and r < n + top) else 1.0
                z[dim + r * m + c] = d * z[dim + r * m + c] + (f_plus[r] - d * f_minus[r]) * w0
    return v_minus, evals


@njit(cache=True)
def _impact_at_nodes(t, z, m, p, cfg, table, weights, U, force, f_minus, f_plus, work):
    """``_impact`` with the restitution or the wall uncertain and the laws ``saltation``
    and ``ensemble`` (see there; the mean law is ``_impact``'s own). Tangents W under
    ``ensemble``: ``S = dR + (f(t*, R y-) - dR f(t*, y-)) e_0^T / v_0-`` with dR the
    identity on the positions and -A on the velocities."""
    n = cfg[C_NCOEF]
    dim = 2 * n
    q = table.shape[0]
    eta = p[P_ETA]
    law = cfg[C_LAW]
    z[0] = p[P_DELTA]
    v_minus = z[n]
    if law == LAW_SALTATION and v_minus > EVENT_GRAZE_VELOCITY:
        k = _saltation_gain(t, z, p, cfg, table, weights, U, force, f_minus, f_plus, work,
                            eta)
        for i in range(1, n):
            delta_i = 0.0
            eta_i = 0.0
            for j in range(q):
                delta_i += weights[j] * U[j, i] * table[j, T_DELTA]
                eta_i += weights[j] * U[j, i] * table[j, T_ETA]
            y = z[i] - delta_i
            z[i] = delta_i - eta * y
            z[n + i] = -eta * z[n + i] + k * y - eta_i * v_minus
        return v_minus, 2
    # the ensemble law (and a graze under the saltation law): each node's own reflection
    evals = 0
    m0 = np.int64(0)  # typed, not literal: one compiled vector_field for every call
    off = np.bool_(False)
    one = np.int64(1)  # typed, not literal: one compiled _reflect_at_nodes
    if m > 0:
        vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off, f_minus,
                     work)
        evals += 1
    _reflect_at_nodes(z, n, n, one, table, weights, U, work)
    if m > 0:
        vector_field(z, m0, p, cfg, table, weights, U, t, forcing(t, p, force), off, f_plus,
                     work)
        evals += 1
        # dR f-: f- with its velocities through -A (in place: f- is scratch from here)
        _reflect_at_nodes(f_minus, n, n, one, table, weights, U, work)
        for c in range(m):
            w0 = z[dim + c] / v_minus  # e_0^T W / (e_0^T f-)
            _reflect_at_nodes(z, n, dim + n * m + c, m, table, weights, U, work)
            for r in range(dim):
                z[dim + r * m + c] += (f_plus[r] - f_minus[r]) * w0
    return v_minus, evals


@njit(cache=True)
def _reflect_at_nodes(y, n, first, stride, table, weights, U, work):
    """The ensemble law's reset of velocity coefficients, in place: the n entries of
    ``y`` at ``first``, ``first + stride``, ... (the velocities, or a tangent column's
    velocity rows) become -sum_k w_k eta(xi_k) U_i(xi_k) v(xi_k), v(xi_k) = sum_j v_j
    U_j(xi_k) (work row 4 is scratch)."""
    q = table.shape[0]
    for k in range(q):
        vs = 0.0
        for i in range(n):
            vs += y[first + i * stride] * U[k, i]
        work[4, k] = weights[k] * table[k, T_ETA] * vs
    for i in range(n):
        acc = 0.0
        for k in range(q):
            acc += work[4, k] * U[k, i]
        y[first + i * stride] = -acc


@njit(cache=True)
def _hold(z, m, n, law):
    """Start sticking: the mean at rest on the wall (the ``ensemble`` and ``saltation``
    laws stop every velocity coefficient), and the held rows of W zeroed."""
    dim = 2 * n
    z[n] = 0.0
    if law != LAW_MEAN:
        for i in range(n):
            z[n + i] = 0.0
    for c in range(m):
        z[dim + c] = 0.0
        z[dim + n * m + c] = 0.0
        if law != LAW_MEAN:
            for i in range(1, n):
                z[dim + (n + i) * m + c] = 0.0


@njit(cache=True)
def escape_bound(y0, p, cfg):
    """The |x_i|, |v_i| beyond which the state counts as escaped (see ESCAPE_FACTOR); the
    linear stiffness of a polynomial force law is -C[1, 0], of a compiled function its
    -dg/dx at the origin."""
    start = 0.0
    for j in range(y0.shape[0]):
        a = abs(y0[j])
        if not (a <= start):  # NaN propagates
            start = a
    w = p[P_OMEGA]
    drive = abs(p[P_F]) + abs(p[P_F0]) * (1.0 + abs(p[P_A1]))
    if cfg[C_FORCE] == FORCE_FUNCTION:  # -dg/dx at the origin, by central differences
        _, gx, _ = _function_law(cfg[C_FUNCTION], 0.0, 0.0, _theta_of_p(p), True)
        stiffness = abs(gx)
    else:
        stiffness = abs(p[P_POLY + POLY_DEGREE + 1] if cfg[C_FORCE] == FORCE_POLYNOMIAL
                        else p[P_A])
    if stiffness == 0.0:
        return np.inf  # no linear restoring force: no scale to escape from
    # the lower wall's |delta_minus| enters as |delta| does (adding 0.0 without one)
    lower = abs(p[P_DELTA_MINUS]) if p[P_DELTA_MINUS] > -np.inf else 0.0
    return ESCAPE_FACTOR * (1.0 + start + abs(p[P_DELTA]) + lower
                            + drive * (1.0 + 1.0 / w + 1.0 / (w * w) + 1.0 / stiffness))


@njit(cache=True)
def state_status(z, dim, escape):
    """OK; ESCAPED when a state component |y_j| (j < dim) >= escape; DIVERGED when any
    component (state or tangent) is NaN or inf. Every comparison is false for NaN, so a
    NaN cannot pass. The tangent W may grow large (only renormalised by the caller), so
    only its finiteness is checked."""
    status = OK
    for j in range(z.shape[0]):
        a = abs(z[j])
        if not (a < np.inf):
            return DIVERGED
        if j < dim and not (a < escape):
            status = ESCAPED
    return status


@njit(cache=True)
def _log_event(log, count, t, v, kind):
    if count < log.shape[0]:
        log[count, 0] = t
        log[count, 1] = v
        log[count, 2] = kind
    return count + 1


@njit(cache=True)
def first_impulse(t0, include_start, T1, at_zero):
    """Index j of the first impulse t_j = j T1 at or after t0 (after t0 without
    ``include_start``), or -1 when t0 / T1 is beyond exact integers (impulse times not
    resolvable). Impulses within SNAP of t0 count as at t0."""
    snap = SNAP * max(1.0, abs(t0))
    r = t0 / T1
    if not (abs(r) < 2.0**53):
        return -1
    j = int(r) - (2 if r < 0.0 else 1)  # floor(r) - 1 or below (no floor on the GPU)
    for _ in range(8):
        if j * T1 >= t0 - snap:
            break
        j += 1
    if not include_start:
        for _ in range(8):
            if j * T1 > t0 + snap:
                break
            j += 1
    if j < 0:
        j = 0
    if j == 0 and not at_zero:
        j = 1
    return j


# ---------------------------------------------------------------------------
# The driver's phases (the map is in the module docstring). Each is a function of its
# own, compiled once (``opa._run.callee_signatures`` lists the argument types with which
# ``integrate`` calls it), or inlined: the tiny ones of the step loop, which take scalars
# only, and those that call the vector field (a function of its own would link and
# optimise the vector field once more: seconds of a cold start). The rare phases take the
# arrays they touch and return the scalars they change. An array argument costs two
# atomic reference-count updates per call, also when inlined, unless the function calls
# nothing and cannot raise (``store_outputs``): the register path's step takes none.
_NO_STAGES = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True, inline="always")
def allocate_scratch(size, dim, q):
    """The driver's work arrays: stage rows K and K2 (re-steps), dense-output
    coefficients F, trial state z_new, stage state ztmp, the state at a free-flight
    maximum z_top, f before and after an impact, and the vector field's (6, Q) rows."""
    return (np.empty((K_ROWS, size)), np.empty((K_ROWS, size)), np.empty((7, size)),
            np.empty(size), np.empty(size), np.empty(size), np.empty(dim), np.empty(dim),
            np.empty((6, q)))


@njit(cache=True)
def start_run(z, t, t_end, include_start, p, cfg, escape, snap, out, stats):
    """Phase "start": blank the outputs (NaN rows, empty statistics), check the times and
    the start state, and place the impulse train at t.

    Returns (status, j_imp, t_imp, force, force_end): the first impulse not yet applied
    (index and time; t_imp = inf without impulses) and the pulse force on at t with its end
    (a pulse that started before t may still be on)."""
    for i in range(stats.shape[0]):
        stats[i, S_IMPACTS] = 0.0
        stats[i, S_MIN_VELOCITY] = np.inf
        stats[i, S_STICKS] = 0.0
        stats[i, S_STEPS] = 0.0
        stats[i, S_STICKING] = 0.0
        stats[i, S_GAP] = np.inf
        stats[i, S_GAP_LOWER] = np.inf
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = np.nan
    use_impulses = p[P_F0] != 0.0
    T1 = 2.0 * np.pi / p[P_OMEGA1]
    at_zero = cfg[C_AT_ZERO] != 0
    status = OK
    j_imp = 0
    if not (abs(t) < np.inf and abs(t_end) < np.inf):
        status = BAD_TIME  # a NaN end time would never be reached
    elif use_impulses:
        j_imp = first_impulse(t, include_start, T1, at_zero)
        if j_imp < 0:
            status = BAD_TIME  # impulse index beyond exact integers
    if status == OK and state_status(z, 2 * cfg[C_NCOEF], escape) != OK:
        status = DIVERGED
    t_imp = j_imp * T1 if use_impulses else np.inf
    force = 0.0
    force_end = np.inf
    if status == OK and use_impulses and cfg[C_IMPULSE] == IMPULSE_PULSE and j_imp >= 1:
        j_prev = j_imp - 1
        if j_prev >= (0 if at_zero else 1) and t < j_prev * T1 + p[P_TAU] - snap:
            force = impulse_strength(j_prev * T1, p)
            force_end = j_prev * T1 + p[P_TAU]
    return status, j_imp, t_imp, force, force_end


@njit(cache=True, inline="always")
def kick(t, z, m, strength, sticking, seg, n_events, n_impacts, p, cfg, table, weights, U,
         stats, log):
    """Phase "kick": a Dirac impulse adds ``strength`` to v_0 at t (and, with
    ``cfg[C_DRIVE_NODES]``, each node's own height less the shared one, projected). A
    kick into the wall while the mean rests on it is an impact at once (``_reflect``: a
    fixed-time jump, so W takes only the reset's Jacobian), logged EV_KICK with the kicked
    velocity; a kick that leaves the mean moving ends sticking (EV_RELEASE). At the lower
    wall the same with eta_minus, a kick downwards into it, and the kinds plus EV_LOWER.
    Returns (sticking, n_events, n_impacts)."""
    n = cfg[C_NCOEF]
    z[n] += strength
    if cfg[C_DRIVE_NODES] != 0 and n > 1:  # each node's own height F0_k, less the shared
        mod = strength / p[P_F0] if p[P_F0] != 0.0 else impulse_modulation(t, p)
        for i in range(n):
            acc = 0.0
            for k in range(table.shape[0]):
                acc += weights[k] * U[k, i] * (table[k, T_F0] - p[P_F0])
            z[n + i] += mod * acc
    upper = z[0] >= p[P_DELTA] and z[n] > 0.0
    if upper or (z[0] <= p[P_DELTA_MINUS] and z[n] < 0.0):
        v_kick = z[n]
        _reflect(z, m, n, p[P_ETA] if upper else p[P_ETA_MINUS], cfg[C_LAW] != LAW_MEAN)
        n_events = _log_event(log, n_events, t, v_kick,
                              np.int64(EV_KICK if upper else EV_KICK + EV_LOWER))
        n_impacts += 1
        if seg < stats.shape[0]:
            stats[seg, S_IMPACTS] += 1.0
    if sticking and z[n] != 0.0:
        sticking = np.bool_(False)
        lower = resting_side(z[0], p[P_DELTA], p[P_DELTA_MINUS]) < 0.0
        n_events = _log_event(log, n_events, t, 0.0,
                              np.int64(EV_RELEASE + EV_LOWER if lower else EV_RELEASE))
    return sticking, n_events, n_impacts


@njit(cache=True)
def impulses(t, z, m, sticking, j_imp, t_imp, force, force_end, seg, n_events, n_impacts, p,
             cfg, table, weights, U, snap, escape, stats, log):
    """Phase "impulses" (a breakpoint at t): the pulse that ends at t switches off, and
    every impulse due by t (within ``snap``) acts: a pulse switches on (force and end
    time), a Dirac impulse kicks (``kick``; the state is checked after each).

    Returns (status, sticking, j_imp, t_imp, force, force_end, n_events, n_impacts)."""
    pulse_model = cfg[C_IMPULSE] == IMPULSE_PULSE
    if pulse_model and t >= force_end - snap:
        force = 0.0
        force_end = np.inf
    T1 = 2.0 * np.pi / p[P_OMEGA1]
    while t_imp <= t + snap:
        strength = impulse_strength(t_imp, p)
        if pulse_model:
            force = strength
            force_end = t_imp + p[P_TAU]
        else:
            sticking, n_events, n_impacts = kick(t, z, m, strength, sticking, seg, n_events,
                                                 n_impacts, p, cfg, table, weights, U, stats,
                                                 log)
            status = state_status(z, 2 * cfg[C_NCOEF], escape)
            if status != OK:
                return status, sticking, j_imp, t_imp, force, force_end, n_events, n_impacts
        j_imp += 1
        t_imp = j_imp * T1
    return OK, sticking, j_imp, t_imp, force, force_end, n_events, n_impacts


# No call and nothing that can raise: numba then drops the reference counting of the
# array arguments (two atomic updates each per call otherwise), and the function is small
# enough for LLVM to inline into the driver (a call per output cost 8 % of a run with 20
# outputs per forcing period).
@njit(cache=True)
def store_outputs(t, z, dim, k_out, sticking, t_out, out, stats):
    """Phase "outputs" (a breakpoint at t): the state y is stored at every output time
    reached (``t_out[k_out] <= t``), with the sticking flag of the interval it closes.
    Returns the next k_out."""
    while k_out < t_out.shape[0] and t_out[k_out] <= t:
        for j in range(dim):
            out[k_out, j] = z[j]
        if k_out >= 1 and stats.shape[0] > 0:
            stats[k_out - 1, S_STICKING] = 1.0 if sticking else 0.0
        k_out += 1
    return k_out


@njit(cache=True, inline="always")
def renormalise_tangent(z, dim, k_first, k_stop, log_growth):
    """Phase "outputs" with ``renormalise``: Benettin's step at each output time
    t_out[k], k_first <= k < k_stop (k >= 1): W (``z[dim:]``) scaled to unit Frobenius
    norm, the log of the norm written to ``log_growth[k - 1]`` (-inf when sticking
    collapsed W, which then restarts from equal entries)."""
    size = z.shape[0]
    for k in range(max(k_first, 1), k_stop):
        norm = 0.0
        for j in range(dim, size):
            norm += z[j] * z[j]
        norm = math.sqrt(norm)
        if norm > 0.0 and norm < np.inf:
            log_growth[k - 1] = math.log(norm)
            for j in range(dim, size):
                z[j] /= norm
        else:
            log_growth[k - 1] = -np.inf
            for j in range(dim, size):
                z[j] = 1.0 / math.sqrt(size - dim)


@njit(cache=True, inline="always")
def next_breakpoint(t_next_out, t_imp, force_end, snap):
    """The next fixed time to step to exactly: output, impulse or pulse end (one within
    ``snap`` before the output time is the output time; see SNAP)."""
    t_break = t_next_out
    if t_imp < t_break:
        t_break = t_imp
    if force_end < t_break:
        t_break = force_end
    if t_next_out - t_break <= snap:
        t_break = t_next_out
    return t_break


@njit(cache=True, inline="always")
def contact_changes(sticking, acc, x0, v0, delta, delta_minus=-np.inf):
    """Whether sticking ends or begins at a breakpoint (phase "resume"), from the
    unconstrained acceleration ``acc`` of x_0 there: sticking ends when it points away from
    the wall it rests on (acc < 0 at the upper wall, acc > 0 at the lower); it begins at
    rest on a wall (x_0 = delta or delta_minus, v_0 = 0, e.g. the start state, from which
    no impact will be detected) with the net force into it."""
    if sticking:
        return resting_side(x0, delta, delta_minus) * acc < 0.0
    return v0 == 0.0 and ((x0 >= delta and acc > 0.0) or (x0 <= delta_minus and acc < 0.0))


@njit(cache=True, inline="always")
def stick_or_release(t, z, m, force, sticking, seg, n_events, p, cfg, table, weights, U, K,
                     work, stats, log):
    """Phase "resume", where ``contact_changes``: sticking ends at t (EV_RELEASE) or
    begins there (EV_STICK: the mean held at rest on the wall by ``_hold``), and f(t, z)
    into K[0] again for the next step; at the lower wall the kinds plus EV_LOWER.
    Returns (sticking, n_events); one evaluation."""
    lower = resting_side(z[0], p[P_DELTA], p[P_DELTA_MINUS]) < 0.0
    offset = EV_LOWER if lower else 0
    if sticking:
        sticking = np.bool_(False)
        n_events = _log_event(log, n_events, t, 0.0, np.int64(EV_RELEASE + offset))
    else:
        z[0] = p[P_DELTA_MINUS] if lower else p[P_DELTA]
        _hold(z, m, cfg[C_NCOEF], cfg[C_LAW])
        sticking = np.bool_(True)
        n_events = _log_event(log, n_events, t, 0.0, np.int64(EV_STICK + offset))
        if stats.shape[0] > 0:
            stats[seg, S_STICKS] += 1.0
    vector_field(z, m, p, cfg, table, weights, U, t, forcing(t, p, force), sticking, K[0], work)
    return sticking, n_events


@njit(cache=True, inline="always")
def step_size(t, h, t_break, hmax, sticking, stick_hmax):
    """The step to try from t: h within the largest step (T/32 while sticking), cut to
    end exactly at the breakpoint. Returns (h_try, is_last)."""
    h_lim = min(h, hmax)
    if sticking:
        h_lim = min(h_lim, stick_hmax)
    if t + h_lim >= t_break:
        return t_break - t, np.bool_(True)
    return h_lim, np.bool_(False)


@njit(cache=True, inline="always")
def register_step(t, x, v, h, k0x, k0v, mu, a, c, f, w, force, sticking, rtol, atol):
    """Phase "trial step" on the 2-D register path (the DMR, a Monte Carlo sample): one
    DOP853 step of size h from (t, x, v) with f(t, x, v) = (k0x, k0v), every stage in a
    scalar (``_stages2_dop853``) and the error estimate and wall margin from them
    (``_error2``). Scalars only, in and out: an array argument, even of an inlined
    function, costs reference-count updates, a third of a DMR step.

    Returns (err, margin, x_new, v_new, kx, kv), kx and kv the stages 1-12 (the last
    f(t + h, x_new, v_new)), stored in K only when the dense output needs them."""
    xn, vn, kx, kv = _stages2_dop853(t, x, v, h, k0x, k0v, mu, a, c, f, w, math.cos(w * t),
                                     math.sin(w * t), force, sticking)
    err, margin = _error2(h, x, v, xn, vn, k0x, k0v, kx, kv, rtol, atol)
    return err, margin, xn, vn, kx, kv


# The user laws' stages inlined into their register steps: the driver's one call reaches
# them (a call to a step that calls the stages cost a polynomial law's register step 9 %
# against the built-in law's in a loop of steps; inlined, 5 %)
_stages2_dop853_poly_inlined = njit(cache=True, inline="always")(
    _stages2_dop853_poly.py_func)
_stages2_dop853_fn_inlined = njit(cache=True, inline="always")(_stages2_dop853_fn.py_func)


@njit(cache=True)
def register_step_poly(t, x, v, h, k0x, k0v, law, f, w, force, sticking, rtol, atol):
    """``register_step`` of a polynomial force law (``force_law``'s tuple of C[j, k]).
    A call, not inlined: a second inlined step in the driver's loop made the paper's
    law's DMR 4 % slower (benchmarks.bench_several's speed check)."""
    xn, vn, kx, kv = _stages2_dop853_poly_inlined(t, x, v, h, k0x, k0v, law, f, w,
                                                  math.cos(w * t), math.sin(w * t), force,
                                                  sticking)
    err, margin = _error2(h, x, v, xn, vn, k0x, k0v, kx, kv, rtol, atol)
    return err, margin, xn, vn, kx, kv


@njit(cache=True)
def register_step_fn(t, x, v, h, k0x, k0v, address, theta, f, w, force, sticking, rtol,
                     atol):
    """``register_step`` of a compiled force function at ``address`` with its constants
    at ``theta`` (a call, as ``register_step_poly``; one call for both laws, choosing
    inside, made the polynomial law's DMR about 8 % slower)."""
    xn, vn, kx, kv = _stages2_dop853_fn_inlined(t, x, v, h, k0x, k0v, address, theta, f, w,
                                                math.cos(w * t), math.sin(w * t), force,
                                                sticking)
    err, margin = _error2(h, x, v, xn, vn, k0x, k0v, kx, kv, rtol, atol)
    return err, margin, xn, vn, kx, kv


@njit(cache=True, inline="always")
def next_step_size(method, err, h_try, h, is_last):
    """The step after an accepted one (err <= 1): the controller's factor, and at a
    breakpoint no smaller than the step the controller had asked for."""
    if err == 0.0:
        factor = MAX_FACTOR
    else:
        factor = min(MAX_FACTOR, SAFETY * step_factor(method, err))
    return max(h_try * factor, h if is_last else 0.0)


@njit(cache=True, inline="always")
def chatter(t, z, m, v_minus, force, p, cfg, table, weights, U, f_minus, work, side=1.0):
    """Phase "chatter -> stick", after an impact slower than the chatter velocity
    (eta < 1): with the net force into the wall (acceleration g > 0 at rest there) the
    bounces that would follow, of speeds eta^k v-, accumulate after
    2 eta v- / (g (1 - eta)) (flights 2 eta^k v- / g); the mean is put at rest on the wall
    (``_hold``) and sticks from then. Otherwise the impact law's rebound stands. At the
    lower wall (``side`` -1, eta_minus) the force into it is g < 0, and v- < 0: the same
    accumulation time.

    Returns (sticking, the time the sticking starts); one evaluation."""
    n = cfg[C_NCOEF]
    _, eta = wall_of(side, p)
    z[n] = 0.0
    acc = vector_field(z, np.int64(0), p, cfg, table, weights, U, t, forcing(t, p, force),
                       np.bool_(False), f_minus, work)
    if side * acc > 0.0:
        _hold(z, m, n, cfg[C_LAW])
        return True, t + 2.0 * eta * v_minus / (acc * (1.0 - eta))
    z[n] = -eta * v_minus
    return False, t


@njit(cache=True, inline="always")
def impact_event(method, t, h, theta, z, z_new, m, force, seg, n_events, n_impacts, p, cfg,
                 table, weights, U, K, K2, ztmp, f_minus, f_plus, work, stats, log, escape,
                 side=1.0):
    """Phase "impact": x_0 reaches the wall at theta h into the accepted step from t
    (``wall_crossing`` on its dense output). The state there is a re-step exactly to it
    (``restep_to``: Newton on full Runge-Kutta steps, into z_new); it takes the impact
    law on y and its saltation matrix on W (``_impact``); the impact is logged (EV_IMPACT,
    or EV_GRAZE below EVENT_GRAZE_VELOCITY, with the pre-impact velocity v-) and counted;
    an impact slower than the chatter velocity may end in sticking (``chatter``); the state
    is checked (near grazing the saltation matrix, which divides by v-, can overflow).
    Then f(t, z) into K[0] for the next step. ``side`` -1: the lower wall (re-step to
    x_0 = delta_minus, eta_minus, the kinds plus EV_LOWER, the logged v- negative; the
    statistics take the speed |v-|).

    Returns (t, status, sticking, n_events, n_impacts, evaluations), t the impact time."""
    root = IMPACT_ROOT if side > 0.0 else IMPACT_LOWER_ROOT
    hh, evals = restep_to(method, np.int64(root), t, z, h, theta, K, K2, z_new, ztmp,
                          m, p, cfg, table, weights, U, force, work)
    t = t + hh
    for j in range(z.shape[0]):
        z[j] = z_new[j]
    v_minus, e = _impact(t, z, m, p, cfg, table, weights, U, force, f_minus, f_plus, work,
                         side)
    evals += e
    n_impacts += 1
    speed = side * v_minus
    offset = 0 if side > 0.0 else EV_LOWER
    kind = np.int64((EV_GRAZE if speed < EVENT_GRAZE_VELOCITY else EV_IMPACT) + offset)
    n_events = _log_event(log, n_events, t, v_minus, kind)
    want_stats = stats.shape[0] > 0
    if want_stats:
        stats[seg, S_IMPACTS] += 1.0
        if speed < stats[seg, S_MIN_VELOCITY]:
            stats[seg, S_MIN_VELOCITY] = speed
    sticking = False
    _, eta = wall_of(side, p)
    if eta < 1.0 and speed < p[P_CHATTER_V]:
        sticking, t_stick = chatter(t, z, m, v_minus, force, p, cfg, table, weights, U,
                                    f_minus, work, side)
        evals += 1
        if sticking:
            n_events = _log_event(log, n_events, t_stick, 0.0, np.int64(EV_STICK + offset))
            if want_stats:
                stats[seg, S_STICKS] += 1.0
    status = state_status(z, 2 * cfg[C_NCOEF], escape)
    if status == OK:
        vector_field(z, m, p, cfg, table, weights, U, t, forcing(t, p, force), sticking, K[0],
                     work)
        evals += 1
    return t, status, sticking, n_events, n_impacts, evals


@njit(cache=True, inline="always")
def pulls_off(t, z, force, p, cfg, table, weights, U, f_plus, work):
    """Whether the unconstrained acceleration of the mean at rest on the wall turns away
    from it at the state z at t (the release condition of sticking: acc < 0 at the upper
    wall, acc > 0 at the lower, the wall z[0] rests on); one evaluation."""
    side = resting_side(z[0], p[P_DELTA], p[P_DELTA_MINUS])
    acc = vector_field(z, np.int64(0), p, cfg, table, weights, U, t, forcing(t, p, force),
                       np.bool_(False), f_plus, work)
    return side * acc < 0.0


@njit(cache=True, inline="always")
def release_event(method, t, h, z, m, force, n_events, p, cfg, table, weights, U, K, F, ztmp,
            f_plus, work, log, escape):
    """Phase "release": sticking ends inside the accepted step from t (its dense output F
    ready), where the unconstrained acceleration at rest on the wall turns away from it
    (``pulls_off``), located by bisection to 1e-13 in time; the state there, held on the
    wall, leaves it (EV_RELEASE; EV_RELEASE + EV_LOWER from the lower wall). Then f(t, z)
    into K[0] for the next step.

    Returns (t, status, n_events, evaluations)."""
    n = cfg[C_NCOEF]
    lower = resting_side(z[0], p[P_DELTA], p[P_DELTA_MINUS]) < 0.0
    delta = p[P_DELTA_MINUS] if lower else p[P_DELTA]
    lo = 0.0
    hi = 1.0
    evals = 0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        dense_state(method, mid, z, F, ztmp)
        ztmp[0] = delta
        ztmp[n] = 0.0
        evals += 1
        if pulls_off(t + mid * h, ztmp, force, p, cfg, table, weights, U, f_plus, work):
            hi = mid
        else:
            lo = mid
        if (hi - lo) * h < 1e-13:
            break
    dense_state(method, hi, z, F, ztmp)
    t = t + hi * h
    for j in range(z.shape[0]):
        z[j] = ztmp[j]
    z[0] = delta
    z[n] = 0.0
    n_events = _log_event(log, n_events, t, 0.0,
                          np.int64(EV_RELEASE + EV_LOWER if lower else EV_RELEASE))
    status = state_status(z, 2 * n, escape)
    if status == OK:
        vector_field(z, m, p, cfg, table, weights, U, t, forcing(t, p, force), np.bool_(False),
                     K[0], work)
        evals += 1
    return t, status, n_events, evals


@njit(cache=True, inline="always")
def free_flight_gap(method, t, z, h, seg, K, K2, F, z_top, ztmp, m, p, cfg, table, weights,
                    U, force, work, stats, side):
    """Phase "gap statistics": the highest maximum of x_0 inside the accepted step (dense
    output F ready; ``free_flight_maximum``), refined by re-stepping exactly to it
    (``restep_to``) when it comes closer to the wall than the interval's smallest gap so
    far (``stats[seg, S_GAP]``, delta - x_0 at the maxima). side = -1.0: the lowest
    minimum and the lower wall's gap x_0 - delta_minus (``stats[seg, S_GAP_LOWER]``).
    Returns the evaluations."""
    upper = side > 0.0
    wall = p[P_DELTA] if upper else p[P_DELTA_MINUS]
    slot = S_GAP if upper else S_GAP_LOWER
    gap, theta = free_flight_maximum(method, z[0], dense_column(F, np.int64(0)), wall, side)
    if gap < stats[seg, slot]:
        _, evals = restep_to(method, np.int64(MAXIMUM_ROOT if upper else MINIMUM_ROOT), t, z,
                             h, theta, K, K2, z_top, ztmp, m, p, cfg, table, weights, U, force,
                             work)
        stats[seg, slot] = side * (wall - z_top[0])
        return evals
    return 0


# ---------------------------------------------------------------------------
# The driver
@njit(cache=True)
def integrate(z, m, t_out, include_start, renormalise, p, cfg, table, weights, U, rtol, atol,
              out, stats, log_growth, log):
    """Integrate the augmented state ``z`` in place through the output times ``t_out``:
    ``integrate_with`` on freshly allocated work arrays (``allocate_scratch``)."""
    K, K2, F, z_new, ztmp, z_top, f_minus, f_plus, work = allocate_scratch(
        z.shape[0], 2 * cfg[C_NCOEF], table.shape[0])
    return integrate_with(z, m, t_out, include_start, renormalise, p, cfg, table, weights, U,
                          rtol, atol, out, stats, log_growth, log, K, K2, F, z_new, ztmp, z_top,
                          f_minus, f_plus, work)


@njit(cache=True, inline="always")
def integrate_with(z, m, t_out, include_start, renormalise, p, cfg, table, weights, U, rtol,
                   atol, out, stats, log_growth, log, K, K2, F, z_new, ztmp, z_top, f_minus,
                   f_plus, work):
    """Integrate the augmented state ``z`` in place through the output times ``t_out``,
    with the work arrays of ``allocate_scratch`` passed in: it allocates nothing, so the
    same driver compiles for a GPU thread (``opa._gpu``), whose work arrays are its own
    local memory.

    Parameters
    ----------
    z : (D + D m,) state at ``t_out[0]`` and the row-major tangent matrix W (D, m);
        it ends as the augmented state at the last time reached.
    m : number of tangent columns (0: the plain trajectory).
    t_out : (n_out,) increasing output times, hit exactly as breakpoints.
    include_start : apply an impulse that falls on ``t_out[0]`` (otherwise it belongs to
        the previous interval). States are right-continuous: impulses at an output time
        are applied before the state is stored.
    renormalise : scale W to unit Frobenius norm at every output time and write the log
        of its growth over interval i to ``log_growth[i]`` (``-inf`` when sticking
        collapsed it; W then restarts from equal entries): Benettin's loop with the
        exact tangent map.
    p, cfg : parameter and configuration vectors (the ``P_*`` and ``C_*`` indices).
    table : (Q, N_TABLE) the coefficients of the force law at each node; weights : (Q,)
        the rule's weights; U : (Q, n + 1) node-major basis values.
    out : (n_out, D) the states at ``t_out`` (W is not stored); rows not reached are NaN.
    stats : (n_out - 1, N_STATS) per-interval statistics (impacts, smallest pre-impact
        speed |v-|, sticking episodes, steps, sticking at the end, smallest free-flight
        gap delta - x_0 at maxima, and x_0 - delta_minus at minima: inf without a lower
        wall), or an empty (0, N_STATS) array to skip them.
    log : (cap, 3) event rows (time, velocity, kind EV_*, plus EV_LOWER at the lower
        wall); impacts record the pre-impact velocity of x_0 (negative at the lower
        wall); rows beyond cap are counted, not written.

    Returns
    -------
    status, n_events, n_impacts, n_steps, n_rhs

    The state is checked after every accepted step and every jump (impact, impulse
    kick, sticking, release): a NaN or inf component ends the run with DIVERGED, a state
    component beyond ``escape_bound`` (of the start state) with ESCAPED.

    The loop is the phases of the module docstring: at each breakpoint ``impulses``,
    ``store_outputs`` and the resume; then the steps up to the next breakpoint, each a
    trial step (``register_step`` on the 2-D register path, else ``rk_step``) and, once
    accepted, the events inside it on its dense output (``wall_crossing`` then
    ``impact_event``, ``release_event``, ``free_flight_gap``) before the state advances.
    """
    n = cfg[C_NCOEF]
    dim = 2 * n
    size = z.shape[0]
    method = cfg[C_METHOD]
    last = last_stage(method)
    delta = p[P_DELTA]
    delta_minus = p[P_DELTA_MINUS]  # -inf: no lower wall
    max_steps = cfg[C_MAXSTEPS]
    hmax = p[P_HMAX]
    stick_hmax = 2.0 * np.pi / p[P_OMEGA] / 32.0
    want_stats = stats.shape[0] > 0
    lower_stats = want_stats and delta_minus > -np.inf  # the lower wall's gap (S_GAP_LOWER)
    n_out = t_out.shape[0]
    # the 2-D register path, decided once: its trial step takes and returns scalars only
    two_d = method == METHOD_DOP853 and size == 2 and is_deterministic(m, cfg, table, p)
    mu, a_lin, c_cub, f_amp, w = p[P_MU], p[P_A], p[P_C], p[P_F], p[P_OMEGA]
    poly = cfg[C_FORCE] == FORCE_POLYNOMIAL
    law = force_law(p)  # a polynomial law's coefficients (read only when poly)
    function = cfg[C_FORCE] == FORCE_FUNCTION
    address = cfg[C_FUNCTION]  # a compiled function's (read only when function)
    constants = _theta_of_p(p)  # the address of a compiled function's constants
    kx = kv = _NO_STAGES
    off = np.bool_(False)  # typed, not literal: a literal False is a type of its own
    t = t_out[0]
    t_end = t_out[n_out - 1]
    escape = escape_bound(z[:dim], p, cfg)
    snap = SNAP * max(1.0, abs(t_end))
    status, j_imp, t_imp, force, force_end = start_run(z, t, t_end, include_start, p, cfg,
                                                       escape, snap, out, stats)
    if status != OK:
        return status, 0, 0, 0, 0
    sticking = off
    n_events = n_impacts = k_out = np.int64(0)  # typed: passed to the phases
    n_steps = n_rhs = n_passes = 0
    h = 0.0
    while True:
        # Every pass takes a step or passes a breakpoint closer than round-off; the cap
        # only matters for the latter, e.g. impulse times denser than the resolution of t,
        # which would otherwise loop without a step.
        n_passes += 1
        if n_passes > 2 * (max_steps + n_out):
            status = MAX_STEPS
            break
        seg = max(k_out - 1, 0)  # the output interval being integrated (stats row)
        # ---- breakpoints at t: impulses (and pulse ends), outputs
        if t_imp <= t + snap or t >= force_end - snap:
            status, sticking, j_imp, t_imp, force, force_end, n_events, n_impacts = impulses(
                t, z, m, sticking, j_imp, t_imp, force, force_end, seg, n_events, n_impacts,
                p, cfg, table, weights, U, snap, escape, stats, log)
            if status != OK:
                break
        if t_out[k_out] <= t:
            k_stored = k_out
            k_out = store_outputs(t, z, dim, k_out, sticking, t_out, out, stats)
            if renormalise and m > 0:
                renormalise_tangent(z, dim, k_stored, k_out, log_growth)
            if k_out >= n_out:
                break
            seg = k_out - 1
        t_break = next_breakpoint(t_out[k_out], t_imp, force_end, snap)
        # ---- resume: f(t, z) for the next step; sticking may end or begin at t itself
        acc = vector_field(z, m, p, cfg, table, weights, U, t, forcing(t, p, force), sticking, K[0],
                           work)
        n_rhs += 1
        if contact_changes(sticking, acc, z[0], z[n], delta, delta_minus):
            sticking, n_events = stick_or_release(t, z, m, force, sticking, seg, n_events, p, cfg,
                                                  table, weights, U, K, work, stats, log)
            n_rhs += 1
        if h == 0.0:  # the first step: a fraction of the interval, then the controller's
            h = min(1e-3, 0.01 * (t_break - t) + 1e-12)

        # ---- steps up to t_break
        while t < t_break:
            if n_steps >= max_steps:
                status = MAX_STEPS
                break
            h_try, is_last = step_size(t, h, t_break, hmax, sticking, stick_hmax)
            if h_try <= 1e-14 * max(1.0, abs(t)):
                if is_last:
                    t = t_break
                    break
                status = STEP_COLLAPSE
                break
            # ---- trial step into z_new, K[last] = f(t + h_try, z_new)
            if two_d:
                if poly:
                    err, margin, z_new[0], z_new[1], kx, kv = register_step_poly(
                        t, z[0], z[1], h_try, K[0, 0], K[0, 1], law, f_amp, w, force,
                        sticking, rtol, atol)
                elif function:
                    err, margin, z_new[0], z_new[1], kx, kv = register_step_fn(
                        t, z[0], z[1], h_try, K[0, 0], K[0, 1], address, constants, f_amp, w,
                        force, sticking, rtol, atol)
                else:
                    err, margin, z_new[0], z_new[1], kx, kv = register_step(
                        t, z[0], z[1], h_try, K[0, 0], K[0, 1], mu, a_lin, c_cub, f_amp, w,
                        force, sticking, rtol, atol)
                n_rhs += last
            else:
                n_rhs += rk_step(method, t, z, h_try, K, z_new, ztmp, m, p, cfg, table, weights,
                                 U, force, sticking, work)
                err = error_norm(method, z, z_new, K, h_try, rtol, atol)
                margin = wall_margin(K, last, n, h_try)
            n_steps += 1
            if want_stats:
                stats[seg, S_STEPS] += 1.0
            if not (err < np.inf):  # a non-finite trial: retry a quarter as long
                h = 0.25 * h_try
                if h < 1e-14 * max(1.0, abs(t)):
                    status = DIVERGED
                    break
                continue
            if err > 1.0:  # rejected
                h = h_try * max(MIN_FACTOR, SAFETY * step_factor(method, err))
                continue
            h_next = next_step_size(method, err, h_try, h, is_last)

            # ---- events inside the accepted step, on its dense output
            if sticking:  # sticking ends inside the step?
                n_rhs += 1
                jump = pulls_off(t + h_try, z_new, force, p, cfg, table, weights, U, f_plus, work)
                near_wall = near_floor = near_top = near_bottom = off
            else:  # an impact, or a free-flight maximum closer than the smallest gap so far?
                jump = off
                near_wall = may_reach_wall(z[0], z_new[0], margin, delta)
                near_floor = may_reach_floor(z[0], z_new[0], margin, delta_minus)
                near_top = want_stats and K[0, 0] > 0.0 and may_reach_wall(
                    z[0], z_new[0], margin, delta - stats[seg, S_GAP])
                near_bottom = lower_stats and K[0, 0] < 0.0 and may_reach_floor(
                    z[0], z_new[0], margin, delta_minus + stats[seg, S_GAP_LOWER])
            if jump or near_wall or near_floor or near_top or near_bottom:
                n_rhs += step_dense(two_d, kx, kv, method, t, z, z_new, h_try, K, F, ztmp, m, p,
                                    cfg, table, weights, U, force, sticking, work)
            if jump:
                t, status, n_events, evals = release_event(method, t, h_try, z, m, force,
                                                           n_events, p, cfg, table, weights, U,
                                                           K, F, ztmp, f_plus, work, log, escape)
                n_rhs += evals
                sticking = off
            elif near_wall or near_floor:  # the first crossing of either wall in the step
                theta, side = first_crossing(method, z[0], dense_column(F, np.int64(0)), h_try,
                                             delta, delta_minus, near_wall, near_floor)
                jump = theta > 0.0
                if jump:
                    t, status, sticking, n_events, n_impacts, evals = impact_event(
                        method, t, h_try, theta, z, z_new, m, force, seg, n_events, n_impacts, p,
                        cfg, table, weights, U, K, K2, ztmp, f_minus, f_plus, work, stats, log,
                        escape, side)
                    n_rhs += evals
                    h_next = max(h_next * 0.5, 1e-10)
            if jump:  # the state jumped at t inside the step: resume stepping from there
                if status != OK:
                    break
                h = h_next
                if t >= t_break:
                    t = t_break
                    break
                continue
            if near_top:
                n_rhs += free_flight_gap(method, t, z, h_try, seg, K, K2, F, z_top, ztmp, m, p,
                                         cfg, table, weights, U, force, work, stats, 1.0)
            if near_bottom:
                n_rhs += free_flight_gap(method, t, z, h_try, seg, K, K2, F, z_top, ztmp, m, p,
                                         cfg, table, weights, U, force, work, stats, -1.0)
            # ---- accept: advance to the step's end (held on the wall while sticking)
            t = t_break if is_last else t + h_try
            if two_d:
                z[0] = z_new[0]
                z[1] = z_new[1]
                K[0, 0] = kx[11]
                K[0, 1] = kv[11]
            else:
                for j in range(size):
                    z[j] = z_new[j]
                    K[0, j] = K[last, j]
            if sticking:
                z[0] = delta if resting_side(z[0], delta, delta_minus) > 0.0 else delta_minus
                z[n] = 0.0
            h = h_next
            status = state_status(z, dim, escape)
            if status != OK:
                break
        if status != OK:
            break
    return status, n_events, n_impacts, n_steps, n_rhs


# ---------------------------------------------------------------------------
# Many independent runs of the one integrator: one parallel driver for every batch (the
# samples of an ensemble, the elements of a multi-element system, the configurations of
# one OPA system, the event logs of sampled systems), so that it is compiled once.
@njit(cache=True)
def run_one(y0, t_out, p, cfg, table, weights, U, rtol, atol, out, log):
    """One plain trajectory from y0 (not modified) with the impulse at t_out[0] applied:
    the DMR, one Monte Carlo sample or one OPA system. Returns what ``integrate`` does."""
    z = y0.copy()
    # typed arguments: the signature of a call from Python, so integrate compiles once
    return integrate(z, np.int64(0), t_out, np.bool_(True), np.bool_(False), p, cfg, table,
                     weights, U, rtol, atol, out, np.empty((0, N_STATS)), np.empty(0), log)


@njit(cache=True, parallel=True)
def run_batch(y0, t_out, P, cfgs, table, weights, U, rtol, atol, out, logs, counters, abort):
    """B plain runs in parallel: run b starts from y0 with parameters ``P[b]``,
    configuration ``cfgs[b]`` and rule ``table[b], weights[b], U[b]`` (node-major).

    out : (B, n_out, dim); logs : (B, cap, 3) (cap may be 0); counters : (B, 5) with the
    status, events, impacts, steps and right-hand sides of each run.
    abort : (1,) int64. With ``abort[0] == 0`` the first run that fails sets it to 1 and
    the runs not yet started are marked ``SKIPPED`` (an ensemble stops at its first
    failed sample); with ``abort[0] < 0`` every run is made whatever happens. Each run
    depends on nothing but its own inputs, so the results do not depend on the threads.
    """
    B = P.shape[0]
    for b in prange(B):
        if abort[0] > 0:
            counters[b, 0] = SKIPPED
            continue
        res = run_one(y0, t_out, P[b], cfgs[b], table[b], weights[b], U[b], rtol, atol, out[b],
                      logs[b])
        for j in range(5):
            counters[b, j] = res[j]
        if res[0] != OK and abort[0] == 0:
            abort[0] = 1


@njit(cache=True, parallel=True)
def run_batch_from(Y0, include_start, t_out, P, cfgs, table, weights, U, rtol, atol, out,
                   logs, counters):
    """B plain runs in parallel, as ``run_batch`` but each from its own state ``Y0[b]``
    (B, dim), with the impulse at ``t_out[0]`` applied only if ``include_start`` (runs
    resumed mid-way, as the attractor classification's chunks are). Every run is made."""
    B = P.shape[0]
    for b in prange(B):
        z = Y0[b].copy()
        res = integrate(z, np.int64(0), t_out, include_start, np.bool_(False), P[b], cfgs[b],
                        table[b], weights[b], U[b], rtol, atol, out[b],
                        np.empty((0, N_STATS)), np.empty(0), logs[b])
        for j in range(5):
            counters[b, j] = res[j]


# ---------------------------------------------------------------------------
# A user's compiled force function (FORCE_FUNCTION): made here, since jitted code lives in
# this module only; ``opa._forcefunction`` writes the Python source and keeps the result.
FUNCTION_SIGNATURE = types.float64(types.float64, types.float64, types.CPointer(types.float64))


def jit_user_function(function):
    """A user's Python function, jitted for its calls from a compiled force function
    (returned as it is when it is jitted already)."""
    from numba.core.registry import CPUDispatcher

    if isinstance(function, CPUDispatcher):
        return function
    return njit(function)


def compile_force_function(function):
    """``function(x, v, theta)`` (theta: a pointer to its constants) as a C function of
    FUNCTION_SIGNATURE; its ``address`` goes to cfg[C_FUNCTION]. One compile per model and
    process (about 0.1 s to 1 s): the kernel itself stays compiled and cached."""
    from numba import cfunc

    return cfunc(FUNCTION_SIGNATURE)(function)
