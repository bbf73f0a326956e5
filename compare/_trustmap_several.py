r"""The trust map of several uncertain parameters: trust lines over a model parameter's
values and over horizons, with s* refined by bisection.

With d uncertain parameters the intensity is one scale s along the fixed relative sizes
r (:func:`compare._trustline.scaled`: :math:`\sigma_j = s\, r_j\, |\bar p_j|`). At each
value of a model parameter (``parameter``, e.g. omega) and each horizon (the run's
length in forcing periods) the trust line certifies each OPA variant at each scale of
the grid (:func:`compare._trustline.trust_line`), and

    s*(value, horizon, variant) = the largest scale of the grid at which the variant
                                  agrees, every smaller scale agreeing too.

With ``resolution`` the grid's s* at the longest horizon is refined by bisection: between
s* and the next scale of the grid (the first that does not agree) the midpoint is run and
certified, and the half that holds the change kept, until the interval is narrower than
``resolution``. A midpoint that is undecided counts as not agreeing (the lower end stays a
scale at which the variant was certified to agree). The result is the interval
(``scale_star_lower``, ``scale_star_upper``) that holds the change of verdict; its lower
end is a certified scale, its upper end one that was not (inf when every scale of the
grid agrees: there is nothing to bisect).

What stays one-dimensional (the map of one uncertain parameter, :mod:`compare._trustmap`):
the split scans along xi, the strata at the splits and the frontier; in d dimensions the
changes of the impact sequence are not points.
"""

from __future__ import annotations

import math
import time

import numpy as np
import xarray as xr

from compare._trustline import CODES, LINE_VARIANTS, _run, scaled, trust_line
from compare._verify import verify
from opa.engine import PARAMETER_NAMES, SolverOptions, System


def trust_map_several(system: System, relative, scales, *, parameter: str = "omega",
                      values=None, horizons=(10.0,), resolution: float | None = None,
                      log=None, **line) -> xr.Dataset:
    """The trust lines of ``system`` at each of ``values`` of ``parameter`` (default: its
    own value) and each horizon, with s* per (value, horizon, variant) and, with
    ``resolution``, the bisected interval of s* at the longest horizon per (value,
    variant). ``line``: the trust line's run and certificate settings (``per_period``,
    ``samples``, ``max_samples``, ``seed``, ``max_elements``, ``options``: those of
    :func:`compare.trust_line`). Every input is checked before any run
    (:func:`check_map_several`).

    Returns a dataset with dims (``parameter``, horizon, variant, scale): ``verdict``,
    ``verdict_mean``, ``verdict_var``, ``err_mean_rms``, ``err_var_rms``,
    ``true_systems``, ``elements`` (as :func:`trust_line`'s); ``scale_star`` (parameter,
    horizon, variant); ``scale_star_lower``, ``scale_star_upper`` and ``bisection_steps``
    (parameter, variant).
    """
    rule = {**LINE_DEFAULTS, **line}
    unknown = sorted(set(rule) - set(LINE_DEFAULTS))
    if unknown:
        raise ValueError(f"unknown trust line setting {unknown[0]!r}")
    rule["options"] = SolverOptions() if rule["options"] is None else rule["options"]
    at_values, horizons = check_map_several(system, relative, scales, parameter, values,
                                            horizons, resolution)
    started = time.perf_counter()
    lines = []
    for value, at in at_values:
        per_horizon = [trust_line(at, relative, scales, periods=h, log=log, **rule)
                       for h in horizons]
        one = xr.concat(per_horizon, dim=xr.DataArray(list(horizons), dims="horizon"),
                        combine_attrs="override")
        lower, upper, steps = _bisected(at, relative, one.isel(horizon=-1), resolution,
                                        dict(rule, periods=horizons[-1]), log)
        one["scale_star_lower"] = ("variant", lower)
        one["scale_star_upper"] = ("variant", upper)
        one["bisection_steps"] = ("variant", steps)
        lines.append(one)
    ds = xr.concat(lines, dim=xr.DataArray([v for v, _ in at_values], dims=parameter),
                   combine_attrs="override")
    for name, text in _LONG_NAMES.items():
        ds[name].attrs.update(long_name=text, units="1")
    ds[parameter].attrs.update(long_name=f"the model parameter {parameter}", units="1")
    ds.horizon.attrs.update(long_name="the run's length (forcing periods)", units="1")
    ds.attrs.pop(parameter, None)  # the first value's: the coordinate holds them all
    ds.attrs.update(parameter=parameter, resolution=-1.0 if resolution is None
                    else float(resolution), wall_seconds=time.perf_counter() - started)
    return ds


