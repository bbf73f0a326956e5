"""Single runs of the DMR (eq. (29)) and of the OPA equivalent system (eqs. (24)-(28)).

This layer validates input, runs the kernel through ``opa._run`` and builds the ``dmr``
and ``opa`` datasets of docs/datasets.md.
"""

from __future__ import annotations


import numpy as np

from opa._dataset import element_layout, provenance_attrs, time_coord
from opa._lazy import lazy
from opa._model import (
    check_instance,
    Oscillator,
    SolverOptions,
)
from opa._run import output_times, run, run_batch, stack
from opa._system import IMPULSE_FIELDS, System, as_system
from opa._work import check_steps

xr = lazy("xarray")


def simulate_dmr(
    system: System | Oscillator | None = None,
    *,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
    **impulse_model,
) -> xr.Dataset:
    """One deterministic trajectory of the impact oscillator (the DMR, eq. (29)).

    Parameters
    ----------
    system : an :class:`opa.System` (its oscillator and impulse model; the uncertainty is
        not part of the DMR) or an :class:`opa.Oscillator` (paper defaults when omitted).
    periods, per_period : output times t_j = j (2 pi/omega)/K, j = 0..P K; K = 1 gives
        the stroboscopic samples. ``times`` overrides this grid.
    options : solver options (tolerances, method, ...).
    impulse, pulse_width, impulse_at_zero : the impulse model, when ``system`` is an
        Oscillator (:class:`opa.System`).

    Returns
    -------
    xarray.Dataset with ``x(time)``, ``v(time)``, ``impact_time(impact)``,
    ``impact_velocity(impact)`` and the provenance attributes of docs/datasets.md.
    States at an impulse time are recorded just after the impulse (right-continuous).

    Examples
    --------
    >>> ds = simulate_dmr(Oscillator(), periods=10)
    >>> ds.x.sizes["time"]
    11
    """
    options = check_instance("options", options, SolverOptions, SolverOptions())
    system = as_system(system, options, allowed=IMPULSE_FIELDS, where="simulate_dmr",
                       several=True, **impulse_model).deterministic()
    oscillator = system.oscillator
    times = output_times(oscillator, periods, per_period, times)
    span = float(times[-1] - times[0]) / oscillator.forcing_period
    check_steps("this DMR run", span, oscillator, options.max_steps,
                [("omega", f"{oscillator.omega:g}"), ("periods", f"{span:g}")])
    rec = run(system.kernel_inputs(options), system.initial_state(), times,
              rtol=options.rtol, atol=options.atol, label="DMR trajectory")
    ds = xr.Dataset(
        {
            "x": ("time", rec.states[:, 0], {"long_name": "displacement x", "units": "1"}),
            "v": ("time", rec.states[:, 1], {"long_name": "velocity dx/dt", "units": "1"}),
            **rec.events.dataset_vars(oscillator.two_walls),
        },
        coords=time_coord(times, oscillator.omega),
        attrs=provenance_attrs("dmr", system, options),
    )
    ds.attrs.update(steps=rec.steps, rhs_evaluations=rec.rhs_evaluations)
    return ds


def check_opa_work(system: System, times: np.ndarray, elements, max_elements: int,
                   max_steps: int | None = None, basis: str = "total") -> None:
    """Refuse an OPA run beyond the work budget (:mod:`opa._work`): its systems of 2 (N + 1)
    states over the run, per element, and for adaptive elements the split scan that places
    them (up to ``SPLIT_BUDGET`` splits, each bisected over the whole run); and one whose
    trajectory would need more than ``max_steps`` steps (slow forcing). With several
    uncertain parameters a system counts as the larger of its terms and its nodes
    (:func:`opa._galerkin.check_chaos_size`, which refuses sizes past its bounds), per
    box."""
    from opa._elements import SPLIT_BUDGET
    from opa._work import check_steps, check_work

    periods = float(times[-1] - times[0]) / system.oscillator.forcing_period
    if max_steps is not None:
        check_steps("this OPA run", periods, system.oscillator, max_steps,
                    [("omega", f"{system.oscillator.omega:g}"), ("periods", f"{periods:g}")])
    order = int(system.order)
    size = order + 1
    if system.dimension > 1:  # the terms, or the nodes the right-hand side visits
        from opa._galerkin import check_chaos_size

        size = max(check_chaos_size(system, basis))
    adaptive = isinstance(elements, str) and elements == "adaptive"
    try:  # elements are checked later, where they are used; here only counted
        count = max_elements if adaptive else (1 if elements is None else
                                               np.size(elements) - 1 if np.ndim(elements)
                                               else int(elements))
        count = max(int(count), 1)
    except (TypeError, ValueError, OverflowError):
        count = 1
    work = size * max(count, 1) * periods
    drivers = [("periods", f"{periods:g}"), ("order", order)]
    if adaptive and system.dimension > 1:
        drivers.append(("elements", f"adaptive (up to {count} boxes)"))
    elif adaptive:
        work += SPLIT_BUDGET * 60 * periods  # ~60 bisection runs to 1e-6 in xi per split
        drivers.append(("elements", f"adaptive (its split scan: up to {SPLIT_BUDGET} splits)"))
    elif count > 1:
        drivers.append(("elements", count))
    check_work("this OPA run", work, drivers, oscillator=system.oscillator)


