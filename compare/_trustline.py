r"""Where OPA can be trusted with several uncertain parameters: the trust line.

With d uncertain parameters the intensity is one scale s along a fixed vector of
relative sizes r: :math:`\sigma_j = s\, r_j\, |\bar p_j|` (``relative``: r_j, the size of
parameter j's spread relative to its nominal value at s = 1). At each scale of a grid
the OPA variants run, each is certified against the true sampled systems by
:func:`compare.verify` (paired Monte Carlo on replicated Sobol' points with the run as
control variate, :mod:`compare._verify_several`), and

    s* = the largest scale of the grid at which the variant agrees, every smaller scale
         of the grid agreeing too (0 when the smallest does not).

The variants: the single-element OPA of order N with the paper's ``mean`` impact law and
with the ``saltation`` law, and adaptive boxes (``opa._boxes``, saltation law). No
bisection refines s* between grid points: each verdict costs a certificate, and the
trust boundary in d dimensions is not a point (the one-parameter map of
:mod:`compare._trustmap` locates it by bisection; its split scans and strata are
one-dimensional).
"""

from __future__ import annotations

import math
import time

import numpy as np
import xarray as xr

from compare._verify import verify
from opa.engine import SolverOptions, System, provenance_attrs

#: the variants of the trust line: (name, impact law, elements)
LINE_VARIANTS = (("OPA mean", "mean", None), ("OPA saltation", "saltation", None),
            ("adaptive boxes", "saltation", "adaptive"))
#: the verdicts' codes in the dataset
CODES = {"agrees": 0, "disagrees": 1, "undecided": 2, "failed": 3}


def scaled(system: System, relative, scale: float) -> System:
    """``system`` with sigma_j = scale r_j |p_bar_j| (``relative``: the r_j)."""
    problem = system.problem
    relative = tuple(float(r) for r in relative)
    if len(relative) != problem.dimension or not all(
            math.isfinite(r) and r > 0 for r in relative):
        raise ValueError(f"relative must give one positive size per uncertain parameter "
                         f"({problem.dimension}), got {relative}")
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"each scale must be a positive number, got {scale}")
    means = [abs(system.oscillator.value(n)) for n in problem.names]
    if not all(means):
        zero = [n for n, m in zip(problem.names, means) if not m]
        raise ValueError(f"relative sizes need nonzero nominal values; {','.join(zero)} = 0")
    return system.replace(sigma=tuple(scale * r * m for r, m in zip(relative, means)))


def trust_line(system: System, relative, scales, *, periods: float = 10,
               per_period: int = 8, samples: int = 256, max_samples: int = 4096,
               seed: int = 0, max_elements: int = 64, options: SolverOptions | None = None,
               log=None) -> xr.Dataset:
    """The verdict of each OPA variant at each scale along ``relative`` and its s*.

    Returns a dataset with dims (variant, scale): ``verdict`` (codes of ``CODES``),
    ``verdict_mean``, ``verdict_var``, ``err_mean_rms`` and ``err_var_rms`` (the paired
    estimates' RMS over the outputs), ``true_systems`` (the certificate's), ``elements``;
    ``scale_star`` (variant), and attributes with the problem and the rule.

    Examples
    --------
    >>> import opa
    >>> s = opa.System(opa.preset("3.2", omega=3.98), uncertain="mu,c", order=2)
    >>> scaled(s, (0.02, 0.1), 1.0).sigma
    (0.016, 0.005000000000000001)
    """
    options = SolverOptions() if options is None else options
    scales = sorted(float(s) for s in scales)
    if not scales or len(set(scales)) != len(scales):
        raise ValueError(f"scales must be distinct positive numbers, got {scales}")
    systems = [scaled(system, relative, s) for s in scales]  # every input checked first
    shape = (len(LINE_VARIANTS), len(scales))
    data = {name: np.full(shape, fill, dtype=kind) for name, fill, kind in (
        ("verdict", 2, np.int8), ("verdict_mean", 2, np.int8), ("verdict_var", 2, np.int8),
        ("err_mean_rms", np.nan, float), ("err_var_rms", np.nan, float),
        ("true_systems", 0, np.int64), ("elements", 0, np.int64))}
    started = time.perf_counter()
    for j, (scale, at) in enumerate(zip(scales, systems)):
        for i, (name, law, elements) in enumerate(LINE_VARIANTS):
            run = _run(at.replace(impact_law=law), elements, periods, per_period, options,
                       max_elements)
            if run is None:  # the OPA system could not be completed: nothing to certify
                for field in ("verdict", "verdict_mean", "verdict_var"):
                    data[field][i, j] = CODES["failed"]
                if log is not None:
                    log(f"trust line: scale {scale:g}, {name}: the OPA system could not be "
                        f"completed")
                continue
            v = verify(run, samples=samples, max_samples=max_samples, seed=seed,
                       options=options)
            data["verdict"][i, j] = CODES[v.attrs["verdict"]]
            data["verdict_mean"][i, j] = CODES[v.attrs["verdict_mean"]]
            data["verdict_var"][i, j] = CODES[v.attrs["verdict_var"]]
            data["err_mean_rms"][i, j] = float(np.sqrt(np.mean(v.verify_err_mean.values**2)))
            data["err_var_rms"][i, j] = float(np.sqrt(np.mean(v.verify_err_var.values**2)))
            data["true_systems"][i, j] = int(v.attrs["verify_samples"])
            data["elements"][i, j] = int(run.attrs.get("elements", 1))
            if log is not None:
                log(f"trust line: scale {scale:g} ({_sigmas(at)}), {name}: "
                    f"{v.attrs['verdict']} (error of E[x] RMS "
                    f"{data['err_mean_rms'][i, j]:.3g}, {v.attrs['verify_samples']} true "
                    f"systems)")
    return _dataset(system, relative, scales, data, options, started)


