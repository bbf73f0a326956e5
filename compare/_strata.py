"""The strata of a certificate: the law of xi cut at the elements' edges and at the changes
of the impact sequence.

A certificate estimates E[x - x_hat] by stratified sampling. Any partition of the law
gives an unbiased estimate; the partition decides whether the *standard error* can be
trusted. Where the impact sequence changes inside a stratum, x(t, xi) jumps there and the
few points of the stratum may all fall on one side: its sample variance then says nothing
about the jump (a rare region of 2 % of the law is missed by 16 Sobol' replicates in
most seeds). So the strata are cut at the splits that :func:`opa._splits.scan_splits`
locates (to ``SPLIT_TOL`` in xi) within the support, and every stratum gets points of its
own.

Splits come in cascades (a chatter burst is hundreds of splits within 1e-4 in xi). A
cascade is one *zone*: splits closer than the merge gap form one stratum of their own,
bounded by the cascade's outermost splits, so the smooth stretches between cascades stay
whole. When the zones would be more than the points allow (``max_strata``), the merge gap
doubles until they fit. Any partition keeps the estimate unbiased; the zones only keep
the rough parts of x(t, xi) out of the smooth strata.

The ``horizon`` splits (an event sliding across the end of the run) are not cuts: x(t, xi)
stays continuous there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the resolution of the splits the strata are cut at, in xi
SPLIT_TOL = 1e-6
#: splits closer than this (in xi, relative to the support's width) form one zone
MERGE_GAP = 1e-3
#: split kinds that are not discontinuities of x(t, xi) for t inside the run
CONTINUOUS_KINDS = ("horizon", "output crossing")


@dataclass(frozen=True)
class Strata:
    """A partition of the law's support ``[cuts[0], cuts[-1]]``.

    ``cuts`` (S + 1,): increasing; ``element`` (S,): the OPA element each stratum lies in;
    ``probability`` (S,): each stratum's probability under the whole law (summing to 1);
    ``splits``: the discontinuities located in the support; ``zones``: the strata that hold
    a cascade of them; ``complete``: whether the split scan saw every change of the
    sequence in the support (False: it hit its limit, and some splits may sit inside a
    smooth stratum; said in the certificate).
    """

    cuts: np.ndarray
    element: np.ndarray
    probability: np.ndarray
    splits: int
    zones: int
    complete: bool

    def __len__(self) -> int:
        return len(self.element)

    def describe(self) -> str:
        """One phrase for the dataset and the log."""
        if not self.splits:
            where = "no change of the impact sequence in the support"
        else:
            where = (f"{self.splits} change{'s' if self.splits > 1 else ''} of the impact "
                     f"sequence located to {SPLIT_TOL:g} in xi, cut into {self.zones} "
                     f"zone{'s' if self.zones > 1 else ''}")
            if not self.complete:
                where += " (the split scan hit its limit: more may hide inside strata)"
        return f"{len(self)} strata ({where})"


def split_values(system, options, measure, horizon: float) -> tuple[np.ndarray, bool]:
    """The values of xi in the law's support where the impact sequence up to ``horizon``
    changes (discontinuities of x(t, xi) only), increasing, and whether the scan was
    complete."""
    from opa.engine import ScanOptions, scan_splits

    sigma = float(system.sigma)
    if sigma == 0.0:
        return np.empty(0), True
    name = system.uncertain
    centre = system.oscillator.value(name)
    lo, hi = centre + sigma * measure.a, centre + sigma * measure.b
    tol = max(SPLIT_TOL * sigma, 8.0 * np.finfo(float).eps * max(abs(lo), abs(hi)))
    found = scan_splits(system, options, name, lo, hi, horizon,
                        ScanOptions(tol=tol, center=centre))
    xi = np.array(sorted((s.value - centre) / sigma for s in found.splits
                         if s.kind not in CONTINUOUS_KINDS))
    xi = xi[(xi > measure.a) & (xi < measure.b)]
    return xi, not found.truncated


def zones(values: np.ndarray, gap: float) -> list[tuple[float, float]]:
    """Sorted split values grouped into zones: neighbours closer than ``gap`` share one.

    >>> zones(np.array([-0.5, 0.1, 0.1001, 0.1002, 0.7]), 1e-3)
    [(-0.5, -0.5), (0.1, 0.1002), (0.7, 0.7)]
    """
    out: list[tuple[float, float]] = []
    for v in np.asarray(values, dtype=float):
        if out and v - out[-1][1] < gap:
            out[-1] = (out[-1][0], float(v))
        else:
            out.append((float(v), float(v)))
    return out


def build_strata(measure, edges, split_xi, *, max_strata: int,
                 complete: bool = True) -> Strata:
    """The strata: the elements (``edges``) cut at the zones of ``split_xi``.

    A zone of one split is a cut at it; a zone of several is a stratum of its own from
    its first to its last split. The merge gap starts at ``MERGE_GAP`` times the support's
    width and doubles until the strata are at most ``max_strata`` (never fewer than the
    elements).

    >>> from opa._measure import uniform
    >>> s = build_strata(uniform(), [-1.0, 1.0], np.array([0.0]), max_strata=8)
    >>> s.cuts.tolist(), s.probability.tolist()
    ([-1.0, 0.0, 1.0], [0.5, 0.5])
    """
    edges = np.asarray(edges, dtype=float)
    split_xi = np.asarray(split_xi, dtype=float)
    width = float(edges[-1] - edges[0])
    gap = MERGE_GAP * width
    while True:
        found = zones(split_xi, gap)
        points = sorted({float(e) for e in edges}
                        | {v for zone in found for v in zone})
        # cuts closer than a few ulps (a split on an element's edge) are one cut
        cuts = [points[0]]
        for p in points[1:]:
            if p - cuts[-1] > 1e-12 * max(1.0, abs(p)):
                cuts.append(p)
        cuts[-1] = float(edges[-1])
        if len(cuts) - 1 <= max(max_strata, len(edges) - 1) or gap > width:
            break
        gap *= 2.0
    cuts = np.asarray(cuts)
    mids = 0.5 * (cuts[:-1] + cuts[1:])
    element = np.clip(np.searchsorted(edges, mids, side="right") - 1, 0, len(edges) - 2)
    cdf = np.asarray(measure.cdf(cuts), dtype=float)
    probability = np.diff(cdf)
    probability = probability / probability.sum()
    return Strata(cuts, element, probability, int(len(split_xi)), len(found),
                  bool(complete))


def replicate_allocation(per_replicate: int, probability) -> np.ndarray:
    """Points per stratum in each replicate of ``per_replicate`` points: one each, the rest
    in proportion to the strata's probabilities (largest remainders).

    >>> replicate_allocation(8, [0.02, 0.98]).tolist()
    [1, 7]
    """
    probability = np.asarray(probability, float)
    rest = int(per_replicate) - len(probability)
    if rest < 0:
        raise ValueError(f"{len(probability)} strata need at least one point each, got "
                         f"{per_replicate} per replicate")
    return 1 + neyman_allocation(rest, probability, np.ones(len(probability)))


def replicate_points(measure, strata: Strata, allocation, replicates: int, seed: int,
                     scale: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stratified randomised QMC in independent replicates: in replicate r, stratum j gets
    ``scale * allocation[j]`` points, the first points of coordinate r of a scrambled
    Sobol' sequence of ``replicates`` dimensions (one per stratum, seeded by ``(seed,
    j)``; each coordinate scrambled on its own, so the replicates are independent),
    mapped through the law conditioned on the stratum, each weighing
    ``P_j / (scale * allocation[j])``. Returns xi, the weights (each replicate's sum to 1)
    and the replicate of each point, rows ordered by replicate, then stratum. The points
    at ``2 scale`` hold those at ``scale`` (each sequence goes on), so every replicate is
    an unbiased estimate, independent of the others, and a doubling adds points only
    (:func:`grown_rows`)."""
    import warnings

    from scipy.stats import qmc

    counts = np.asarray(allocation, int) * int(scale)
    per_stratum = []
    for j, n in enumerate(counts):
        stream = qmc.Sobol(replicates, scramble=True,
                           seed=np.random.default_rng(np.random.SeedSequence([seed, j])))
        with warnings.catch_warnings():  # n need not be a power of two
            warnings.simplefilter("ignore", UserWarning)
            u = stream.random(int(n))  # (n, replicates)
        xi = measure.restrict(float(strata.cuts[j]), float(strata.cuts[j + 1])).ppf(u.T)
        per_stratum.append(np.asarray(xi, float).reshape(replicates, int(n)))
    xi = np.concatenate(per_stratum, axis=1).ravel()  # replicate-major, then stratum
    weight = np.tile(np.concatenate([np.full(int(n), p / n)
                                     for p, n in zip(strata.probability, counts)]), replicates)
    which = np.repeat(np.arange(replicates), int(counts.sum()))
    return xi, weight, which


