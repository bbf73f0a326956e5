"""Multi-element OPA: one equivalent system per element of xi's support.

The support of xi is cut at edges ``e_0 < e_1 < ... < e_K``. On element k the response is
expanded in the orthonormal polynomials of the *conditional* law of xi on ``[e_k,
e_{k+1}]`` (:class:`opa._measure.Measure`), and that element's OPA system of order N runs
with its own mean constraint and its own impacts, integrated by the same kernel as the
single-element system (Wan & Karniadakis 2006; elements at discontinuities: Jakeman,
Narayan & Xiu 2013). With element probabilities ``P_k``, means ``m_k = x_0^(k)`` and
variances ``s_k = sum_{i>=1} (x_i^(k))^2`` the whole is assembled exactly:

    E[x] = sum_k P_k m_k,       Var[x] = sum_k P_k (s_k + m_k^2) - E[x]^2.

Where the edges go (:func:`adaptive_edges`): first at the splits of the sampled systems'
impact sequences (:func:`opa._splits.find_splits`: there x(t, xi) is not smooth in xi,
a kink or a square-root singularity at a grazing, and no element should straddle one),
keeping at most a quarter of the element budget (two elements at least) by merging the
neighbours of least joint probability (cascades of splits in tiny intervals); then the
element with the largest share of the variance, ``P_k max_t s_k(t)``, is halved in
probability until that share is below ``tolerance`` or the budget is spent.

The collocation twin (:func:`collocation`) puts the Q-point Gauss rule of each element's
law into the true sampled system: non-intrusive, every node its own impact sequence.
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass

import numpy as np

from opa._basis import quadrature_order
from opa._measure import MAX_GAUSS, Measure
from opa._model import check_count
from opa._model import SolverOptions
from opa._run import STATUS_NAMES, SimulationError, quadrature, run_batch, stack
from opa._system import System

#: the most elements, and the largest adaptive budget: an uncertain wall delta = 0.05 xi at
#: section 3.2, omega = 3.98, 10 periods (issue 43) needs 390 elements to reach an RMS
#: error of E[x] below 1e-4 (7.7e-5 against 2^19 Sobol samples; 1.1e-4 at 256), in 0.5 s
MAX_ELEMENTS = 1024
# Splits located before the edges are chosen (all of them in the cases measured: 192 at
# section 3.2, omega = 3.98, sigma = 0.05, 10 periods, in about a second).
SPLIT_BUDGET = 1024
# ... and at most this many per element of the budget (long horizons of a sensitive
# system have splits everywhere; finding them all would cost more than the elements).
SPLITS_PER_ELEMENT = 4
# The splits may take at most 1/SPLIT_SHARE of the element budget; refinement has the
# rest. Measured (opa-mc converge defaults, saltation law): with a quarter, 48 elements
# reach an RMS error of 1e-4 where a half needs 64.
SPLIT_SHARE = 4


class SplitCache:
    """The splits :func:`split_edges` located for the last ``size`` problems, oldest
    forgotten first: a study repeats them (every impact law and order of one system at one
    sigma shares them). Owned by whoever keeps it (a map, a study) and passed as
    ``splits=``; a call without one uses this module's shared one (:data:`SHARED_SPLITS`)."""

    def __init__(self, size: int = 8):
        self.size = check_count("size", size, 1)
        self._found: dict = {}

    def get(self, key, locate):
        """The splits of problem ``key``, located by ``locate()`` the first time."""
        if key not in self._found:
            if len(self._found) >= self.size:
                self._found.pop(next(iter(self._found)))
            self._found[key] = locate()
        return self._found[key]

    def clear(self) -> None:
        self._found.clear()

    def __len__(self) -> int:
        return len(self._found)


#: the splits of calls that bring no SplitCache of their own (simulate_opa's, the map's):
#: the one piece of process-wide state left here, until those callers keep their own
SHARED_SPLITS = SplitCache()