def _sigmas(system: System) -> str:
    return ", ".join(f"sigma_{n} = {s:.4g}" for n, s in zip(system.problem.names,
                                                            system.problem.scales))


def _run(system, elements, periods, per_period, options, max_elements):
    """The variant's OPA run, or None when its system cannot be completed."""
    import warnings

    from opa import SimulationError, simulate_opa
    from opa.engine import ElementBudgetWarning

    extra = {"max_elements": max_elements} if elements == "adaptive" else {}
    try:
        with warnings.catch_warnings():  # a budget that ran out is said by the verdict
            warnings.simplefilter("ignore", ElementBudgetWarning)
            return simulate_opa(system, periods=periods, per_period=per_period,
                                options=options, elements=elements, **extra)
    except SimulationError:
        return None


def star(verdicts: np.ndarray, scales) -> float:
    """The largest scale at which the verdict agrees with every smaller one agreeing
    (0.0 when the smallest does not).

    >>> star(np.array([0, 0, 2, 0]), [0.25, 0.5, 1.0, 2.0])
    0.5
    """
    best = 0.0
    for code, scale in zip(verdicts, scales):
        if code != CODES["agrees"]:
            break
        best = scale
    return best


def _dataset(system, relative, scales, data, options, started) -> xr.Dataset:
    names = [name for name, _, _ in LINE_VARIANTS]
    codes = " ".join(CODES)
    ds = xr.Dataset(
        {name: (("variant", "scale"), values, {
            "long_name": _LONG_NAMES[name], "units": "1",
            **({"flag_values": np.arange(len(CODES), dtype=np.int8), "flag_meanings": codes}
               if name.startswith("verdict") else {})})
         for name, values in data.items()},
        coords={"variant": ("variant", names), "scale": ("scale", np.asarray(scales))},
        attrs=provenance_attrs("trust-line", scaled(system, relative, 1.0), options))
    ds.variant.attrs.update(long_name="the OPA variant: one element with the mean or the "
                                      "saltation impact law, or adaptive boxes", units="1")
    ds.scale.attrs.update(long_name="the scale s of sigma_j = s x relative_j x abs(p_bar_j)",
                          units="1")
    ds["scale_star"] = ("variant", np.array([star(data["verdict"][i], scales)
                                             for i in range(len(names))]), {
        "long_name": "largest scale of the grid at which the variant agrees, every smaller "
                     "one agreeing (0: not even the smallest)", "units": "1"})
    ds.attrs.update(relative=np.asarray(relative, dtype=float),
                    sigma_rule="sigma_j = scale x relative_j x |p_bar_j|",
                    wall_seconds=float(time.perf_counter() - started))
    return ds


_LONG_NAMES = {
    "verdict": "the certificate's verdict on the run (agrees, disagrees, undecided; failed: "
               "the OPA system could not be completed)",
    "verdict_mean": "the certificate's verdict on E[x]",
    "verdict_var": "the certificate's verdict on Var[x]",
    "err_mean_rms": "RMS over the outputs of the paired estimate of the error of E[x]",
    "err_var_rms": "RMS over the outputs of the paired estimate of the error of Var[x]",
    "true_systems": "true sampled systems the certificate ran",
    "elements": "elements (boxes) of the OPA run",
}
