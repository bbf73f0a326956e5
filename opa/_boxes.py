r"""Multi-element OPA with several uncertain parameters: the elements are boxes.

The support of :math:`\xi` (a box, the product of the marginals' intervals) is cut into
boxes :math:`B_e`; on each the conditional law is the product of the marginals restricted
to the box's sides, and the Galerkin system of order N (:mod:`opa._galerkin`) is solved
in that law's own orthonormal basis. The moments follow from the law of total variance,

.. math::

    E[x] = \sum_e P_e m_e, \qquad
    Var[x] = \sum_e P_e (v_e + m_e^2) - E[x]^2,

with :math:`P_e` the box's probability, :math:`m_e = x_{0,e}` and
:math:`v_e = \sum_{\alpha \ne 0} x_{\alpha,e}^2`.

Boxes come from ``elements=K`` (K equal-probability intervals along each parameter: K^d
boxes) or ``elements="adaptive"``, in the style of ME-gPC (Wan & Karniadakis 2006): the
boxes with the largest share of the variance, :math:`\eta_e = P_e \max_t v_e(t)` (the
criterion of the one-parameter elements, :mod:`opa._elements`), are halved at their
conditional median along the parameter whose terms carry most of the box's variance,
until every share is below ``tolerance`` or ``max_elements`` is reached (an
``ElementBudgetWarning`` says so). As in one dimension, ``error_estimate`` is the RMS
change of E[x] over time in the last refinement step (NaN: none was made) and
``largest_share`` the largest share left. A box whose corners give the true sampled systems
different numbers of impacts holds a change of the impact sequence, where the expansion
is not smooth: those boxes are flagged (``element_split_inside``) and, at equal share,
halved first. (In one dimension the elements' edges are put on the splits themselves;
in several the split is a curve that boxes can only approach.)

The Sobol indices of a multi-element run come from the piecewise expansion by exact
quadrature: the boxes' edges along each parameter cut the support into a tensor grid
of cells, each inside one box, and a Gauss rule of N + 1 points per side of each cell
integrates the conditional moments of the piecewise polynomial exactly.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass

import numpy as np
import xarray as xr

from opa._chaos import ChaosBasis
from opa._dataset import provenance_attrs, time_coord
from opa._elements import ElementBudgetWarning, true_runs
from opa._galerkin import chaos_basis, chaos_rule, initial_coefficients
from opa._model import SolverOptions
from opa._run import SimulationError, run_batch, stack
from opa._system import System

#: most boxes an adaptive run may make (and K^d may reach)
MAX_BOXES = 4096


@dataclass(frozen=True)
class Box:
    """One element: the sides ``lower[j] <= xi_j <= upper[j]``."""

    lower: tuple
    upper: tuple

    def measures(self, whole) -> tuple:
        """The marginals restricted to the box's sides (the whole law where a side is
        the whole support)."""
        return tuple(m if (lo, hi) == (m.lo, m.hi) else m.restrict(lo, hi)
                     for m, lo, hi in zip(whole, self.lower, self.upper))

    def probability(self, whole) -> float:
        return float(np.prod([float(m.cdf(hi) - m.cdf(lo))
                              for m, lo, hi in zip(whole, self.lower, self.upper)]))

    def halves(self, j: int, whole) -> tuple[Box, Box]:
        """The box cut along parameter j at its conditional median."""
        m = whole[j]
        lo, hi = self.lower[j], self.upper[j]
        if (lo, hi) != (m.lo, m.hi):
            m = m.restrict(lo, hi)
        cut = float(m.ppf(0.5))
        left = Box(self.lower, self.upper[:j] + (cut,) + self.upper[j + 1:])
        right = Box(self.lower[:j] + (cut,) + self.lower[j + 1:], self.upper)
        return left, right

    def corners(self) -> np.ndarray:
        """The 2^d corners, shape (2^d, d)."""
        return np.array(list(itertools.product(*zip(self.lower, self.upper))), dtype=float)


def uniform_boxes(whole, count: int) -> list[Box]:
    """``count`` equal-probability intervals along each parameter: count^d boxes."""
    edges = [np.asarray(m.ppf(np.linspace(0.0, 1.0, count + 1)), dtype=float) for m in whole]
    for e, m in zip(edges, whole):
        e[0], e[-1] = m.lo, m.hi
    boxes = []
    for cell in itertools.product(*(range(count) for _ in whole)):
        boxes.append(Box(tuple(float(edges[j][i]) for j, i in enumerate(cell)),
                         tuple(float(edges[j][i + 1]) for j, i in enumerate(cell))))
    return boxes


@dataclass
class BoxRun:
    """One box's Galerkin run: coefficients (P, T), its probability, work, impacts."""

    box: Box
    probability: float
    x_coef: np.ndarray
    v_coef: np.ndarray
    rhs_evaluations: int
    impacts: int
    failure: str = ""
    method: str = "opa"  # or "collocation": its OPA system failed (see collocate_box)
    true_rhs_evaluations: int = 0  # the true systems' of a collocated box