def simulate_opa(
    system: System | Oscillator | None = None,
    *,
    periods: float = 100,
    per_period: int = 1,
    options: SolverOptions | None = None,
    times: np.ndarray | None = None,
    initial: np.ndarray | None = None,
    elements=None,
    tolerance: float | None = None,
    max_elements: int | None = None,
    partial: bool = False,
    basis: str = "total",
    **fields,
) -> xr.Dataset:
    """The OPA equivalent system of order N (the EMR, eqs. (24)-(28)).

    ``x(t, xi) ~ sum_i x_i(t) U_i(xi)`` with the uncertain parameter
    ``p = p_bar + sigma xi``; impacts use the mean constraint ``x_0 = delta``
    (eq. (21)) and the impact law ``mean`` (eq. (28): only x_0' jumps) or ``ensemble``
    (every velocity coefficient is multiplied by -eta). ``truncation="paper"`` drops
    the ``sigma/2 Y_{N+1}`` term of the last equation as eq. (27) does; ``galerkin``
    keeps the exact projection. Initial coefficients: x_0 = x0, v_0 = v0, others 0,
    unless ``initial`` (shape (2, N+1): rows x_coef, v_coef) is given, e.g. to continue
    from the end of an earlier run.

    The system is an :class:`opa.System`, or an :class:`opa.Oscillator` (paper
    defaults when omitted) with the System's fields as keywords: ``sigma`` (default
    0.01), ``order`` (N, default 4), ``uncertain``, ``distribution``,
    ``allow_negative``, ``truncation``, ``impact_law``, ``impulse``, ``pulse_width``,
    ``impulse_at_zero``.

    Multi-element OPA (:mod:`opa._elements`): ``distribution`` is the law of xi (a name
    of :data:`opa._measure.DISTRIBUTIONS`, a chaospy distribution with bounded support,
    or a :class:`opa._measure.Measure`; default the semicircle) and ``elements`` cuts
    its support: ``K`` equal-probability elements, an increasing array of edges, or
    ``"adaptive"`` (edges at the splits of the sampled systems' impact sequences, then
    halving of the element with the largest variance share until it is below
    ``tolerance``, default 1e-6, or ``max_elements``, default 64, is reached; both are
    refused without ``"adaptive"``, where they would have no effect). Each element runs its own
    OPA system
    of order N; the result holds the assembled ``x_mean, x_var, v_mean, v_var`` and the
    per-element coefficients, edges and probabilities. With ``elements`` and the System
    given by keywords, ``impact_law`` defaults to ``"saltation"``, the law whose elements
    converge (the paper's ``mean`` law converges only like K^-1.2, docs/elements.md); a
    :class:`System` keeps its own law. An adaptive run records whether its tolerance was
    met (``attrs["tolerance_met"]``, ``attrs["stopped_by"]``), the RMS change of E[x] in
    its last refinement step (``attrs["error_estimate"]``), and warns
    (:class:`opa._elements.ElementBudgetWarning`) when the budget stopped it.

    Every OPA dataset has the same layout (docs/datasets.md): ``x_mean, x_var, v_mean,
    v_var`` and the element variables ``element_x_coef``, ``element_v_coef`` (element,
    order, time), ``element_edges``, ``element_probability``; the paper's single-element
    OPA is the case of one element. ``x_coef, v_coef`` (order, time) are there whenever
    there is one element (in the law's orthonormal basis).

    ``partial``: a trajectory that cannot be completed (e.g. the OPA system diverges)
    returns the outputs reached, NaN after, with the reason in ``attrs["failure"]``,
    instead of raising :class:`SimulationError`.

    Several uncertain parameters (``uncertain="mu,c"``, ``sigma=(0.02, 0.005)``,
    ``distribution=("semicircle", "uniform")``, or an :class:`opa.Problem` as
    ``uncertain``): the Galerkin system on the multi-index set ``basis`` (``total``
    degree <= N, ``tensor`` or ``hyperbolic:Q``; :mod:`opa._galerkin`), one element; the
    dataset's coefficients run over ``term`` with their ``multi_index`` (term,
    parameter), and the Sobol indices of x and v from the coefficients come with them
    (``x_sobol_first``, ``x_sobol_total``, ...). ``basis`` is refused with one
    parameter, where the basis is the law's own polynomials up to N.

    Returns
    -------
    xarray.Dataset with ``x_coef(order, time)``, ``v_coef(order, time)``,
    ``x_mean`` (= x_coef[0], the EMR), ``x_var`` (= sum_{i>=1} x_coef^2), ``v_mean``,
    ``v_var`` and the impacts of the mean coordinate.

    Examples
    --------
    >>> ds = simulate_opa(Oscillator(), sigma=0.01, order=4, periods=10)
    >>> ds.x_coef.shape
    (5, 11)
    """
    options = check_instance("options", options, SolverOptions, SolverOptions())
    tolerance, max_elements = _refinement(elements, tolerance, max_elements)
    if not isinstance(system, System) and fields.get("impact_law") is None:
        fields["impact_law"] = default_impact_law(elements)
    system = as_system(system, options, where="simulate_opa", several=True, **fields)
    system.check_samples()
    oscillator, order = system.oscillator, system.order
    check_opa_work(system, output_times(oscillator, periods, per_period, times), elements,
                   max_elements, options.max_steps, basis)
    if system.dimension > 1:
        return _several(system, options, output_times(oscillator, periods, per_period, times),
                        elements, initial, partial, basis, tolerance, max_elements)
    if basis != "total":
        raise ValueError(f"basis = {basis!r:.40} applies with several uncertain parameters; "
                         f"with one the basis is the law's polynomials up to N")
    if system.distribution is not None or elements is not None:
        from opa._elements import simulate_elements

        if initial is not None or partial:
            raise ValueError("initial and partial are not supported with elements or a "
                             "distribution")
        return simulate_elements(
            system, options=options, times=output_times(oscillator, periods, per_period, times),
            elements=1 if elements is None else elements, tolerance=tolerance,
            max_elements=max_elements)
    times = output_times(oscillator, periods, per_period, times, dim=2 * (order + 1))
    rec = run(system.kernel_inputs(options), system.initial_state(initial), times,
              rtol=options.rtol, atol=options.atol, label=f"OPA (N={order}) trajectory",
              partial=partial)
    return _single_element(system, options, times, rec)