class ElementBudgetWarning(UserWarning):
    """Adaptive refinement stopped before every element's variance share fell below the
    tolerance (the element budget ran out)."""


@dataclass
class ElementRun:
    """The result of one element's OPA system."""

    a: float
    b: float
    probability: float
    x_coef: np.ndarray  # (N+1, T)
    v_coef: np.ndarray
    rhs_evaluations: int
    impacts: int
    failure: str = ""  # why the element's system stopped early ("" if it did not)
    method: str = "opa"  # or "collocation": its OPA system failed (see collocate_element)
    first_impact: float = np.inf  # of the element's mean (inf: none, or not logged)
    status: int = 0  # the kernel's status code (opa._run.STATUS_NAMES; 0: finished)

    @property
    def var(self) -> np.ndarray:
        return (self.x_coef[1:] ** 2).sum(axis=0)


def element_rule(measure: Measure, order: int):
    """Nodes, weights and orthonormal basis values (N+2, Q) for the element's system.

    The whole semicircle law uses the closed-form rule of the single-element system, so
    that one element reproduces today's OPA bit for bit; N = 0 is the one-point rule at
    the element's mean."""
    if measure.name == "semicircle" and measure.is_whole:
        return quadrature(order)
    q = 1 if order == 0 else quadrature_order(order)
    if q > MAX_GAUSS:
        raise ValueError(f"order N = {order} with elements or a law other than the whole "
                         f"semicircle needs a Gauss rule of 2N + 1 = {q} nodes, more than "
                         f"the {MAX_GAUSS} computed: use N <= {(MAX_GAUSS - 1) // 2}")
    coefficients = measure.recurrence(max(order + 2, q))
    nodes, weights = measure.gauss(q, coefficients)
    basis = measure.basis(order + 1, nodes, coefficients)
    return nodes, weights, np.ascontiguousarray(basis)


def run_elements(system: System, options: SolverOptions, measures: list[Measure], *,
                 times: np.ndarray, partial: bool = False,
                 events: bool = False) -> list[ElementRun]:
    """The OPA systems of several elements over ``times``, in parallel (compiled kernel).

    An element whose system cannot be completed raises :class:`SimulationError`, or with
    ``partial`` comes back with NaN after the failure and the reason in ``failure``.
    With ``events`` each element's first impact is logged."""
    own, order = system.replace(truncation="galerkin"), system.order
    inputs = stack([own.kernel_inputs(options, element_rule(m, order)) for m in measures])
    batch = run_batch(inputs, system.initial_state(), times, rtol=options.rtol,
                      atol=options.atol, capacity=max(64, 4 * len(times)) if events else 0)
    out = batch.states
    # a run the kernel calls complete but whose state is not finite (a jump that produced
    # NaN, which the kernel does not check yet) is a failure too
    reasons = [batch.message(e) if not batch.ok[e] else
               "" if np.isfinite(out[e]).all() else "the state became non-finite"
               for e in range(len(measures))]
    status = [int(batch.status[e]) if not batch.ok[e] else
              0 if not reasons[e] else STATUS_NAMES.index("diverged")
              for e in range(len(measures))]
    failures = [f"element [{m.a:.6g}, {m.b:.6g}] of the OPA (N={order}) system stopped: "
                f"{why}" if why else "" for m, why in zip(measures, reasons)]
    if not partial and any(failures):
        raise SimulationError(next(f for f in failures if f))
    for e, failure in enumerate(failures):
        if failure:
            out[e][~np.isfinite(out[e]).all(axis=1)] = np.nan
    return [ElementRun(m.a, m.b, m.probability(), out[e, :, : order + 1].T,
                       out[e, :, order + 1:].T, int(batch.rhs_evaluations[e]),
                       int(batch.impacts[e]), failures[e],
                       first_impact=batch.events(e).first_impact() if events else np.inf,
                       status=status[e])
            for e, m in enumerate(measures)]