def run_boxes(system: System, options: SolverOptions, boxes, times, basis: str, *,
              partial: bool = False) -> tuple[list[BoxRun], ChaosBasis, int]:
    """Each box's Galerkin system over ``times``, in parallel: the runs, the basis of the
    first (every box has the same multi-index set) and the rule's node count. A box whose
    system cannot be completed raises :class:`SimulationError`, or with ``partial`` comes
    back with its ``failure`` said and NaN coefficients (the adaptive refinement halves
    it)."""
    whole = system.problem.measures
    inputs, chaos, nodes = [], None, 0
    for box in boxes:
        local = chaos_basis(system, basis, box.measures(whole))
        rule = chaos_rule(local)
        inputs.append(system.kernel_inputs(options, rule=rule))
        chaos, nodes = chaos or local, len(rule[1])
    P = chaos.size
    batch = run_batch(stack(inputs), initial_coefficients(system, P), times,
                      rtol=options.rtol, atol=options.atol)
    failures = []
    for e, box in enumerate(boxes):
        failure = ""
        if not batch.ok[e] or not np.isfinite(batch.states[e]).all():
            why = batch.message(e) if not batch.ok[e] else "the state became non-finite"
            failure = f"box {_box_text(box)} of the OPA (N={system.order}) system stopped: {why}"
            if not partial:
                raise SimulationError(failure)
            batch.states[e] = np.nan
        failures.append(failure)
    return [BoxRun(box, box.probability(whole), batch.states[e, :, :P].T.copy(),
                   batch.states[e, :, P:].T.copy(), int(batch.rhs_evaluations[e]),
                   int(batch.impacts[e]), failures[e])
            for e, box in enumerate(boxes)], chaos, nodes


def collocate_box(system: System, options: SolverOptions, run: BoxRun, basis: str, *,
                  times) -> BoxRun:
    """A box's coefficients by collocation: the true sampled systems at the nodes of the
    tensor Gauss rule of the box's conditional law that is exact for products of two of
    its basis functions (N + 1 points per parameter), projected on that basis
    (``x_alpha = sum_q w_q x(xi_q) Psi_alpha(xi_q)``).

    The fallback of a box whose OPA system cannot be completed and that halving did not
    mend (its mean grazes or the Galerkin system diverges near a change of the impact
    sequence), as :func:`opa._elements.collocate_element` is in one dimension: the true
    systems do not depend on the Galerkin system."""
    whole = system.problem.measures
    local = chaos_basis(system, basis, run.box.measures(whole))
    nodes, weights = local.exact_rule(2, "tensor")  # positive weights
    phi = local.evaluate(nodes)  # (Q, P)
    paths, rhs = true_runs(system, options, nodes, times,
                           what=f"collocation of box {_box_text(run.box)} at")
    coef = np.einsum("qj,q,qts->sjt", phi, weights, paths)  # (2, P, T)
    return BoxRun(run.box, run.probability, coef[0], coef[1], run.rhs_evaluations, 0,
                  run.failure, "collocation", rhs)


def replace_failed_boxes(system, options, runs, basis, *, times) -> list[BoxRun]:
    """Every failed box of ``runs`` computed again by :func:`collocate_box`."""
    return [collocate_box(system, options, r, basis, times=times) if r.failure else r
            for r in runs]


