"""Analytic truths the tests share: closed forms that owe nothing to ``opa``, ``mc`` or
``compare``, each defined once here and checked against something independent in
``tests/test_truths.py`` (scipy's ``solve_ivp`` and ``quad``, ``scipy.stats``).

The oscillator is the paper's eq. (1) with the nonlinear terms switched off where a
closed form needs it (mu = c = 0):

    x'' = mu (1 - x'^2) x' - a x - c x^3 + f cos(omega t) + F(t),   x < delta
    x'(t+) = -eta x'(t-)                                             at x = delta

and xi follows the semicircle law p(xi) = (2/pi) sqrt(1 - xi^2) on [-1, 1].
"""

from __future__ import annotations

import math
from functools import lru_cache
from math import comb

import numpy as np
from scipy.integrate import quad
from scipy.special import eval_chebyu, roots_jacobi

# --------------------------------------------------------------------------- linear oscillator


def linear_oscillator(t, a, f, omega, x0, v0):
    """The undamped forced linear oscillator without a wall: returns ``(x, v)`` at ``t``.

    ``x'' + a x = f cos(omega t)``, ``x(0) = x0``, ``x'(0) = v0``, with ``a > 0`` and
    ``omega^2 != a``. With ``w0 = sqrt(a)`` and the particular amplitude
    ``p = f / (a - omega^2)`` (undetermined coefficients)::

        x(t) = (x0 - p) cos(w0 t) + v0 / w0 sin(w0 t) + p cos(omega t)
        v(t) = -(x0 - p) w0 sin(w0 t) + v0 cos(w0 t) - p omega sin(omega t)

    >>> x, v = linear_oscillator(0.0, 1.3, 2.0, 2.8, -1.0, 0.4)
    >>> round(float(x), 12), round(float(v), 12)
    (-1.0, 0.4)
    """
    w0 = np.sqrt(a)
    p = f / (a - omega**2)
    x = (x0 - p) * np.cos(w0 * t) + v0 / w0 * np.sin(w0 * t) + p * np.cos(omega * t)
    v = -(x0 - p) * w0 * np.sin(w0 * t) + v0 * np.cos(w0 * t) - p * omega * np.sin(omega * t)
    return x, v


def linear_flow(a, s):
    """The state-transition matrix of ``x'' + a x = 0`` (``a > 0``) over a time ``s``::

        [x(s), v(s)] = [[cos(w0 s), sin(w0 s) / w0], [-w0 sin(w0 s), cos(w0 s)]] [x(0), v(0)]

    (the homogeneous part of :func:`linear_oscillator`, ``w0 = sqrt(a)``).
    """
    w0 = math.sqrt(a)
    return np.array([[math.cos(w0 * s), math.sin(w0 * s) / w0],
                     [-w0 * math.sin(w0 * s), math.cos(w0 * s)]])


def impulse_size(t_j, F0, a1, omega1, n):
    """The impulse at ``t_j = j 2 pi / omega1``: ``I_j = F0 (1 + a1 sin(omega1 t_j / n))``
    (the impulse train F(t) of Huang et al. 2023, eq. (1), as README's "impulse model" reads
    it: a velocity jump for Dirac impulses, the height of a rectangular force for pulses).

    >>> float(impulse_size(0.0, 0.3, 1.0, 1.0, 2))
    0.3
    """
    return F0 * (1.0 + a1 * np.sin(omega1 * t_j / n))


def kicked_linear_oscillator(t, a, f, omega, x0, v0, kicks):
    """:func:`linear_oscillator` with Dirac kicks ``kicks = [(t_j, I_j), ...]``, by
    superposition (the equation is linear): each kick adds the free response to a velocity
    jump ``I_j`` at ``t_j``::

        x += I_j sin(w0 (t - t_j)) / w0,   v += I_j cos(w0 (t - t_j))     for t >= t_j

    Outputs are right-continuous: at ``t = t_j`` the kick is already in.
    """
    t = np.asarray(t, dtype=float)
    x, v = linear_oscillator(t, a, f, omega, x0, v0)
    w0 = math.sqrt(a)
    for t_j, size in kicks:
        s = np.maximum(t - t_j, 0.0)
        kick = size * (t >= t_j)
        x = x + kick * np.sin(w0 * s) / w0
        v = v + kick * np.cos(w0 * s)
    return x, v