def _several(system, options, times, elements, initial, partial, basis, tolerance,
             max_elements) -> xr.Dataset:
    """:func:`simulate_opa` with several uncertain parameters: one element
    (:mod:`opa._galerkin`) or boxes (:mod:`opa._boxes`)."""
    if initial is not None:
        raise ValueError("initial is not available with several uncertain parameters yet "
                         "(the deterministic start)")
    if elements is None:
        from opa._galerkin import simulate_chaos

        return simulate_chaos(system, options, times, basis=basis, partial=partial)
    from opa._boxes import MAX_BOXES, simulate_boxes

    if isinstance(elements, str) and not 2 <= max_elements <= MAX_BOXES:
        raise ValueError(f"max_elements must be 2 to {MAX_BOXES} boxes, got {max_elements}")
    if partial:
        raise ValueError("partial is not available with elements")
    return simulate_boxes(system, options, times, elements, basis=basis,
                          tolerance=tolerance, max_elements=max_elements)


def default_impact_law(elements) -> str:
    """The impact law of an OPA run that names none: ``"saltation"`` with ``elements``
    (any K or ``"adaptive"``: the law whose elements converge), else ``"mean"`` (the
    paper's eq. (28)). :func:`simulate_opa` and ``opa-mc simulate opa`` both use it.

    >>> default_impact_law(None), default_impact_law(4), default_impact_law("adaptive")
    ('mean', 'saltation', 'saltation')
    """
    return "mean" if elements is None else "saltation"