def true_runs(system: System, options: SolverOptions, xi, times, *, what: str,
              impacts: bool = False):
    """The true sampled impact systems at the points ``xi`` of the uncertain variable:
    paths (M, T, 2) of x and x' and the right-hand sides used (with ``impacts``, also
    each system's number of impacts (M,)). A system that cannot be completed raises
    :class:`SimulationError` naming ``what`` and its xi."""
    xi = np.asarray(xi, dtype=float)
    batch = run_batch(system.sampled_inputs(options, xi=xi), system.deterministic()
                      .initial_state(), times, rtol=options.rtol, atol=options.atol,
                      stop_on_failure=True)
    if not batch.ok.all():
        m = int(np.flatnonzero(batch.failed)[0])
        point = (f"{xi[m]:.6g}" if np.ndim(xi[m]) == 0  # a row of xi: several parameters
                 else "(" + ", ".join(f"{v:.6g}" for v in xi[m]) + ")")
        raise SimulationError(f"{what} xi = {point} stopped: {batch.message(m)}")
    rhs = int(batch.rhs_evaluations.sum())
    return (batch.states, rhs, batch.impacts) if impacts else (batch.states, rhs)


def collocate_element(system: System, options: SolverOptions, measure: Measure, *,
                      times, failure: str = "") -> ElementRun:
    """The element's coefficients by collocation: the true sampled systems at the N+1
    Gauss nodes of the element's law, projected on its orthonormal basis
    (``x_j = sum_q w_q x(xi_q) phi_j(xi_q)``; the discrete rule keeps phi_0..phi_N
    orthonormal, so mean and variance are the rule's exactly).

    The fallback of an element whose OPA system cannot be completed (its mean grazes or
    the closure diverges): the true systems do not depend on the closure."""
    order = system.order
    nodes, weights = measure.gauss(order + 1)
    phi = measure.basis(order, nodes)  # (N+1, q)
    paths, rhs = true_runs(system, options, nodes, times,
                           what=f"collocation of element [{measure.a:.6g}, {measure.b:.6g}] at")
    coef = np.einsum("jq,qts->sjt", phi * weights, paths)  # (2, N+1, T)
    return ElementRun(float(measure.a), float(measure.b), measure.probability(), coef[0],
                      coef[1], rhs, 0, failure, "collocation")


def replace_failed(system, options, measure, runs: list[ElementRun], *,
                   times) -> list[ElementRun]:
    """Every failed element of ``runs`` computed again by :func:`collocate_element`."""
    return [collocate_element(system, options, measure.restrict(r.a, r.b), times=times,
                              failure=r.failure) if r.failure else r for r in runs]


def straddling(system: System, options: SolverOptions, edges, t_end: float) -> np.ndarray:
    """1 for each element whose two edge systems (the true sampled systems at its end
    points) differ in their event sequence up to ``t_end`` (the impacts, stick and release
    events and the impulse intervals they fall in, opa._splits), else 0.

    Such an element contains a split of the impact sequence: x(t, xi) is not smooth in xi
    there and the element's polynomial cannot follow it (a lower bound: two changes that
    undo each other between the edges are not seen)."""
    from opa._splits import event_sequences

    edges = np.asarray(edges, dtype=float)
    if system.sigma == 0.0:
        return np.zeros(len(edges) - 1, dtype=np.int8)
    centre = system.oscillator.value(system.uncertain)
    sequences = event_sequences(system, options, system.uncertain,
                                centre + system.sigma * edges, t_end)
    return np.array([0 if a.signature(t_end) == b.signature(t_end) else 1
                     for a, b in zip(sequences[:-1], sequences[1:])], dtype=np.int8)


def run_element(system, options, measure, **kw) -> ElementRun:
    """One element's OPA system (see :func:`run_elements`)."""
    return run_elements(system, options, [measure], **kw)[0]