def pulsed_linear_oscillator(t, a, f, omega, x0, v0, pulses, tau):
    """:func:`linear_oscillator` with rectangular forces ``pulses = [(t_j, F_j), ...]`` of
    width ``tau``, by superposition. With ``h = F_j / a`` and ``s = t - t_j`` a pulse adds
    (Duhamel's integral of a constant force, then the free response after it ends)::

        0 <= s < tau:  x += h (1 - cos(w0 s)),
                       v += h w0 sin(w0 s)
        s >= tau:      x += h (cos(w0 (s - tau)) - cos(w0 s)),
                       v += h w0 (sin(w0 s) - sin(w0 (s - tau)))
    """
    t = np.asarray(t, dtype=float)
    x, v = linear_oscillator(t, a, f, omega, x0, v0)
    w0 = math.sqrt(a)
    for t_j, height in pulses:
        h = height / a
        s = t - t_j
        on, after = (s >= 0) & (s < tau), s >= tau
        x = x + np.where(on, h * (1 - np.cos(w0 * s)), 0.0)
        x = x + np.where(after, h * (np.cos(w0 * (s - tau)) - np.cos(w0 * s)), 0.0)
        v = v + np.where(on, h * w0 * np.sin(w0 * s), 0.0)
        v = v + np.where(after, h * w0 * (np.sin(w0 * s) - np.sin(w0 * (s - tau))), 0.0)
    return x, v


def linear_impact_orbit(a, f, omega, eta, delta):
    """The period-1 single-impact orbit of ``x'' + a x = f cos(omega t)``, ``x <= delta``.

    With ``x = X cos(omega t) + h(t)``, ``X = f / (a - omega^2)``, the free flight of one
    period ``T = 2 pi / omega`` from the post-impact state ``(delta, -eta v)`` at phase
    ``phi = omega t*`` back to ``(delta, v)`` gives, with ``K = -sqrt(a) tan(sqrt(a) T / 2)``::

        (1 - eta) v = -2 X omega sin(phi),   (1 + eta) v = 2 (delta - X cos phi) K,

    i.e. ``X omega (1 + eta) sin(phi) - (1 - eta) K X cos(phi) = -(1 - eta) K delta``
    (the fixed-point equations of the impact map, derived from :func:`linear_oscillator`).
    The monodromy matrix over ``[0, T]`` is ``Phi(T - t*) S Phi(t*)`` with the linear flow
    ``Phi`` (:func:`linear_flow`) and the saltation matrix
    ``S = [[-eta, 0], [(1 + eta) acc / v, -eta]]``, ``acc = -a delta + f cos(phi)``;
    its determinant is ``eta^2``.

    Returns (state at t = 0, monodromy matrix, impact phase phi, impact velocity v > 0).
    """
    w0 = math.sqrt(a)
    T = 2 * math.pi / omega
    X = f / (a - omega**2)
    K = -w0 * math.tan(w0 * T / 2)
    alpha, beta = X * omega * (1 + eta), (1 - eta) * K * X
    R, psi = math.hypot(alpha, beta), math.atan2(beta, alpha)
    base = math.asin(-(1 - eta) * K * delta / R)
    for root in (base, math.pi - base):
        phi = (root + psi) % (2 * math.pi)
        v = -2 * X * omega * math.sin(phi) / (1 - eta)
        if v > 0:
            break
    t_star = phi / omega
    h0, dh0 = delta - X * math.cos(phi), -eta * v + X * omega * math.sin(phi)
    s = T - t_star
    y0 = np.array([X + h0 * math.cos(w0 * s) + dh0 / w0 * math.sin(w0 * s),
                   -h0 * w0 * math.sin(w0 * s) + dh0 * math.cos(w0 * s)])
    acc = -a * delta + f * math.cos(phi)
    S = np.array([[-eta, 0.0], [(1 + eta) * acc / v, -eta]])
    return y0, linear_flow(a, T - t_star) @ S @ linear_flow(a, t_star), phi, v


# --------------------------------------------------------------------------- the wall