def _refinement(elements, tolerance, max_elements) -> tuple[float, int]:
    """The adaptive refinement's ``tolerance`` and ``max_elements`` with their defaults
    (1e-6, 64); either given without ``elements="adaptive"`` is refused (it would have no
    effect)."""
    adaptive = isinstance(elements, str) and elements == "adaptive"
    for name, value in (("tolerance", tolerance), ("max_elements", max_elements)):
        if value is not None and not adaptive:
            raise ValueError(f"{name} = {value!r} applies with elements='adaptive' only (the "
                             f"refinement of adaptive elements), got elements={elements!r:.40}")
    return (1e-6 if tolerance is None else tolerance,
            64 if max_elements is None else max_elements)


def _single_element(system: System, options: SolverOptions, times: np.ndarray,
                    rec) -> xr.Dataset:
    """The ``opa`` dataset of the paper's single-element OPA from its kernel record: the
    coefficients, the moments they give, the one element's layout and the impacts of the
    mean coordinate."""
    oscillator, order = system.oscillator, system.order
    xc = rec.states[:, : order + 1].T
    vc = rec.states[:, order + 1 :].T
    layout, layout_coords = element_layout(
        xc[None], vc[None], [-1.0, 1.0], [1.0], [rec.impacts], [rec.rhs_evaluations])
    ds = xr.Dataset(
        {
            "x_coef": (("order", "time"), xc,
                       {"long_name": "OPA coefficient x_i = E[x U_i(xi)]", "units": "1"}),
            "v_coef": (("order", "time"), vc,
                       {"long_name": "OPA coefficient v_i = E[x' U_i(xi)]", "units": "1"}),
            "x_mean": ("time", xc[0], {"long_name": "OPA mean E[x] = x_0 (EMR)", "units": "1"}),
            "x_var": ("time", (xc[1:] ** 2).sum(axis=0),
                      {"long_name": "OPA variance sum_{i>=1} x_i^2", "units": "1"}),
            "v_mean": ("time", vc[0], {"long_name": "OPA mean velocity v_0", "units": "1"}),
            "v_var": ("time", (vc[1:] ** 2).sum(axis=0),
                      {"long_name": "OPA velocity variance sum_{i>=1} v_i^2", "units": "1"}),
            **layout,
            **rec.events.dataset_vars(oscillator.two_walls),
        },
        coords={**time_coord(times, oscillator.omega), "order": ("order", np.arange(order + 1)),
                **layout_coords},
        attrs=provenance_attrs("opa", system, options),
    )
    ds.attrs.update(steps=rec.steps, rhs_evaluations=rec.rhs_evaluations,
                    distribution="semicircle", elements=1, element_mode="single")
    if rec.failure is not None:
        ds.attrs["failure"] = rec.failure
    return ds


def opa_variants(system: System, variants, times: np.ndarray, options: SolverOptions, *,
                 coefficients: bool = False):
    """The OPA system under several (impact law, truncation) variants, in parallel: mean
    and variance of x over ``times`` (NaN after a trajectory that could not be completed),
    the time of each variant's first impact (inf: none) and its kernel status (0: it
    finished; ``opa._run.STATUS_NAMES`` names each code).

    Returns (x_mean (V, T), x_var (V, T), first_impact (V,), status (V,)), and with
    ``coefficients`` the coefficients x_j (V, N+1, T) of the surrogate
    (:func:`opa._surrogate.surrogate_values`; NaN where the mean is)."""
    order = system.order
    inputs = stack([system.replace(impact_law=law, truncation=trunc).kernel_inputs(options)
                    for law, trunc in variants])
    batch = run_batch(inputs, system.initial_state(), times, rtol=options.rtol,
                      atol=options.atol, capacity=max(64, 4 * len(times)))
    batch.blank_failures()
    first = np.array([batch.events(v).first_impact() for v in range(len(batch))])
    out = batch.states
    x = out[:, :, : order + 1]
    moments = x[:, :, 0], (x[:, :, 1:] ** 2).sum(axis=2), first, batch.status
    return (*moments, x.transpose(0, 2, 1).copy()) if coefficients else moments