def _box_text(box: Box) -> str:
    return " x ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in zip(box.lower, box.upper))


def moments(runs) -> tuple[np.ndarray, np.ndarray]:
    """E and Var of the coefficient arrays ``runs`` [(P_e, coef (P, T))] by the law of
    total variance."""
    mean = sum(p * c[0] for p, c in runs)
    second = sum(p * (c[0] ** 2 + (c[1:] ** 2).sum(axis=0)) for p, c in runs)
    return mean, np.maximum(second - mean ** 2, 0.0)


def split_inside(system: System, options: SolverOptions, boxes, times) -> np.ndarray:
    """For each box, whether the true sampled systems at its corners differ in their
    number of impacts over ``times`` (a change of the impact sequence inside)."""
    corners = np.concatenate([box.corners() for box in boxes])
    batch = run_batch(system.sampled_inputs(options, xi=corners),
                      system.deterministic().initial_state(), times, rtol=options.rtol,
                      atol=options.atol)
    impacts = batch.impacts.reshape(len(boxes), -1)
    return impacts.min(axis=1) != impacts.max(axis=1)


def indicator(run: BoxRun, chaos: ChaosBasis) -> tuple[float, int]:
    """(eta_e, the parameter to split along): the box's share of the variance
    ``P_e max_t v_e(t)``, and the parameter whose terms carry most of the box's variance
    (the direction along which it varies most)."""
    if run.failure:  # a box whose system diverged is halved first, along its widest side
        widths = np.subtract(run.box.upper, run.box.lower)
        return math.inf, int(np.argmax(widths))
    power = (run.x_coef[1:] ** 2).max(axis=1)  # each term's largest square over time
    eta = run.probability * float((run.x_coef[1:] ** 2).sum(axis=0).max())
    share = [power[chaos.indices[1:, j] > 0].sum() for j in range(chaos.dimension)]
    return eta, int(np.argmax(share))


def refine(system, options, times, basis, tolerance, max_elements):
    """Adaptive boxes: the runs, basis, node count, flags and the refinement's record.
    Each step halves every box whose variance share is at least the tolerance and a
    quarter of the largest (the largest first, flagged boxes before others at equal
    share), within the budget; it stops when every share is below the tolerance."""
    whole = system.problem.measures
    boxes = [Box(tuple(m.lo for m in whole), tuple(m.hi for m in whole))]
    runs, chaos, nodes = run_boxes(system, options, boxes, times, basis, partial=True)
    flags = split_inside(system, options, boxes, times)
    steps, change, mean = 0, float("nan"), runs[0].x_coef[0]
    while True:
        scored = [indicator(r, chaos) for r in runs]
        share = np.array([s[0] for s in scored])
        top = float(share.max())
        room = max_elements - len(runs)
        if top < tolerance or room <= 0:
            # what halving could not mend is computed by collocation of the true systems
            runs = replace_failed_boxes(system, options, runs, basis, times=times)
            met = top < tolerance
            if not met:
                warnings.warn(
                    f"adaptive boxes stopped at {len(runs)} elements with the largest "
                    f"variance share {top:.3g} above the tolerance {tolerance:g}: raise "
                    f"max_elements (now {max_elements}) or the tolerance",
                    ElementBudgetWarning, stacklevel=4)
            return runs, chaos, nodes, flags, dict(
                stopped_by="tolerance" if met else "element budget", error_estimate=change,
                largest_share=top, tolerance_met=int(met), tolerance=float(tolerance),
                max_elements=int(max_elements), refinement_steps=steps)
        finite = share[np.isfinite(share)]
        bar = max(tolerance, 0.25 * (finite.max() if len(finite) else 0.0))
        pick = sorted((e for e in range(len(runs)) if share[e] >= bar),
                      key=lambda e: (-share[e], not flags[e]))[:room]
        halves = [h for e in pick for h in runs[e].box.halves(scored[e][1], whole)]
        new, _, _ = run_boxes(system, options, halves, times, basis, partial=True)
        new_flags = split_inside(system, options, halves, times)
        keep = [e for e in range(len(runs)) if e not in set(pick)]
        runs = [runs[e] for e in keep] + new
        flags = np.concatenate([flags[keep], new_flags])
        steps += 1
        new_mean, _ = moments([(r.probability, r.x_coef) for r in runs])
        change, mean = float(np.sqrt(np.mean((new_mean - mean) ** 2))), new_mean  # NaN
        # while a box has failed