def grown_rows(allocation, replicates: int, scale: int) -> np.ndarray:
    """Where the rows of :func:`replicate_points` at ``scale`` sit among those at ``2
    scale`` (each stratum's first ``scale * allocation[j]`` points are the same).

    >>> grown_rows([1, 2], 2, 1).tolist()
    [0, 2, 3, 6, 8, 9]
    """
    rows, base = [], 0
    for _ in range(replicates):
        for n in np.asarray(allocation, int) * int(scale):
            rows.extend(range(base, base + int(n)))
            base += 2 * int(n)
    return np.asarray(rows, dtype=np.int64)


def neyman_allocation(total: int, probability, spread) -> np.ndarray:
    """Points per stratum for ``total`` more points: proportional to P_k s_k (Neyman),
    rounded so that they sum to ``total``; where every s_k is 0, proportional to P_k.

    >>> neyman_allocation(10, [0.5, 0.5], [1.0, 3.0]).tolist()
    [3, 7]
    """
    weight = np.asarray(probability, float) * np.asarray(spread, float)
    if not weight.sum() > 0:
        weight = np.asarray(probability, float)
    share = total * weight / weight.sum()
    n = np.floor(share).astype(int)
    n[np.argsort(n - share)[: total - int(n.sum())]] += 1  # largest remainders
    return n


