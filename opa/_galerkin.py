r"""The OPA equivalent system with several uncertain parameters: the Galerkin projection
of eq. (1) on a multi-index basis of the product law of xi.

With d uncertain parameters (:class:`opa.Problem`) the response is expanded as

.. math::

    x(t, \xi) \approx \sum_{\alpha \in \mathcal{A}} x_\alpha(t) \Psi_\alpha(\xi), \qquad
    \Psi_\alpha(\xi) = \prod_{j=1}^d p^{(j)}_{\alpha_j}(\xi_j),

over a multi-index set :math:`\mathcal{A}` (total degree N by default; tensor or
hyperbolic as options, :func:`opa._chaos.multi_indices`), with the orthonormal
polynomials :math:`p^{(j)}` of each marginal. The Galerkin system is the paper's eqs.
(24)-(26) with :math:`U_i` replaced by :math:`\Psi_\alpha`; the kernel evaluates it in
pseudo-spectral form on a cubature rule exact for every product of four basis functions
(the cube of the expansion times one basis function, total degree 4N), so the
projection of the cubic terms is exact as it is in one dimension. The kernel receives
the rule's basis values, weights and the parameter table (:meth:`opa.Problem.table`)
and does not know that xi has d dimensions. The mean constraint of the impact (eq.
(21)) and the ``mean``, ``ensemble`` and ``saltation`` impact laws carry over unchanged:
they act on the coefficients, not on xi.

The first-order and total Sobol indices of x(t) and v(t) come with the run, from the
coefficients (Sudret 2008, :func:`opa._sensitivity.sobol_indices`).

Several elements are boxes (:mod:`opa._boxes`). The paper's closure (eq. (27), one
uncertain parameter) is not available in d > 1 and is refused by name.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from opa._chaos import ChaosBasis
from opa._dataset import provenance_attrs, time_coord
from opa._model import SolverOptions
from opa._run import run
from opa._sensitivity import sobol_indices
from opa._system import System

#: multi-index sets a d-dimensional OPA run may use (``opa._chaos.multi_indices``)
BASIS_KINDS = ("total", "tensor", "hyperbolic")


def chaos_basis(system: System, basis: str = "total", measures=None) -> ChaosBasis:
    """The multi-index basis of order N over the marginals of ``system``'s problem (or
    over ``measures``, an element's conditional marginals): ``basis`` is ``total`` (total
    degree <= N), ``tensor`` (each degree <= N) or ``hyperbolic:Q`` (q-norm <= N,
    0 < Q <= 1).

    >>> from opa import System
    >>> chaos_basis(System(uncertain="mu,c", sigma=0.01, order=2)).indices.tolist()
    [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    """
    kind, _, qtext = str(basis).partition(":")
    if kind not in BASIS_KINDS or (qtext and kind != "hyperbolic"):
        raise ValueError(f"basis must be one of total, tensor, hyperbolic:Q, got "
                         f"{basis!r:.40}")
    try:
        q = float(qtext) if qtext else (0.75 if kind == "hyperbolic" else 1.0)
    except ValueError:
        raise ValueError(f"basis hyperbolic:Q takes a number 0 < Q <= 1, got "
                         f"{basis!r:.40}") from None
    return ChaosBasis.from_order(system.problem.measures if measures is None else measures,
                                 system.order, kind, q)


#: most products of nodes and terms (Q x P) the equivalent system may hold: its basis
#: table and each right-hand side cost that many operations (the one-parameter system
#: at its largest order, N = 500, holds 1001 x 501 = 5e5)
MAX_NODE_TERMS = 20_000_000


def check_chaos_size(system: System, basis: str = "total") -> tuple[int, int]:
    """(P, Q): the terms of the multi-index set and the nodes of the tensor rule (an upper
    bound of the rule's), before any of them is built; refuse in one line naming the
    order, the basis and the parameters where Q x P exceeds ``MAX_NODE_TERMS`` or the
    basis table exceeds the memory budget."""
    from math import comb

    from opa._memory import check_memory

    kind = str(basis).partition(":")[0]
    d, N = system.problem.dimension, int(system.order)
    P = (N + 1) ** d if kind == "tensor" else comb(N + d, d)  # hyperbolic: at most total
    Q = (2 * N + 1) ** d
    what = (f"order {N} with {d} uncertain parameters ({','.join(system.problem.names)}) "
            f"and the {kind} basis")
    if P * Q > MAX_NODE_TERMS:
        raise ValueError(f"{what} makes {P} terms on up to {Q} nodes: {P * Q:.3g} products "
                         f"per right-hand side, more than {MAX_NODE_TERMS:.0e}; lower the "
                         f"order, use a sparser basis (hyperbolic:Q) or fewer parameters")
    check_memory("the OPA system's basis table", Q * (P + 1) * 8,
                 f"{what}: up to {Q} nodes x {P + 1} values")
    return P, Q


def chaos_rule(basis: ChaosBasis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's rule of ``basis``: nodes (Q, d), weights (Q,) exact for products of
    four basis functions, and the basis degree-major (P + 1, Q), its last row (the
    closure's U_{N+1} in one dimension) zero."""
    nodes, weights = basis.exact_rule(4)
    values = basis.evaluate(nodes)  # (Q, P)
    degree_major = np.zeros((basis.size + 1, len(weights)))
    degree_major[:-1] = values.T
    return nodes, weights, degree_major


def initial_coefficients(system: System, size: int) -> np.ndarray:
    """The start of a d-dimensional run: x_0 = x0, v_0 = v0, every other coefficient 0
    (a deterministic initial state)."""
    y = np.zeros(2 * size)
    y[0] = system.oscillator.x0
    y[size] = system.oscillator.v0
    return y


def simulate_chaos(system: System, options: SolverOptions, times: np.ndarray, *,
                   basis: str = "total", partial: bool = False) -> xr.Dataset:
    """The Galerkin OPA system of ``system`` (d >= 2 uncertain parameters) at ``times``:
    the ``opa`` dataset with the coefficients over the multi-index set, the moments and
    the Sobol indices they give."""
    chaos = chaos_basis(system, basis)
    rule = chaos_rule(chaos)
    inputs = system.kernel_inputs(options, rule=rule)
    rec = run(inputs, initial_coefficients(system, chaos.size), times, rtol=options.rtol,
              atol=options.atol, partial=partial,
              label=f"OPA (N={system.order}, d={system.problem.dimension}) trajectory")
    ds = chaos_dataset(system, options, times, rec, chaos)
    ds.attrs.update(basis=basis, nodes=len(rule[1]))
    return ds


def chaos_dataset(system, options, times, rec, chaos: ChaosBasis) -> xr.Dataset:
    """The dataset of a d-dimensional OPA run from its kernel record (docs/datasets.md)."""
    P = chaos.size
    xc = rec.states[:, :P].T
    vc = rec.states[:, P:].T
    names = list(system.problem.names)
    data = {
        "x_coef": (("term", "time"), xc, {"long_name": "OPA coefficient x_alpha = E[x "
                                                       "Psi_alpha(xi)]", "units": "1"}),
        "v_coef": (("term", "time"), vc, {"long_name": "OPA coefficient v_alpha = E[x' "
                                                       "Psi_alpha(xi)]", "units": "1"}),
        "x_mean": ("time", xc[0], {"long_name": "OPA mean E[x] = x_0", "units": "1"}),
        "x_var": ("time", (xc[1:] ** 2).sum(axis=0),
                  {"long_name": "OPA variance sum_{alpha != 0} x_alpha^2", "units": "1"}),
        "v_mean": ("time", vc[0], {"long_name": "OPA mean velocity v_0", "units": "1"}),
        "v_var": ("time", (vc[1:] ** 2).sum(axis=0),
                  {"long_name": "OPA velocity variance sum_{alpha != 0} v_alpha^2",
                   "units": "1"}),
        "multi_index": (("term", "parameter"), chaos.indices.astype(np.int64),
                        {"long_name": "degree of each parameter's polynomial in Psi_alpha",
                         "units": "1"}),
        **rec.events.dataset_vars(system.oscillator.two_walls),
    }
    for state, coef in (("x", xc), ("v", vc)):
        with np.errstate(all="ignore"):
            found = sobol_indices(coef, chaos.indices)
        data[f"{state}_sobol_first"] = (("parameter", "time"), found.first, {
            "long_name": f"first-order Sobol index of {state} from the OPA coefficients "
                         f"(NaN where its variance is 0)", "units": "1"})
        data[f"{state}_sobol_total"] = (("parameter", "time"), found.total, {
            "long_name": f"total Sobol index of {state} from the OPA coefficients (NaN "
                         f"where its variance is 0)", "units": "1"})
    ds = xr.Dataset(data, coords={**time_coord(times, system.oscillator.omega),
                                  "term": ("term", np.arange(P)),
                                  "parameter": ("parameter", names)},
                    attrs=provenance_attrs("opa", system, options))
    ds.attrs.update(steps=rec.steps, rhs_evaluations=rec.rhs_evaluations, elements=1,
                    element_mode="single")
    if rec.failure is not None:
        ds.attrs["failure"] = rec.failure
    return ds