def sobol_from_boxes(runs, chaos: ChaosBasis, whole, coef: str = "x_coef"):
    """First-order and total Sobol indices (d, T) of the piecewise expansion, by exact
    quadrature on the tensor grid of cells the boxes' edges make."""
    d, order = chaos.dimension, int(chaos.indices.max())
    edges = [np.unique(np.concatenate([[r.box.lower[j], r.box.upper[j]] for r in runs]))
             for j in range(d)]
    axes = []  # per parameter: the cells' Gauss nodes and weights (probability)
    for j, m in enumerate(whole):
        xs, ws = [], []
        for lo, hi in zip(edges[j][:-1], edges[j][1:]):
            cell = m if (lo, hi) == (m.lo, m.hi) else m.restrict(lo, hi)
            x, w = cell.gauss(order + 1)
            xs.append(x)
            ws.append(w * cell.probability())
        axes.append((np.concatenate(xs), np.concatenate(ws)))
    weights = [a[1] for a in axes]
    shape = tuple(len(w) for w in weights)
    values = np.full(shape + (getattr(runs[0], coef).shape[1],), np.nan)
    for r in runs:  # each box is a block of whole cells: its slice of the grid
        block = tuple(slice((order + 1) * int(np.searchsorted(edges[j], r.box.lower[j])),
                            (order + 1) * int(np.searchsorted(edges[j], r.box.upper[j])))
                      for j in range(d))
        points = np.stack([g.ravel() for g in np.meshgrid(
            *(axes[j][0][block[j]] for j in range(d)), indexing="ij")], axis=1)
        local = ChaosBasis(r.box.measures(whole), chaos.indices)
        values[block] = (local.evaluate(points) @ getattr(r, coef)).reshape(
            *(b.stop - b.start for b in block), -1)
    return _anova(values, weights)


def _anova(values: np.ndarray, weights) -> tuple[np.ndarray, np.ndarray]:
    """First-order and total indices (d, T) of ``values`` on a tensor rule (one weight
    vector per axis, the last axis the outputs)."""
    d = len(weights)

    def mean_over(array, keep):
        for j in reversed(range(d)):
            if j not in keep:
                shape = [1] * array.ndim
                shape[j] = len(weights[j])
                array = (array * weights[j].reshape(shape)).sum(axis=j, keepdims=True)
        return array

    mean = mean_over(values, ())
    var = mean_over((values - mean) ** 2, ()).reshape(-1)
    first, total = np.empty((d, values.shape[-1])), np.empty((d, values.shape[-1]))
    for j in range(d):
        given = mean_over(values, (j,))  # E[x | xi_j]
        first[j] = mean_over((given - mean) ** 2, ()).reshape(-1)
        others = tuple(k for k in range(d) if k != j)
        rest = mean_over(values, others)  # E[x | xi_~j]
        total[j] = var - mean_over((rest - mean) ** 2, ()).reshape(-1)
    with np.errstate(all="ignore"):
        # a deterministic output (the start) has no variance but round-off's, ~eps^2 x^2
        live = var > 1e-20 * np.max(np.abs(values)) ** 2
        return (np.where(live, first / np.where(live, var, 1.0), np.nan),
                np.where(live, total / np.where(live, var, 1.0), np.nan))


def simulate_boxes(system: System, options: SolverOptions, times, elements, *,
                   basis: str = "total", tolerance: float = 1e-6,
                   max_elements: int = 64) -> xr.Dataset:
    """Multi-element OPA of ``system`` (several uncertain parameters) with boxes: K per
    parameter (``elements=K``) or adaptive; the ``opa`` dataset (docs/datasets.md)."""
    whole = system.problem.measures
    if isinstance(elements, str):
        runs, chaos, nodes, flags, record = refine(system, options, times, basis, tolerance,
                                                   max_elements)
    else:
        count = int(elements)
        if count ** system.dimension > MAX_BOXES:
            raise ValueError(f"elements = {count} makes {count}^{system.dimension} boxes, more "
                             f"than {MAX_BOXES}")
        boxes = uniform_boxes(whole, count)
        runs, chaos, nodes = run_boxes(system, options, boxes, times, basis, partial=True)
        runs = replace_failed_boxes(system, options, runs, basis, times=times)
        flags, record = split_inside(system, options, boxes, times), {}
    return _dataset(system, options, times, runs, chaos, whole, flags,
                    dict(record, basis=basis, nodes=nodes,
                         element_mode="adaptive" if isinstance(elements, str) else "uniform"))


