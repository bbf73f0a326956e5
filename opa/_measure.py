"""The law of xi: orthonormal polynomials and Gauss rules for any measure, by recurrence.

A :class:`Measure` is a probability law of xi on a bounded support ``[lo, hi]``, restricted
to an interval ``[a, b]`` of it (the conditional law on an element of the multi-element
system). Its density is written ``(x - lo)^(alpha - 1) (hi - x)^(beta - 1) g(x)`` with
``g`` smooth; the end-point factors are what make plain Gauss-Legendre discretisations of
Beta-type laws converge slowly, so they are integrated exactly by Gauss-Jacobi rules.

From a fine discretisation (``M`` Gauss-Jacobi points on ``[a, b]``) the three-term
recurrence of the orthonormal polynomials,

    b_{k+1} p_{k+1}(x) = (x - a_k) p_k(x) - b_k p_{k-1}(x),    p_0 = 1,

comes from the Lanczos process with full reorthogonalisation (stable, and exact for every
degree below ``M``); the Gauss rule of any size follows by Golub-Welsch (the eigenvalues of
the Jacobi matrix and the squared first components of its eigenvectors). chaospy is used
only as a way to say what xi is: its own polynomials lose accuracy past order ~20.

Named laws (``parse``): ``semicircle`` (the paper's, Beta(3/2, 3/2) on [-1, 1]),
``uniform``, ``beta:A,B`` (Beta(A, B) on [-1, 1]) and ``normal-trunc:K`` (a standard
normal truncated at +-K standard deviations, scaled to [-1, 1]).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special, stats

from opa._basis import orthonormal

DISCRETISATION = 400  # points of the Gauss-Jacobi discretisation (exact below this degree)
# Lanczos costs O(m n^2) memory-time for n coefficients on m >= 2n points: 1000 nodes take
# a second and 32 MB; far more is better served by sampling.
MAX_GAUSS = 1000


@dataclass(frozen=True)
class Measure:
    """A probability law of xi on ``[lo, hi]``, restricted to ``[a, b]``."""

    name: str
    lo: float
    hi: float
    alpha: float = 1.0  # density ~ (x - lo)^(alpha - 1) near lo
    beta: float = 1.0  # density ~ (hi - x)^(beta - 1) near hi
    smooth: Callable | None = field(default=None, compare=False)  # g(x); None: 1
    cdf_full: Callable | None = field(default=None, compare=False)  # of the whole law
    ppf_full: Callable | None = field(default=None, compare=False)
    a: float | None = None
    b: float | None = None
    # recurrences computed so far, keyed by (a, b, n, m); shared by restrictions, which
    # is why the key holds the interval
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise ValueError(f"the support of xi must be a finite interval, got "
                             f"[{self.lo}, {self.hi}]")
        if not (self.alpha > 0 and self.beta > 0):
            raise ValueError(f"end-point exponents must be > 0, got {self.alpha}, {self.beta}")
        a = self.lo if self.a is None else float(self.a)
        b = self.hi if self.b is None else float(self.b)
        if not (self.lo <= a < b <= self.hi):
            raise ValueError(f"an element must lie inside [{self.lo}, {self.hi}] with a < b, "
                             f"got [{a}, {b}]")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    # -- the law ---------------------------------------------------------------------
    @property
    def is_whole(self) -> bool:
        return self.a == self.lo and self.b == self.hi

    def restrict(self, a: float, b: float) -> "Measure":
        """The conditional law on ``[a, b]`` (inside the current interval)."""
        if not (self.a <= a < b <= self.b):
            raise ValueError(f"[{a}, {b}] is not inside [{self.a}, {self.b}]")
        return replace(self, a=float(a), b=float(b))

    def cdf(self, x):
        """CDF of the whole (unrestricted) law."""
        return self.cdf_full(np.clip(np.asarray(x, float), self.lo, self.hi))

    def probability(self) -> float:
        """Probability of ``[a, b]`` under the whole law."""
        return float(self.cdf(self.b) - self.cdf(self.a))

    def ppf(self, u):
        """Quantiles of the restricted law (u in [0, 1])."""
        u = np.asarray(u, float)
        fa, fb = float(self.cdf(self.a)), float(self.cdf(self.b))
        return np.clip(self.ppf_full(fa + u * (fb - fa)), self.a, self.b)

    # -- discretisation, recurrence, Gauss rules ---------------------------------------
    def discretise(self, m: int = DISCRETISATION) -> tuple[np.ndarray, np.ndarray]:
        """``m`` points and weights (summing to 1) integrating the restricted law exactly
        for polynomials times the smooth factor up to degree ``2m - 1``."""
        a, b = self.a, self.b
        ea = self.alpha - 1.0 if a == self.lo else 0.0
        eb = self.beta - 1.0 if b == self.hi else 0.0
        t, w = _jacobi_rule(m, eb, ea)  # weight (1 - t)^eb (1 + t)^ea on [-1, 1]
        x = a + 0.5 * (b - a) * (t + 1.0)
        rest = np.ones_like(x)
        if a != self.lo:
            rest *= (x - self.lo) ** (self.alpha - 1.0)
        if b != self.hi:
            rest *= (self.hi - x) ** (self.beta - 1.0)
        if self.smooth is not None:
            rest *= self.smooth(x)
        w = w * rest
        return x, w / w.sum()

    def recurrence(self, n: int, m: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Recurrence coefficients ``a_0..a_{n-1}`` and ``b_1..b_{n-1}`` (``b`` padded with
        ``b_0 = 0`` in front) of the orthonormal polynomials, by Lanczos."""
        if int(n) != n or n < 1:
            raise ValueError(f"n must be a positive integer, got {n}")
        n = int(n)
        m = max(DISCRETISATION, 2 * n + 8) if m is None else m
        key = (self.a, self.b, n, m)
        if key not in self._cache:
            with np.errstate(all="ignore"):
                found = self._lanczos(n, m)
            if not (np.isfinite(found[0]).all() and np.isfinite(found[1]).all()):
                raise ValueError(f"distribution {self.name}: its orthonormal polynomials up to "
                                 f"degree {n - 1} are not finite in double precision; use a "
                                 f"lower order N or a milder law")
            self._cache[key] = found
        alpha, bcoef = self._cache[key]
        return alpha.copy(), bcoef.copy()

    def _lanczos(self, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
        if n > m:
            raise ValueError(f"n = {n} exceeds the discretisation m = {m}")
        x, w = self.discretise(m)
        if not (np.isfinite(x).all() and np.isfinite(w).all()):
            raise ValueError(f"distribution {self.name}: the discretisation of its density is "
                             f"not finite in double precision")
        Q = np.zeros((m, n))
        alpha = np.zeros(n)
        bcoef = np.zeros(n)
        q = np.sqrt(w)
        q_prev = np.zeros(m)
        for k in range(n):
            Q[:, k] = q
            r = x * q
            alpha[k] = q @ r
            r = r - alpha[k] * q - (bcoef[k] * q_prev if k else 0.0)
            # full reorthogonalisation, twice ("twice is enough")
            for _ in range(2):
                r -= Q[:, : k + 1] @ (Q[:, : k + 1].T @ r)
            if k + 1 < n:
                bcoef[k + 1] = np.linalg.norm(r)
                if bcoef[k + 1] == 0.0:
                    raise ValueError(f"the measure has fewer than {k + 2} support points")
                q_prev, q = q, r / bcoef[k + 1]
        return alpha, bcoef

    def gauss(self, q: int, coefficients=None) -> tuple[np.ndarray, np.ndarray]:
        """The ``q``-point Gauss rule of the restricted law (Golub-Welsch), ascending;
        ``coefficients``: a recurrence of at least ``q`` terms already computed."""
        if int(q) != q or not 1 <= q <= MAX_GAUSS:
            raise ValueError(f"a Gauss rule of the {self.name} law takes 1 to {MAX_GAUSS} "
                             f"nodes, got {q}")
        q = int(q)
        alpha, b = self.recurrence(q) if coefficients is None else coefficients
        alpha, b = alpha[:q], b[:q]
        if q == 1:
            return alpha.copy(), np.ones(1)
        try:
            vals, vecs = np.linalg.eigh(np.diag(alpha) + np.diag(b[1:], 1)
                                        + np.diag(b[1:], -1))
        except np.linalg.LinAlgError:
            raise ValueError(f"distribution {self.name}: its {q}-point Gauss rule cannot be "
                             f"computed (the eigenvalues of the Jacobi matrix did not "
                             f"converge); use a lower order N or a milder law") from None
        w = vecs[0] ** 2
        return vals, w / w.sum()

    def basis(self, n_max: int, x, coefficients=None) -> np.ndarray:
        """Orthonormal p_0..p_{n_max} at ``x``: shape ``(n_max + 1, *x.shape)``."""
        alpha, b = coefficients if coefficients is not None else self.recurrence(n_max + 1)
        return orthonormal(n_max, x, alpha, b)


@functools.lru_cache(maxsize=32)
def _jacobi_rule(m: int, eb: float, ea: float) -> tuple[np.ndarray, np.ndarray]:
    """scipy's Gauss-Jacobi rule, cached: elements share a handful of (m, exponents)."""
    t, w = special.roots_jacobi(m, eb, ea)
    t.flags.writeable = False
    w.flags.writeable = False
    return t, w


def semicircle() -> Measure:
    law = stats.beta(1.5, 1.5, loc=-1.0, scale=2.0)
    return Measure("semicircle", -1.0, 1.0, 1.5, 1.5, None, law.cdf, law.ppf)


def uniform() -> Measure:
    law = stats.uniform(loc=-1.0, scale=2.0)
    return Measure("uniform", -1.0, 1.0, 1.0, 1.0, None, law.cdf, law.ppf)


def beta(a: float, b: float) -> Measure:
    if not (a > 0 and b > 0 and math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"beta shape parameters must be positive numbers, got {a}, {b}")
    law = stats.beta(a, b, loc=-1.0, scale=2.0)
    return Measure(f"beta:{a:g},{b:g}", -1.0, 1.0, a, b, None, law.cdf, law.ppf)


def normal_trunc(k: float) -> Measure:
    if not (k > 0 and math.isfinite(k)):
        raise ValueError(f"normal-trunc needs a positive truncation K, got {k}")
    law = stats.truncnorm(-k, k, scale=1.0 / k)
    return Measure(f"normal-trunc:{k:g}", -1.0, 1.0, 1.0, 1.0,
                   lambda x: np.exp(-0.5 * (k * x) ** 2), law.cdf, law.ppf)


DISTRIBUTIONS = ("semicircle", "uniform", "beta:A,B", "normal-trunc:K")


def parse(spec) -> Measure:
    """A :class:`Measure` from a name (see the module doc), a chaospy distribution with
    bounded support, or a Measure."""
    if isinstance(spec, Measure):
        return spec
    if spec is None:
        return semicircle()
    if isinstance(spec, str):
        name, _, args = spec.partition(":")
        try:
            values = [float(v) for v in args.split(",")] if args else []
        except ValueError:
            raise ValueError(f"distribution {spec!r}: parameters must be numbers") from None
        if name == "semicircle" and not values:
            return semicircle()
        if name == "uniform" and not values:
            return uniform()
        if name == "beta" and len(values) == 2:
            return _usable(spec, beta, values)
        if name == "normal-trunc" and len(values) == 1:
            return _usable(spec, normal_trunc, values)
        raise ValueError(f"distribution must be one of {', '.join(DISTRIBUTIONS)}, got {spec!r}")
    return from_chaospy(spec)


def _works(make, values) -> bool:
    try:
        with np.errstate(all="ignore"):
            x, w = make(*values).discretise()
    except (ValueError, FloatingPointError, ArithmeticError):
        return False
    return bool(np.isfinite(x).all() and np.isfinite(w).all() and w.sum() > 0)


def _usable(spec: str, make, values) -> Measure:
    """``make(*values)`` if its discretisation is finite in double precision; otherwise a
    ValueError naming the parameters and the largest multiple of them that works."""
    law = make(*values)
    if _works(make, values):
        return law
    lo, hi = 0.0, 1.0  # scale the parameters down until the law can be discretised
    if not _works(make, [v * 1e-3 for v in values]):
        raise ValueError(f"distribution {spec!r}: its density cannot be discretised in double "
                         f"precision (parameters {', '.join(f'{v:g}' for v in values)})")
    lo = 1e-3
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _works(make, [v * mid for v in values]) else (lo, mid)
    name = spec.partition(":")[0]
    ok = ",".join(f"{math.floor(v * lo * 100) / 100:g}" for v in values)
    what = ("shape parameters A, B = " if name == "beta" else "truncation K = ") + \
        ", ".join(f"{v:g}" for v in values)
    raise ValueError(f"distribution {spec!r}: {what} too large for the discretisation of "
                     f"the density in double precision (its Gauss-Jacobi weights overflow or "
                     f"vanish); this law works up to {name}:{ok}")


def _cut_tail(pdf, cdf, lo: float, hi: float) -> bool:
    """Whether chaospy's support [lo, hi] is an unbounded law cut where its tails are
    negligible (at about 8 standard deviations): probability left beyond an end, more
    than roundoff (1e-12), or a roundoff's worth beside a density that has died out there
    (below 1e-10 of its largest value; a uniform law's cdf(lo) may be 1.7e-16 with its
    density at full height)."""
    x = np.linspace(lo, hi, 201)
    top = float(np.max(np.asarray(pdf(x), dtype=float)))
    inside = 1e-9 * (hi - lo)
    for left, edge in ((float(cdf(lo)), lo + inside), (1.0 - float(cdf(hi)), hi - inside)):
        if left > 1e-12 or (left > 0.0 and float(pdf(edge)) < 1e-10 * top):
            return True
    return False


def from_chaospy(dist) -> Measure:
    """A chaospy distribution of xi (bounded support). The end-point exponents of its
    density are measured numerically and factored out, so that Beta-type laws
    (Wigner, Beta) keep a spectrally accurate discretisation."""
    try:
        lower, upper = np.ravel(dist.lower), np.ravel(dist.upper)
        pdf, cdf, inv = dist.pdf, dist.cdf, dist.inv
    except AttributeError:
        raise ValueError(f"distribution must be a name or a chaospy distribution, got "
                         f"{dist!r:.80}") from None
    if len(lower) != 1 or len(upper) != 1:
        raise ValueError(f"distribution must be the law of one variable xi, got a joint law "
                         f"of {len(lower)} ({type(dist).__name__})")
    lo, hi = float(lower[0]), float(upper[0])
    if math.isfinite(lo) and math.isfinite(hi) and hi - lo <= 1e6:
        from scipy import integrate

        mass = integrate.quad(lambda x: float(np.ravel(pdf(x))[0]), lo, hi, limit=200)[0]
        if not abs(mass - 1.0) <= 1e-6:
            raise ValueError(
                f"distribution {type(dist).__name__}: its density integrates to {mass:.6g} "
                f"over its support [{lo:g}, {hi:g}], not 1, so its cdf and quantiles "
                f"disagree with it (chaospy 4.3's Trunc of a normal law does this); give a "
                f"law whose density "
                f"integrates to 1, e.g. 'normal-trunc:K' for a truncated normal")
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo > 1e6 \
            or _cut_tail(pdf, cdf, lo, hi):
        raise ValueError(f"the distribution of xi must have a bounded support, got "
                         f"[{lo}, {hi}] (use a truncated law such as 'normal-trunc:K')")
    width = hi - lo

    def exponent(end, sign):
        e1, e2 = 1e-7 * width, 2e-7 * width
        f1, f2 = float(pdf(end + sign * e1)), float(pdf(end + sign * e2))
        if f1 <= 0 or f2 <= 0:
            return 1.0
        return 1.0 + round(2 * math.log(f2 / f1) / math.log(2.0)) / 2  # to halves

    alpha, beta_ = exponent(lo, 1.0), exponent(hi, -1.0)

    def smooth(x):
        return pdf(x) / ((x - lo) ** (alpha - 1.0) * (hi - x) ** (beta_ - 1.0))

    return Measure(f"chaospy:{type(dist).__name__}", lo, hi, alpha, beta_, smooth,
                   lambda x: np.asarray(cdf(x), float), lambda u: np.asarray(inv(u), float))


__all__ = ["DISTRIBUTIONS", "Measure", "beta", "from_chaospy", "normal_trunc", "parse",
           "semicircle", "uniform"]