def bouncing_sequence(g, h, eta, count):
    """Impact times and speeds of a mass dropped from rest at a distance ``h`` from the wall
    under a constant force ``g`` towards it (``x'' = g``, ``x(0) = delta - h``, ``v(0) = 0``).

    The first impact comes at ``t_1 = sqrt(2 h / g)`` with speed ``v_1 = sqrt(2 g h)``; each
    rebound ``-eta v_k`` flies ``2 eta v_k / g`` and returns at ``v_{k+1} = eta v_k``.
    Returns ``(times, speeds)`` of the first ``count`` impacts.

    >>> bouncing_sequence(1.0, 0.5, 0.5, 3)
    (array([1. , 2. , 2.5]), array([1.  , 0.5 , 0.25]))
    """
    speeds = math.sqrt(2 * g * h) * eta ** np.arange(count)
    flights = np.concatenate([[math.sqrt(2 * h / g)], 2 * eta * speeds[:-1] / g])
    return np.cumsum(flights), speeds


def chatter_time(v, g, eta):
    """Time from an impact at speed ``v`` under a constant force ``g`` into the wall to the
    accumulation point of the bounces (chatter), where the mass comes to rest on the wall:
    the geometric sum of the flights ``2 eta^k v / g``, ``k >= 1``, is ``2 eta v / (g (1 - eta))``.

    >>> chatter_time(1.0, 1.0, 0.5)
    2.0
    """
    return 2 * eta * v / (g * (1 - eta))


def accumulation_time(g, h, eta):
    """When a mass dropped from rest at ``h`` (see :func:`bouncing_sequence`) comes to rest on
    the wall: ``t_inf = sqrt(2 h / g) + 2 eta sqrt(2 g h) / (g (1 - eta))``.

    >>> accumulation_time(1.0, 0.5, 0.5)
    3.0
    """
    return math.sqrt(2 * h / g) + chatter_time(math.sqrt(2 * g * h), g, eta)


def release_from_wall(t, f, omega, delta=0.0):
    """A mass at rest on the wall ``x = delta`` under ``x'' = f cos(omega t)`` (``f > 0``,
    no stiffness or damping) stays there while the force pushes into the wall and leaves
    where it turns, at ``t_r = pi / (2 omega)``; after that, from rest at the wall::

        x(t) = delta - f / omega^2 cos(omega t) - f / omega (t - t_r)
        v(t) = f / omega (sin(omega t) - 1)

    Returns ``(t_r, x, v)`` with ``x`` and ``v`` at ``t`` (meaningful for ``t >= t_r``).
    """
    t_r = math.pi / (2 * omega)
    t = np.asarray(t, dtype=float)
    x = delta - f / omega**2 * np.cos(omega * t) - f / omega * (t - t_r)
    v = f / omega * (np.sin(omega * t) - 1.0)
    return t_r, x, v


def kick_at_rest_on_the_wall(size, eta):
    """The velocity right after a kick ``size`` to a mass at rest on the wall: a kick into
    the wall (``size > 0``) is an impact at that speed and rebounds at ``-eta size``; a kick
    away from it (``size < 0``) is just that velocity.

    >>> kick_at_rest_on_the_wall(1.0, 0.8), kick_at_rest_on_the_wall(-0.5, 0.8)
    (-0.8, -0.5)
    """
    return -eta * size if size > 0 else size


# --------------------------------------------------------------------------- semicircle law


def semicircle_density(x):
    """The semicircle (Wigner) density ``p(x) = (2/pi) sqrt(1 - x^2)`` on [-1, 1], 0 outside.

    >>> float(semicircle_density(0.0)) == 2 / math.pi
    True
    """
    x = np.asarray(x, dtype=float)
    return 2 / np.pi * np.sqrt(np.clip(1 - x * x, 0.0, None))


def semicircle_cdf(x):
    """``P(xi <= x) = 1/2 + (x sqrt(1 - x^2) + arcsin x) / pi`` on [-1, 1] (the integral
    of :func:`semicircle_density`), 0 below and 1 above.

    >>> float(semicircle_cdf(0.0)), float(semicircle_cdf(1.0))
    (0.5, 1.0)
    """
    x = np.clip(np.asarray(x, dtype=float), -1.0, 1.0)
    return 0.5 + (x * np.sqrt(1 - x * x) + np.arcsin(x)) / np.pi