def assemble(runs: list[ElementRun]) -> dict[str, np.ndarray]:
    """Mean and variance of x and x' of the whole from the elements' (exact)."""
    P = np.array([r.probability for r in runs])
    P = P / P.sum()  # the edges cover the support; this removes the cdf's round-off
    out = {}
    for name, attr in (("x", "x_coef"), ("v", "v_coef")):
        m = np.stack([getattr(r, attr)[0] for r in runs])
        s = np.stack([(getattr(r, attr)[1:] ** 2).sum(axis=0) for r in runs])
        mean = P @ m
        out[f"{name}_mean"] = mean
        out[f"{name}_var"] = np.maximum(P @ (s + (m - mean) ** 2), 0.0)
    return out


def global_coefficients(x_coefs, edges, probability, measure: Measure,
                        order: int) -> np.ndarray:
    """The coefficients ``E[x_hat phi_i(xi)]``, i = 0..order, of the piecewise surrogate
    ``x_hat(t, xi) = sum_j x_j^(k)(t) phi_j^(k)(xi)`` on element k, in the orthonormal
    basis ``phi_i`` of the whole law: what a Monte Carlo ensemble estimates as ``x_coef``.

    Exact (Gauss rule of each element's law with enough points for the product of the
    two polynomials). ``x_coefs`` (K, N+1, T); ``edges`` (K+1,); returns (order+1, T).

    Examples
    --------
    One element over the whole support gives its own coefficients back:

    >>> from opa._measure import uniform
    >>> c = np.array([[[1.0], [0.5], [0.25]]])
    >>> np.round(global_coefficients(c, [-1, 1], [1.0], uniform(), 2).ravel(), 12)
    array([1.  , 0.5 , 0.25])
    """
    x_coefs = np.asarray(x_coefs, dtype=float)
    N = x_coefs.shape[1] - 1
    q = (N + order) // 2 + 1  # 2q - 1 >= N + order: the products are integrated exactly
    whole = measure.recurrence(order + 1)
    out = np.zeros((order + 1, x_coefs.shape[2]))
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        element = measure.restrict(float(a), float(b))
        nodes, weights = element.gauss(q)
        own = element.basis(N, nodes)  # (N+1, q)
        phi = measure.basis(order, nodes, whole)  # (order+1, q)
        values = own.T @ x_coefs[k]  # x_hat at the nodes, (q, T)
        out += probability[k] * (phi * weights) @ values
    return out


def uniform_edges(measure: Measure, count: int) -> np.ndarray:
    """``count`` elements of equal probability."""
    try:
        count = check_count("elements", count, 1)
    except ValueError:
        raise ValueError(f"elements must be a positive integer, 'adaptive' or a list of "
                         f"edges, got {count!r}") from None
    if count > MAX_ELEMENTS:
        raise ValueError(f"elements must be at most {MAX_ELEMENTS}, got {count}")
    edges = measure.ppf(np.linspace(0.0, 1.0, int(count) + 1))
    edges[0], edges[-1] = measure.lo, measure.hi
    return np.maximum.accumulate(edges)


def split_edges(system, options, measure, *, t_end, max_splits=64, tol=1e-6,
                splits: SplitCache | None = None) -> tuple[np.ndarray, list]:
    """Edges at the splits of the sampled systems' impact sequences up to ``t_end`` (xi
    located to ``tol``); returns the edges and the splits. ``splits``: where splits
    located before are kept (default :data:`SHARED_SPLITS`)."""
    from opa._splits import find_splits

    sigma, uncertain = system.sigma, system.uncertain
    centre = system.oscillator.value(uncertain)
    if sigma == 0.0:
        return np.array([measure.lo, measure.hi]), []
    key = (system.deterministic(), options, uncertain, sigma, measure.name, measure.lo,
           measure.hi, t_end, max_splits, tol)
    found = (SHARED_SPLITS if splits is None else splits).get(key, lambda: find_splits(
        system, options, uncertain, centre + sigma * measure.lo, centre + sigma * measure.hi,
        t_end, tol=tol * sigma, max_splits=max_splits, center=centre, order="generation")[0])
    cuts = sorted({(s.value - centre) / sigma for s in found if s.kind != "horizon"})
    cuts = [c for c in cuts if measure.lo < c < measure.hi]
    return np.array([measure.lo, *cuts, measure.hi]), found