def _dataset(system, options, times, runs, chaos, whole, flags, attrs) -> xr.Dataset:
    names = list(system.problem.names)
    x_mean, x_var = moments([(r.probability, r.x_coef) for r in runs])
    v_mean, v_var = moments([(r.probability, r.v_coef) for r in runs])
    data = {
        "x_mean": ("time", x_mean, {"long_name": "OPA mean E[x] over the boxes",
                                    "units": "1"}),
        "x_var": ("time", x_var, {"long_name": "OPA variance Var[x] over the boxes (law of "
                                               "total variance)", "units": "1"}),
        "v_mean": ("time", v_mean, {"long_name": "OPA mean velocity over the boxes",
                                    "units": "1"}),
        "v_var": ("time", v_var, {"long_name": "OPA velocity variance over the boxes",
                                  "units": "1"}),
        "element_x_coef": (("element", "term", "time"), np.array([r.x_coef for r in runs]),
                           {"long_name": "each box's coefficients x_alpha in its own "
                                         "conditional law's basis", "units": "1"}),
        "element_v_coef": (("element", "term", "time"), np.array([r.v_coef for r in runs]),
                           {"long_name": "each box's coefficients v_alpha", "units": "1"}),
        "element_lower": (("element", "parameter"), np.array([r.box.lower for r in runs]),
                          {"long_name": "lower side of each box in xi", "units": "1"}),
        "element_upper": (("element", "parameter"), np.array([r.box.upper for r in runs]),
                          {"long_name": "upper side of each box in xi", "units": "1"}),
        "element_probability": ("element", np.array([r.probability for r in runs]),
                                {"long_name": "probability of each box", "units": "1"}),
        "element_split_inside": ("element", np.asarray(flags, dtype=np.int8), {
            "long_name": "1 where the true systems at the box's corners differ in their "
                         "number of impacts", "units": "1"}),
        "element_method": ("element", np.array([r.method == "collocation" for r in runs],
                                               dtype=np.int8), {
            "long_name": "how each box was computed", "units": "1",
            "flag_values": np.array([0, 1], dtype=np.int8),
            "flag_meanings": "opa collocation_after_opa_failed"}),
        "multi_index": (("term", "parameter"), chaos.indices.astype(np.int64),
                        {"long_name": "degree of each parameter's polynomial in Psi_alpha",
                         "units": "1"}),
    }
    for state in ("x", "v"):
        first, total = sobol_from_boxes(runs, chaos, whole, f"{state}_coef")
        data[f"{state}_sobol_first"] = (("parameter", "time"), first, {
            "long_name": f"first-order Sobol index of {state} from the boxes' expansions "
                         f"(NaN where its variance is 0)", "units": "1"})
        data[f"{state}_sobol_total"] = (("parameter", "time"), total, {
            "long_name": f"total Sobol index of {state} from the boxes' expansions (NaN "
                         f"where its variance is 0)", "units": "1"})
    ds = xr.Dataset(data, coords={**time_coord(times, system.oscillator.omega),
                                  "term": ("term", np.arange(chaos.size)),
                                  "parameter": ("parameter", names),
                                  "element": ("element", np.arange(len(runs)))},
                    attrs=provenance_attrs("opa", system, options))
    ds.attrs.update(attrs, elements=len(runs),
                    collocation_elements=int(sum(r.method == "collocation" for r in runs)),
                    collocation_rhs_evaluations=int(sum(r.true_rhs_evaluations
                                                        for r in runs)),
                    rhs_evaluations=int(sum(r.rhs_evaluations for r in runs)))
    return ds