def group_allocation(groups: int, probability, indicator, least: int = 1) -> np.ndarray:
    """Jittered groups per stratum for ``groups`` in all: ``least`` each, then half the rest in
    proportion to P_k times the indicator (Neyman with the indicator for the spread) and
    half in proportion to P_k (defensive, for what the ends do not show).

    >>> group_allocation(10, [0.5, 0.25, 0.25], [0.0, 1.0, 3.0]).tolist()
    [3, 3, 4]
    """
    K = len(probability)
    if groups < least * K:
        raise ValueError(f"{groups} groups cannot give each of {K} strata {least}")
    rest = groups - least * K
    return least + neyman_allocation(rest // 2, probability, indicator) \
        + neyman_allocation(rest - rest // 2, probability, np.ones(K))


def slices(measure, a: float, b: float, n: int, grid: int = 4097
           ) -> tuple[np.ndarray, np.ndarray]:
    """Stratum [a, b] cut into ``n`` slices: the ``n + 1`` bounds and each slice's
    probability under the whole law.

    The bounds split [a, b] into equal parts of the mixture of the law (restricted to the
    stratum) and the uniform law on it, half each. Equal probability alone stretches a
    slice over a long stretch of xi where the density is thin (the tail of a beta(2, 5)
    law: the last of 128 slices of [-0.22, 1] spans 0.4 in xi), and a surrogate's misfit
    that grows along it leaves the slice's few points a skewed sample whose variance is
    mostly too small; with the mixture no slice is longer than 2 / n of the stratum, nor
    holds more than 2 / n of its probability. Points are still drawn from the law within
    each slice and weighted by its probability, so the estimate stays unbiased.

    >>> from opa._measure import uniform
    >>> bounds, p = slices(uniform(), -1.0, 1.0, 4)
    >>> bounds.round(6).tolist(), p.round(6).tolist()
    ([-1.0, -0.5, 0.0, 0.5, 1.0], [0.25, 0.25, 0.25, 0.25])
    """
    x = np.linspace(a, b, grid)
    F = np.asarray(measure.cdf(x), dtype=float)
    law = (F - F[0]) / (F[-1] - F[0]) if F[-1] > F[0] else (x - a) / (b - a)
    mixture = 0.5 * law + 0.5 * (x - a) / (b - a)
    bounds = np.interp(np.arange(n + 1) / n, mixture, x)
    bounds[0], bounds[-1] = a, b
    return bounds, np.diff(np.asarray(measure.cdf(bounds), dtype=float))


def least_samples(strata: int, group: int) -> int:
    """The smallest power of two that holds the true systems at the ``strata + 1`` cuts
    and one group of ``group`` points in every stratum.

    >>> least_samples(64, 4)
    512
    """
    need = strata + 1 + group * strata
    return 1 << max(0, math.ceil(math.log2(need)))


__all__ = ["CONTINUOUS_KINDS", "MERGE_GAP", "SPLIT_TOL", "Strata", "build_strata",
           "group_allocation", "least_samples", "neyman_allocation", "slices",
           "split_values",
           "zones"]