def merge_smallest(measure: Measure, edges, count: int) -> np.ndarray:
    """Remove cuts until at most ``count`` elements remain, each time the cut between
    the two neighbouring elements of least joint probability (a cascade of splits packed
    into a tiny interval becomes one element, which refinement may cut again)."""
    edges = list(edges)
    P = list(np.diff(measure.cdf(np.array(edges))))
    while len(P) > count:
        joint = [P[i] + P[i + 1] for i in range(len(P) - 1)]
        i = int(np.argmin(joint))
        P[i: i + 2] = [joint[i]]
        del edges[i + 1]
    return np.array(edges)


def adaptive_edges(system, options, measure, *, times, tolerance, max_elements, log=None,
                   splits: SplitCache | None = None):
    """Edges at the splits (kept in ``splits``: :func:`split_edges`), then halving of the
    element with the largest variance share ``P_k max_t s_k(t)`` until it is below
    ``tolerance`` or ``max_elements`` is reached.

    Returns (runs, history) where history lists, per step, (elements, largest share, RMS
    change of the assembled mean E[x] from the step before: NaN at the first step, which
    has none; the change is the error estimate of the step before it)."""
    if not (isinstance(max_elements, numbers.Integral) and not isinstance(max_elements, bool)
            and type(max_elements).__name__ not in ("bool_", "bool")
            and 2 <= max_elements <= MAX_ELEMENTS):
        raise ValueError(f"max_elements must be an integer in 2..{MAX_ELEMENTS} (a budget of "
                         f"one element cannot refine: give elements=1 instead), got "
                         f"{max_elements!r}")
    if isinstance(tolerance, (bool, str, bytes)) or not (
            isinstance(tolerance, numbers.Real) and tolerance > 0 and math.isfinite(tolerance)):
        raise ValueError(f"tolerance must be a positive number, got {tolerance!r}")
    edges, _ = split_edges(system, options, measure, t_end=float(times[-1]),
                           max_splits=min(SPLIT_BUDGET, SPLITS_PER_ELEMENT * max_elements),
                           splits=splits)
    # at least one cut at a split when there is one and the budget allows two elements:
    # an element straddling a grazing split is where the saltation law fails (section 3.2,
    # omega = 3.98, sigma = 0.03, uniform law: 4 elements cut in probability alone are 4x
    # worse than one element, docs/elements.md)
    edges = merge_smallest(measure, edges, max(min(2, max_elements), max_elements // SPLIT_SHARE))
    def run(pairs):
        return run_elements(system, options, [measure.restrict(a, b) for a, b in pairs],
                            times=times, partial=True)

    runs = run(list(zip(edges[:-1], edges[1:])))
    history = []
    previous = None
    while True:
        # an element whose system diverged has an infinite share: it is halved first
        share = np.array([np.inf if r.failure else r.probability * float(r.var.max())
                          for r in runs])
        mean = None if any(r.failure for r in runs) else assemble(runs)["x_mean"]
        change = (math.nan if mean is None or previous is None
                  else float(np.sqrt(np.mean((mean - previous) ** 2))))
        previous = mean
        history.append((len(runs), float(share.max()), change))
        room = max_elements - len(runs)
        if share.max() < tolerance or room <= 0:
            break
        # one round: halve (in probability) every element within a factor 4 of the
        # largest finite share and above the tolerance, the largest first, within the
        # budget (diverged elements first of all)
        finite = share[np.isfinite(share)]
        top = finite.max() if len(finite) else 0.0
        pick = [k for k in np.argsort(-share)
                if share[k] >= max(tolerance, 0.25 * top)][:room]
        halves = {}
        for k in pick:
            r = runs[k]
            mid = float(measure.restrict(r.a, r.b).ppf(0.5))
            if r.a < mid < r.b:
                halves[k] = [(r.a, mid), (mid, r.b)]
        if not halves:
            break
        new = iter(run([pair for k in sorted(halves) for pair in halves[k]]))
        replaced = []
        for k, r in enumerate(runs):
            replaced += [next(new), next(new)] if k in halves else [r]
        runs = replaced
        if log is not None:
            log(f"  halved {len(halves)} elements (largest variance share "
                f"{share.max():.2e}); {len(runs)} elements")
    # what refinement could not mend is computed by collocation of the true systems
    return replace_failed(system, options, measure, runs, times=times), history


def collocation(system, options, measure, edges, q, *, times):
    """Multi-element Gauss collocation: the q-point rule of each element's law, each node
    a true impact system. Returns (x_mean, x_var, rhs evaluations)."""
    xs, ws = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        element = measure.restrict(a, b)
        nodes, weights = element.gauss(q)
        xs.append(nodes)
        ws.append(weights * element.probability())
    xi = np.concatenate(xs)
    w = np.concatenate(ws)
    w = w / w.sum()
    paths, n_rhs = true_runs(system, options, xi, times, what="collocation node")
    x = paths[:, :, 0]
    mean = w @ x
    return mean, np.maximum(w @ (x - mean) ** 2, 0.0), n_rhs


def simulate_elements(system, *, options, times, elements, tolerance, max_elements, log=None,
                      splits: SplitCache | None = None):
    """The multi-element OPA dataset (see :func:`opa.simulate_opa`; ``splits``: as for
    :func:`split_edges`)."""
    import xarray as xr

    from opa._dataset import element_layout, provenance_attrs, time_coord

    oscillator, order, measure = system.oscillator, system.order, system.measure
    if system.truncation != "galerkin":
        raise ValueError("truncation='paper' is eq. (27) of the semicircle basis on the whole "
                         "support; with elements or another distribution use 'galerkin'")
    history = []
    if isinstance(elements, str):
        if elements != "adaptive":
            raise ValueError(f"elements must be a positive integer, 'adaptive' or a list of "
                             f"edges, got {elements!r}")
        runs, history = adaptive_edges(system, options, measure, times=times,
                                       tolerance=tolerance, max_elements=max_elements, log=log,
                                       splits=splits)
    else:
        if np.ndim(elements) == 0:
            edges = uniform_edges(measure, elements)
        else:
            edges = np.asarray(elements, dtype=float)
            if (edges.ndim != 1 or len(edges) < 2 or not np.all(np.diff(edges) > 0)
                    or edges[0] != measure.lo or edges[-1] != measure.hi):
                raise ValueError(f"element edges must increase from {measure.lo} to "
                                 f"{measure.hi}, got {elements!r}")
        runs = replace_failed(system, options, measure, run_elements(
            system, options, [measure.restrict(a, b) for a, b in zip(edges[:-1], edges[1:])],
            times=times, partial=True), times=times)
    stats = assemble(runs)
    one = {"units": "1"}
    edges = np.array([r.a for r in runs] + [runs[-1].b])
    x_coefs = np.stack([r.x_coef for r in runs])
    v_coefs = np.stack([r.v_coef for r in runs])
    layout, layout_coords = element_layout(
        x_coefs, v_coefs, edges, [r.probability for r in runs], [r.impacts for r in runs],
        [r.rhs_evaluations for r in runs])
    data = {
        "x_mean": ("time", stats["x_mean"], {"long_name": "E[x] assembled from the "
                                             "elements", **one}),
        "x_var": ("time", stats["x_var"], {"long_name": "Var[x] assembled from the "
                                           "elements", **one}),
        "v_mean": ("time", stats["v_mean"], {"long_name": "E[x'] assembled", **one}),
        "v_var": ("time", stats["v_var"], {"long_name": "Var[x'] assembled", **one}),
        **layout,
    }
    if len(runs) == 1:  # one element over the whole support: the coefficients of the law
        data["x_coef"] = (("order", "time"), x_coefs[0],
                          {"long_name": f"OPA coefficient x_i = E[x phi_i(xi)], phi_i "
                           f"orthonormal under the {measure.name} law", **one})
        data["v_coef"] = (("order", "time"), v_coefs[0],
                          {"long_name": "OPA coefficient v_i = E[x' phi_i(xi)]", **one})
    ds = xr.Dataset(
        data,
        coords={**time_coord(times, oscillator.omega), "order": ("order", np.arange(order + 1)),
                **layout_coords},
        attrs=provenance_attrs("opa", system, options),
    )
    straddle = straddling(system, options, edges, float(times[-1]))
    ds["element_straddles"] = ("element", straddle, {
        "long_name": "1 where the element's edge systems differ in their impact sequence "
        "over the run (a split inside: its polynomial cannot follow it)", "units": "1"})
    P = np.array([r.probability for r in runs])
    ds.attrs.update(straddling_elements=int(straddle.sum()),
                    straddling_probability=float(P[straddle == 1].sum() / P.sum()))
    method = np.array([r.method == "collocation" for r in runs], dtype=np.int8)
    ds["element_method"] = ("element", method, {
        "long_name": "how each element was computed", "units": "1",
        "flag_values": np.array([0, 1], dtype=np.int8),
        "flag_meanings": "opa collocation_after_opa_failed"})
    ds.attrs.update(
        collocation_elements=int(method.sum()),
        distribution=measure.name, elements=len(runs),
        element_mode=("adaptive" if isinstance(elements, str) else
                      "uniform" if np.ndim(elements) == 0 else "edges"),
        rhs_evaluations=int(sum(r.rhs_evaluations for r in runs)),
    )
    if history:
        ds["refinement_elements"] = ("refinement", np.array([h[0] for h in history]),
                                     {"long_name": "elements after each refinement step",
                                      **one})
        ds["refinement_share"] = ("refinement", np.array([h[1] for h in history]),
                                  {"long_name": "largest element variance share (inf: an "
                                   "element's OPA system failed; NaN: an element's "
                                   "variance is not finite)", **one})
        ds["refinement_mean_change"] = (
            "refinement", np.array([h[2] for h in history]),
            {"long_name": "RMS change of the assembled E[x] from the step before "
             "(NaN: none before, or an element failed)", **one})
        ds.coords["refinement"] = ("refinement", np.arange(len(history)),
                                   {"long_name": "refinement step", **one})
        met = history[-1][1] < tolerance
        ds.attrs.update(
            tolerance=float(tolerance), max_elements=int(max_elements),
            tolerance_met=int(met),
            stopped_by=("tolerance" if met else "element budget"
                        if len(runs) >= max_elements else "no element could be halved"),
            error_estimate=float(history[-1][2]) if len(history) > 1 else math.nan)
        if not met:
            warnings.warn(
                f"adaptive elements stopped by the {ds.attrs['stopped_by']} at {len(runs)} "
                f"elements with the largest variance share {history[-1][1]:.3g} above the "
                f"tolerance {tolerance:g}: raise max_elements (now {max_elements}) or the "
                f"tolerance", ElementBudgetWarning, stacklevel=3)
    return ds


__all__ = ["ElementBudgetWarning", "ElementRun", "SHARED_SPLITS", "SplitCache",
           "adaptive_edges", "assemble", "collocation", "collocate_element", "element_rule",
           "global_coefficients", "merge_smallest", "replace_failed", "run_element",
           "run_elements", "simulate_elements", "split_edges", "straddling", "true_runs",
           "uniform_edges"]
