"""The stochastic bifurcation diagram: which attractors the random system settles on, with
what probability, and where in xi the type changes.

For each value of a control parameter (e.g. c of section 3.1) each sample of the uncertain
parameter ``p = p_bar + sigma xi`` is a deterministic impact oscillator that settles on
some attractor. Its *type* is the motion label of the sweep (``z = n/p``: period n in
forcing periods with p impacts per period, ``none`` when no period is found in the
record, ``failed`` when the run escapes or stops). At one control value:

1. **Boundaries by continuation in xi.** The bifurcations of the periodic attractors
   along ``p`` over the support are located (:func:`locate_bifurcations`: pseudo-arclength
   continuation of the fixed points of the stroboscopic map, period doublings and folds
   root-found, grazings extrapolated; ``xtol`` in p) and mapped to
   ``xi = (p - p_bar) / sigma``.
2. **The type between boundaries** is classified at the middle of each interval by one
   brute-force run (``transient`` periods, then ``record``); neighbouring intervals of the
   same type merge (a boundary between them changes nothing a user sees).
3. **Probabilities** are the law's mass between the boundaries, ``F(xi_b) - F(xi_a)``:
   exact up to the boundaries' error, for any law of xi.
4. **Monte Carlo beside it**: ``samples`` random points of xi, each classified by its own
   run; probabilities with binomial standard errors ``sqrt(p (1 - p) / M)``; the
   continuation's probabilities are checked against them (``agree``: within 3 SE).

Where continuation cannot follow (a type that is not periodic, or a type the Monte Carlo
samples see that no interval has) the control value's probabilities are the Monte Carlo
ones, and ``method`` says so. Every run starts from the oscillator's ``x0, v0``:
coexisting attractors reached from other initial states are not searched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from opa._model import Oscillator, SolverOptions
from opa._system import System
from opa.dynamics._continuation import locate_bifurcations
from opa.dynamics._sweep import sweep

if TYPE_CHECKING:  # scipy.stats loads scipy.optimize: not at import opa
    from opa._measure import Measure

#: the continuation's probabilities agree with Monte Carlo within this many binomial SE
AGREEMENT_SE = 3.0


@dataclass
class Slice:
    """The stochastic diagram at one control value."""

    value: float
    boundaries: list = field(default_factory=list)  # (xi, kind) where the type changes
    intervals: list = field(default_factory=list)  # (xi_lo, xi_hi, type)
    probability: dict = field(default_factory=dict)  # type -> probability
    mc_probability: dict = field(default_factory=dict)  # type -> MC share
    samples: int = 0
    method: str = "continuation"
    located: list = field(default_factory=list)  # every located bifurcation (xi, kind)


def classify(oscillator: Oscillator, uncertain: str, values, *, options: SolverOptions,
             transient: int, record: int, workers: int = 1) -> list[str]:
    """The attractor type (the sweep's motion label) of the system with ``uncertain`` at
    each of ``values`` (absolute), each from x0, v0."""
    values = np.asarray(values, dtype=float)
    order = np.argsort(values)
    unique, inverse = np.unique(values[order], return_inverse=True)
    ds = sweep("dmr", uncertain, unique, oscillator, transient=transient, record=record,
               options=options, workers=workers, progress=False, locate=False)
    labels = [str(x) for x in ds.label.values]
    out = np.empty(len(values), dtype=object)
    out[order] = [labels[i] for i in inverse]
    return list(out)


def stochastic_slice(oscillator: Oscillator, uncertain: str, sigma: float,
                     measure: "Measure", *, samples: int, seed: int, options: SolverOptions,
                     transient: int = 300, record: int = 64, xtol: float = 1e-10,
                     workers: int = 1) -> Slice:
    """The diagram at one control value (see the module docstring)."""
    centre = float(getattr(oscillator, uncertain))
    lo, hi = measure.lo, measure.hi
    located = locate_bifurcations(oscillator, uncertain, centre + sigma * lo,
                                  centre + sigma * hi, options=options, seeds=5,
                                  xtol=xtol * sigma)
    found = sorted(((p.value - centre) / sigma, p.kind) for p in located)
    found = [(x, k) for x, k in found if lo < x < hi]
    edges = [lo, *[x for x, _ in found], hi]
    mids = [0.5 * (a + b) for a, b in zip(edges[:-1], edges[1:])]
    rng = np.random.default_rng(seed)
    xi = measure.ppf(rng.random(samples)) if samples else np.zeros(0)
    types = classify(oscillator, uncertain, centre + sigma * np.concatenate([mids, xi]),
                     options=options, transient=transient, record=record, workers=workers)
    mid_types, mc_types = types[: len(mids)], types[len(mids):]
    out = Slice(value=math.nan, samples=int(samples), located=found)
    start = edges[0]
    for i, kind in enumerate(mid_types):  # merge neighbours of the same type
        last = i == len(mid_types) - 1
        if last or mid_types[i + 1] != kind:
            out.intervals.append((start, edges[i + 1], kind))
            if not last:
                out.boundaries.append((edges[i + 1], found[i][1]))
                start = edges[i + 1]
    cdf = measure.cdf
    for a, b, kind in out.intervals:
        out.probability[kind] = out.probability.get(kind, 0.0) + float(cdf(b) - cdf(a))
    for kind in mc_types:
        out.mc_probability[kind] = out.mc_probability.get(kind, 0.0) + 1.0 / samples
    unseen = set(out.mc_probability) - set(out.probability)
    if unseen or any(not _periodic(k) for k in out.probability):
        out.method = "sampling"  # continuation cannot follow: Monte Carlo decides
        out.probability = dict(out.mc_probability)
    return out


def _slice_to_json(piece: Slice) -> dict:
    import dataclasses

    return dataclasses.asdict(piece)


def _slice_from_json(data: dict) -> Slice:
    return Slice(value=float(data["value"]), boundaries=[tuple(b) for b in data["boundaries"]],
                 intervals=[tuple(i) for i in data["intervals"]],
                 probability=dict(data["probability"]),
                 mc_probability=dict(data["mc_probability"]), samples=int(data["samples"]),
                 method=str(data["method"]), located=[tuple(b) for b in data["located"]])


def _periodic(kind: str) -> bool:
    return kind not in ("none", "failed")


def stochastic_diagram(oscillator: Oscillator | System, parameter: str, values, *,
                       sigma: float, uncertain: str = "mu", distribution=None,
                       samples: int = 256, seed: int = 0,
                       options: SolverOptions | None = None, transient: int = 300,
                       record: int = 64, xtol: float = 1e-10, workers: int = 1,
                       parts: str | None = None, log=None):
    """Attractor types and their probabilities along ``parameter`` (module docstring).

    Parameters
    ----------
    oscillator : the deterministic model (an :class:`opa.Oscillator`, or a System's).
    parameter : the control parameter swept over ``values`` (not the uncertain one).
    sigma, uncertain, distribution : the uncertainty ``p = p_bar + sigma xi`` and the law
        of xi (default the semicircle).
    samples, seed : Monte Carlo samples classified at each value (0: none).
    transient, record : forcing periods dropped, then recorded, by each classification.
    xtol : tolerance of the located boundaries in xi.
    workers : processes of the classification sweeps.
    parts : a folder where each finished control value is kept as it finishes, a
        :class:`opa._dataset.Store` keyed by everything the value depends on; a rerun
        with the same folder reads them back instead of computing them again (an
        interrupted diagram resumes), and a damaged file is set aside, named (``log``,
        else a warning) and computed again. A folder of a version before the store is
        refused, naming it. None: nothing is kept.
    log : callable taking a progress line, or None.

    Returns
    -------
    xarray.Dataset over ``parameter`` and ``type`` (every attractor type seen): the
    probabilities ``probability`` (continuation, or Monte Carlo where it cannot follow),
    ``mc_probability`` and its ``mc_sem``, ``agree`` (1 where every type's two
    probabilities are within 3 binomial SE), ``method`` (0 continuation, 1 sampling);
    over (``parameter``, ``boundary``) the boundaries ``boundary_xi`` and their
    ``boundary_kind``, NaN/"" padded.

    Examples
    --------
    >>> from opa import preset
    >>> ds = stochastic_diagram(preset("3.1", F0=0.0), "c", [0.0396996668], sigma=0.03,
    ...                         samples=0)
    >>> abs(round(float(ds.boundary_xi[0, 0]), 6)), str(ds.boundary_kind.values[0, 0])
    (0.0, 'period-doubling')
    >>> [round(float(p), 6) for p in ds.probability[0].values]   # half and half
    [0.5, 0.5]
    """
    import xarray as xr

    from opa._dataset import Store, package_version, provenance_attrs
    from opa._measure import parse

    if isinstance(oscillator, System):
        oscillator = oscillator.oscillator
    if not isinstance(oscillator, Oscillator):
        raise ValueError(f"oscillator must be an opa.Oscillator or System, got "
                         f"{type(oscillator).__name__}")
    if uncertain not in ("mu", "a", "c"):
        raise ValueError(f"uncertain must be mu, a or c, got {uncertain!r}")
    if parameter == uncertain or not hasattr(oscillator, parameter):
        raise ValueError(f"parameter must be a model parameter other than the uncertain "
                         f"one ({uncertain}), got {parameter!r}")
    if isinstance(sigma, bool) or not (isinstance(sigma, (int, float)) and sigma > 0
                                       and math.isfinite(sigma)):
        raise ValueError(f"sigma must be a positive number, got {sigma!r}")
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) \
            or samples < 0 or samples == 1:
        raise ValueError(f"samples must be 0 or an integer >= 2, got {samples!r}")
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or not len(values) or not np.isfinite(values).all():
        raise ValueError("values must be a non-empty 1-D array of finite numbers")
    options = options or SolverOptions()
    measure = parse(distribution)
    system = System(oscillator, sigma=float(sigma), uncertain=uncertain,
                    distribution=distribution)
    system.check_samples()
    slices = []
    store = None
    if parts is not None:
        store = Store(parts, "stochastic diagram", log=log)
    for i, value in enumerate(values):
        osc = oscillator.replace(**{parameter: float(value)})
        inputs = {"oscillator": osc, "uncertain": uncertain, "sigma": float(sigma),
                  "measure": measure, "samples": int(samples), "seed": seed + i,
                  "options": options, "transient": int(transient), "record": int(record),
                  "xtol": float(xtol), "value": float(value), "version": package_version()}

        def compute(osc=osc, i=i, value=value):
            piece = stochastic_slice(osc, uncertain, float(sigma), measure,
                                     samples=int(samples), seed=seed + i, options=options,
                                     transient=transient, record=record, xtol=xtol,
                                     workers=workers)
            piece.value = float(value)
            return piece

        if store is None:
            piece, reused = compute(), False
        else:
            before = store.computed
            piece = _slice_from_json(store.get(f"slice-{parameter}{value:g}", inputs,
                                               lambda: _slice_to_json(compute()), ".json"))
            reused = store.computed == before
        slices.append(piece)
        if log is not None:
            shown = ", ".join(f"{k} {p:.3f}" for k, p in sorted(piece.probability.items()))
            log(f"{i + 1}/{len(values)} {parameter} = {value:g}: {shown} ({piece.method}"
                f"{', read back' if reused else ''})")
    kinds = sorted({k for s in slices for k in (*s.probability, *s.mc_probability)},
                   key=_type_order)
    P = np.array([[s.probability.get(k, 0.0) for k in kinds] for s in slices])
    M = np.array([[s.mc_probability.get(k, 0.0) for k in kinds] for s in slices])
    n = np.array([s.samples for s in slices], dtype=float)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        sem = np.where(n > 0, np.sqrt(P * (1 - P) / n), np.nan)
        # a type of probability 0 or 1 has no binomial spread: one sample off is allowed
        tol = np.where(n > 0, np.maximum(AGREEMENT_SE * sem, 1.0 / n), np.nan)
    agree = np.where(n[:, 0] > 0, np.all(np.abs(P - M) <= tol, axis=1), -1).astype(np.int8)
    B = max([len(s.boundaries) for s in slices] + [0])
    bxi = np.full((len(slices), B), np.nan)
    bkind = np.full((len(slices), B), "", dtype=object)
    for i, s in enumerate(slices):
        for j, (x, k) in enumerate(s.boundaries):
            bxi[i, j], bkind[i, j] = x, k
    one = {"units": "1"}
    ds = xr.Dataset(
        {
            "probability": ((parameter, "type"), P, {
                "long_name": "probability of each attractor type (law mass between the "
                "located boundaries, or Monte Carlo where continuation cannot follow)",
                **one}),
            "mc_probability": ((parameter, "type"), M, {
                "long_name": "share of the Monte Carlo samples on each type", **one}),
            "mc_sem": ((parameter, "type"), sem, {
                "long_name": "binomial standard error sqrt(p (1 - p) / M)", **one}),
            "agree": (parameter, agree, {
                "long_name": "1 where every type's probability is within 3 binomial SE "
                "(or one sample) of the Monte Carlo share; -1 without samples", **one}),
            "method": (parameter, np.array([s.method == "sampling" for s in slices],
                                           dtype=np.int8),
                       {"long_name": "0: continuation in xi; 1: Monte Carlo sampling",
                        **one}),
            "boundary_xi": ((parameter, "boundary"), bxi, {
                "long_name": "xi where the attractor type changes (located bifurcation)",
                **one}),
            "boundary_kind": ((parameter, "boundary"), bkind.astype(str), {
                "long_name": "the bifurcation at the boundary"}),
        },
        coords={parameter: (parameter, values, {"long_name": f"control parameter "
                                                 f"{parameter}", **one}),
                "type": ("type", np.array(kinds, dtype=str),
                         {"long_name": "attractor type: period label z = n/p (n forcing "
                          "periods, p impacts), none, failed"}),
                "boundary": ("boundary", np.arange(B), {"long_name": "boundary index",
                                                        **one})},
        attrs=provenance_attrs("stochastic", system, options, seed=seed),
    )
    ds.attrs.update(distribution=measure.name, sweep_parameter=parameter,
                    samples=int(samples), transient=int(transient), record=int(record),
                    xtol=float(xtol))
    return ds


def _type_order(kind: str):
    if "/" in kind:
        n, p = kind.split("/")
        return (0, int(n), int(p))
    return (1, 0, kind)


__all__ = ["AGREEMENT_SE", "Slice", "classify", "stochastic_diagram", "stochastic_slice"]