#: the trust line's settings and their defaults (:func:`compare.trust_line`'s)
LINE_DEFAULTS = dict(per_period=8, samples=256, max_samples=4096, seed=0, max_elements=64,
                     options=None)


def check_map_several(system, relative, scales, parameter="omega", values=None,
                      horizons=(10.0,), resolution=None):
    """Every input of :func:`trust_map_several` checked (a ``ValueError`` naming it):
    returns [(value, the system at that value)] and the sorted horizons; every scale's
    samples are checked at every value."""
    if parameter not in PARAMETER_NAMES or parameter in ("x0", "v0"):
        raise ValueError(f"parameter must be a model parameter, got {parameter!r:.40}")
    if parameter in system.problem.names:
        raise ValueError(f"the swept parameter {parameter!r} is one of the uncertain ones")
    values = (system.oscillator.value(parameter),) if values is None else tuple(
        float(v) for v in values)
    if not values or len(set(values)) != len(values):
        raise ValueError(f"values must be distinct numbers, got {values}")
    horizons = tuple(sorted(float(h) for h in horizons))
    if not horizons or len(set(horizons)) != len(horizons) or not all(
            math.isfinite(h) and h > 0 for h in horizons):
        raise ValueError(f"horizons must be distinct positive numbers, got {horizons}")
    if resolution is not None and not (isinstance(resolution, (int, float))
                                       and math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"resolution must be a positive number, got {resolution!r}")
    at_values = []
    for value in values:
        try:
            at = system.replace(**{parameter: value})
        except ValueError as err:
            raise ValueError(f"{parameter} = {value:g}: {err}") from None
        for scale in scales:
            scaled(at, relative, float(scale)).check_samples()
        at_values.append((value, at))
    return at_values, horizons


def _bisected(system, relative, line, resolution, run_kw, log):
    """(lower, upper, steps) per variant: the interval holding the change of verdict."""
    scales = [float(s) for s in line.scale.values]
    n = len(LINE_VARIANTS)
    lower, upper, steps = np.zeros(n), np.full(n, np.inf), np.zeros(n, dtype=np.int64)
    for i in range(n):
        verdicts = line.verdict.values[i]
        agreed = 0
        while agreed < len(scales) and verdicts[agreed] == CODES["agrees"]:
            agreed += 1
        lower[i] = scales[agreed - 1] if agreed else 0.0
        upper[i] = scales[agreed] if agreed < len(scales) else np.inf
        if resolution is None or not agreed or agreed == len(scales):
            continue  # nothing below the grid is certified; nothing above it to bisect
        while upper[i] - lower[i] > resolution:
            mid = math.sqrt(lower[i] * upper[i])
            ok = _agrees(system, relative, mid, LINE_VARIANTS[i], run_kw)
            steps[i] += 1
            if ok:
                lower[i] = mid
            else:
                upper[i] = mid
            if log is not None:
                log(f"trust map: bisection of s* for {LINE_VARIANTS[i][0]}: scale {mid:.4g} "
                    f"{'agrees' if ok else 'does not agree'}")
    return lower, upper, steps


def _agrees(system, relative, scale, variant, run_kw) -> bool:
    """Whether the variant's run at ``scale`` is certified to agree."""
    _, law, elements = variant
    kw = dict(run_kw)
    run = _run(scaled(system, relative, scale).replace(impact_law=law), elements,
               kw.pop("periods"), kw.pop("per_period"), kw["options"], kw.pop("max_elements"))
    if run is None:
        return False
    return verify(run, **kw).attrs["verdict"] == "agrees"


_LONG_NAMES = {
    "scale_star": "largest scale of the grid at which the variant agrees, every smaller one "
                  "agreeing (0: not even the smallest)",
    "scale_star_lower": "lower end of the bisected interval of s* at the longest horizon: "
                        "a scale certified to agree (0: none)",
    "scale_star_upper": "upper end of that interval: a scale not certified to agree (inf: "
                        "every scale of the grid agrees)",
    "bisection_steps": "certified midpoints the bisection ran",
}

__all__ = ["LINE_DEFAULTS", "check_map_several", "trust_map_several"]