def semicircle_mass(lo, hi):
    """``P(lo < xi < hi)`` under the semicircle law: ``semicircle_cdf(hi) - semicircle_cdf(lo)``."""
    return float(semicircle_cdf(hi) - semicircle_cdf(lo))


def semicircle_moment(k: int) -> float:
    """``E[xi^k]`` under the semicircle law: ``Catalan(k/2) / 4^(k/2)`` for even ``k``
    (the Wigner semicircle of radius 2 has the Catalan numbers as its even moments; radius 1
    scales them by ``2^-k``), 0 for odd ``k``.

    >>> [semicircle_moment(k) for k in range(7)]
    [1.0, 0.0, 0.25, 0.0, 0.125, 0.0, 0.078125]
    """
    if k % 2:
        return 0.0
    m = k // 2
    return comb(2 * m, m) / (m + 1) / 4.0**m


def semicircle_expectation(g, **quad_options) -> float:
    """``E[g(xi)] = (2/pi) int_{-1}^{1} g(x) sqrt(1 - x^2) dx`` by QUADPACK's QAWS rule
    (``scipy.integrate.quad`` with ``weight="alg"``, ``wvar=(1/2, 1/2)``, which integrates
    against ``(1 + x)^(1/2) (1 - x)^(1/2)`` exactly). ``quad_options`` go to ``quad``
    (default ``limit=200``).
    """
    value, _ = quad(g, -1.0, 1.0, weight="alg", wvar=(0.5, 0.5),
                    **{"limit": 200, **quad_options})
    return 2.0 / np.pi * value


def semicircle_gauss_rule(q: int) -> tuple[np.ndarray, np.ndarray]:
    """The q-point Gauss rule of the semicircle law in closed form (Gauss-Chebyshev of the
    second kind, Abramowitz & Stegun section 25.4, weights scaled by 2/pi)::

        xi_k = cos(k pi / (q + 1)),   w_k = 2 / (q + 1) sin^2(k pi / (q + 1)),   k = 1..q

    exact for polynomials of degree ``<= 2q - 1``; nodes ascending.

    >>> semicircle_gauss_rule(1)
    (array([0.]), array([1.]))
    """
    theta = np.arange(q, 0, -1) * np.pi / (q + 1)
    nodes = np.cos(theta)
    if q % 2:
        nodes[q // 2] = 0.0  # cos(pi/2), which numpy gives as 6e-17
    return nodes, 2.0 / (q + 1) * np.sin(theta) ** 2


def semicircle_golub_welsch_rule(q: int) -> tuple[np.ndarray, np.ndarray]:
    """The same rule as :func:`semicircle_gauss_rule` by another algorithm: scipy's
    Gauss-Jacobi rule ``roots_jacobi(q, 1/2, 1/2)`` (Golub-Welsch eigenvalues), weights
    scaled by 2/pi. Use it to check code that uses the closed form."""
    nodes, weights = roots_jacobi(q, 0.5, 0.5)
    return nodes, weights * (2.0 / np.pi)


@lru_cache(maxsize=None)
def _jacobi_table(rows: int) -> tuple[np.ndarray, np.ndarray]:
    nodes, weights = semicircle_golub_welsch_rule(200)
    return weights, np.array([eval_chebyu(i, nodes) for i in range(rows)])


def semicircle_cubic_projection(coef, n_out: int) -> np.ndarray:
    """``(E[x^3 U_i])_{i=0..n_out}`` for ``x = sum_j coef_j U_j(xi)``: the paper's ``X_i``
    (or ``Y_i`` for velocities), eqs. (10)-(13), with ``U_i`` the Chebyshev polynomials of
    the second kind (``scipy.special.eval_chebyu``), orthonormal under the semicircle law.

    By a 200-point :func:`semicircle_golub_welsch_rule`, exact while ``3 deg x + n_out <= 399``.
    """
    coef = np.asarray(coef, dtype=float)
    weights, u = _jacobi_table(max(64, len(coef), n_out + 1))
    values = (coef @ u[: len(coef)]) ** 3
    return u[: n_out + 1] @ (weights * values)
