"""Poincaré sections of a run and what can be read off them (paper section 3).

Two sections, as in the paper's Figs. 3, 9 and 10:

- the **phase plane** (stroboscopic map): the state ``(x, x')`` at ``t_k = k 2 pi / omega``;
- the **constraint plane** ``H = {x = delta}``: at every impact, the forcing phase
  ``omega t mod 2 pi`` and the pre-impact velocity ``x'(t-) > 0``.

From them: the smallest stroboscopic repeat ``p`` (0 if none within the tolerance), the
impacts per repeat and the paper's label ``z = n/p`` (``n`` forcing periods, ``p`` impacts:
a "4/4" motion repeats after 4 forcing periods with 4 impacts), grazing (an impact with
velocity going to 0, or a free-flight maximum of ``x`` reaching ``delta`` without an
impact) and period doubling along a sweep (period ``p -> 2p`` between neighbours).

The module has two layers: array functions (``detect_period``, ``free_flight_maxima``,
``period_doubling``, ...) that never see xarray, and labelled wrappers
(``phase_section``, ``constraint_section``, ``identify_motion``) that take the ``dmr``,
``opa`` and ``mc`` datasets of docs/datasets.md. For the OPA system the sections are those
of the mean ``x_0`` (the EMR); for a Monte Carlo ensemble those of the mean path, which
has no impacts of its own (each sample hits the wall at its own time).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from opa._lazy import lazy
from opa._model import _finite
from opa._system import impulse_schedule

xr = lazy("xarray")

#: default relative tolerance of the stroboscopic repeat, see ``detect_period``
PERIOD_TOL = 1e-4
#: an impact slower than this counts as grazing
MOTION_GRAZE_VELOCITY = 1e-2
#: a free-flight maximum of x closer than this to the wall counts as grazing
MOTION_GRAZE_GAP = 1e-4
#: relative tolerance deciding that an output time is a stroboscopic time k 2 pi / omega
_STROBE_TOL = 1e-9


def _optional_time(name: str, value) -> float | None:
    """None, or ``value`` as a finite float (a NaN bound would silently select nothing)."""
    return None if value is None else _finite(name, value)


# --------------------------------------------------------------------------- array layer


def repeat_distance(points: np.ndarray, shift: int) -> float:
    """Largest distance between section points ``shift`` apart, relative to their size.

    Parameters
    ----------
    points : (K, d) section points in time order (e.g. columns x, x').
    shift : the candidate period p >= 1, p < K.

    Returns
    -------
    ``max_k max_j |s[k+p, j] - s[k, j]| / max(max |s|, 1e-300)``.
    """
    points = np.asarray(points, dtype=float)
    diff = np.abs(points[shift:] - points[:-shift]).max()
    return float(diff / max(float(np.abs(points).max()), 1e-300))


def detect_period(
    x: np.ndarray, v: np.ndarray, *, tol: float = PERIOD_TOL, max_period: int | None = None
) -> tuple[int, float, int]:
    """Smallest stroboscopic repeat of a sequence of section points.

    A sequence ``s_k = (x_k, v_k)`` (states at ``t_k = k 2 pi/omega`` after the transient)
    has period ``p`` when ``|s_{k+p} - s_k| <= tol * max|s|`` for every k, checked over at
    least two repeats (``p <= K/2``).

    Parameters
    ----------
    x, v : (K,) stroboscopic samples.
    tol : relative tolerance (default 1e-4).
    max_period : largest p tried (default K // 2).

    Returns
    -------
    (period, residual, nearest): ``period`` is the smallest p within ``tol``, 0 if none;
    ``residual`` is the relative repeat distance at ``period`` (or at ``nearest``, the p
    with the smallest distance, when there is none); NaN when the samples are not finite.

    Examples
    --------
    >>> k = np.arange(40)
    >>> detect_period(np.cos(np.pi * k / 2), np.sin(np.pi * k / 2))[0]
    4
    """
    points = np.column_stack([np.asarray(x, dtype=float), np.asarray(v, dtype=float)])
    K = len(points)
    limit = K // 2 if max_period is None else min(int(max_period), K // 2)
    if K < 2 or limit < 1 or not np.all(np.isfinite(points)):
        return 0, math.nan, 0
    best, best_p = math.inf, 0
    for p in range(1, limit + 1):
        d = repeat_distance(points, p)
        if d <= tol:
            return p, d, p
        if d < best:
            best, best_p = d, p
    return 0, best, best_p


def impacts_per_period(
    impact_times: np.ndarray, end: float, forcing_period: float, period: int, repeats: int
) -> int:
    """Impacts in one repeat of a period-``period`` motion, -1 if the count is not steady.

    Counts the impacts in each of the last ``repeats`` windows
    ``(end - (i+1) p T, end - i p T]``; a periodic motion has the same count in every
    window. Impacts within 1e-9 T of a window edge are counted in the later window, so
    an impact at a stroboscopic time is not lost to round-off.
    """
    if period < 1 or repeats < 1:
        return -1
    width = period * forcing_period
    edges = end - width * np.arange(repeats, -1, -1)
    shifted = np.asarray(impact_times, dtype=float) + 1e-9 * forcing_period
    counts = np.histogram(shifted, bins=edges)[0]
    return int(counts[0]) if np.all(counts == counts[0]) else -1


def period_label(period: int, impacts: int) -> str:
    """The paper's ``z = n/p``: "n/p" for n forcing periods with p impacts, else "none".

    >>> period_label(6, 2)
    '6/2'
    """
    if period < 1:
        return "none"
    return f"{period}/{impacts}" if impacts >= 0 else f"{period}/?"


def free_flight_maxima(
    t: np.ndarray, x: np.ndarray, v: np.ndarray, breaks: np.ndarray = ()
) -> tuple[np.ndarray, np.ndarray]:
    """Local maxima of x between outputs, by cubic Hermite interpolation of (x, x').

    An output interval ``(t_i, t_{i+1}]`` with ``x'_i > 0 >= x'_{i+1}`` holds a maximum;
    the Hermite cubic through ``x, x'`` at both ends locates it with error O(h^4).
    Intervals containing a break (impact, impulse, start or end of sticking) are skipped:
    the velocity jumps there and the maximum is the impact itself, not a free flight.

    Returns
    -------
    (times, values) of the maxima.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    v = np.asarray(v, dtype=float)
    if len(t) < 2:
        return np.zeros(0), np.zeros(0)
    t0, t1 = t[:-1], t[1:]
    cand = (v[:-1] > 0.0) & (v[1:] <= 0.0) & np.isfinite(x[:-1]) & np.isfinite(x[1:])
    breaks = np.sort(np.asarray(breaks, dtype=float))
    if len(breaks):
        # intervals (t0, t1] holding a break
        first = np.searchsorted(breaks, t0, side="right")
        cand &= ~((first < len(breaks)) & (breaks[np.minimum(first, len(breaks) - 1)] <= t1))
    i = np.flatnonzero(cand)
    h = t1[i] - t0[i]
    x0, x1 = x[i], x[i + 1]
    d0, d1 = h * v[i], h * v[i + 1]
    # d/ds of the Hermite cubic on s in [0, 1]: A s^2 + B s + C, C = d0 > 0 >= A + B + C
    A = 6 * x0 + 3 * d0 - 6 * x1 + 3 * d1
    B = -6 * x0 - 4 * d0 + 6 * x1 - 2 * d1
    C = d0
    s = _first_root_in_unit(A, B, C)
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    return t0[i] + s * h, h00 * x0 + h10 * d0 + h01 * x1 + h11 * d1


def _first_root_in_unit(A, B, C):
    """Smallest root in (0, 1] of A s^2 + B s + C with C > 0 >= A + B + C (vectorised)."""
    s = np.ones_like(C)
    linear = np.abs(A) <= 1e-12 * (np.abs(B) + np.abs(C))
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(linear & (B != 0), -C / np.where(B == 0, 1, B), s)
        disc = np.sqrt(np.maximum(B * B - 4 * A * C, 0.0))
        # numerically stable pair of roots
        q = -0.5 * (B + np.copysign(disc, B))
        r1 = np.where(A != 0, q / np.where(A == 0, 1, A), np.inf)
        r2 = np.where(q != 0, C / np.where(q == 0, 1, q), np.inf)
        r1 = np.where((r1 > 0) & (r1 <= 1 + 1e-12), r1, np.inf)
        r2 = np.where((r2 > 0) & (r2 <= 1 + 1e-12), r2, np.inf)
        quad = np.minimum(r1, r2)
    s = np.where(linear, s, np.where(np.isfinite(quad), quad, 1.0))
    return np.clip(s, 0.0, 1.0)


def period_doubling(periods: np.ndarray) -> np.ndarray:
    """1 where the period is twice a neighbour's (p -> 2p along the sweep), else 0.

    ``periods`` is in parameter order; 0 (no period) never takes part. The flag sits on
    the doubled side, so it reads the same for forward and backward sweeps.

    >>> period_doubling(np.array([3, 3, 6, 6, 0, 12])).tolist()
    [0, 0, 1, 0, 0, 0]
    """
    periods = np.asarray(periods, dtype=np.int64)
    flag = np.zeros(len(periods), dtype=np.int8)
    for i in range(len(periods)):
        for j in (i - 1, i + 1):
            if 0 <= j < len(periods) and periods[j] > 0 and periods[i] == 2 * periods[j]:
                flag[i] = 1
    return flag


def grazing_points(values: np.ndarray, period: np.ndarray, impacts: np.ndarray,
                   min_impact_velocity: np.ndarray, min_gap: np.ndarray) -> np.ndarray:
    """Parameter values where a branch of periodic motions crosses a grazing.

    Along a branch of periodic motions the number of impacts per forcing period changes
    only where an impact appears or disappears, i.e. at a grazing (a free-flight maximum
    reaching the wall with zero velocity, or a minimum the lower wall). Such a change
    between two periodic neighbours is reported, located by the square law near a graze:
    on the impacting side the new impact has ``v^2 ~ |p - p_g|``, on the other side the
    nearest free flight has ``gap ~ |p - p_g|``; with ``g = gap`` on one side and ``g = -v^2/2`` on
    the other, the linear root of ``g`` is taken (the midpoint when either is missing).
    Grazings inside non-periodic ranges are not located (see the per-value ``grazing``
    flag and ``min_impact_velocity`` there).

    Parameters
    ----------
    values : (P,) increasing parameter values; ``period``, ``impacts`` (per period),
        ``min_impact_velocity``, ``min_gap`` per value (NaN where undefined); with a lower
        wall, ``min_gap`` is the nearer wall's (``Motion.nearest_gap``).

    Returns
    -------
    Estimated grazing parameter values, increasing.

    >>> grazing_points(np.array([1.0, 2.0]), np.array([2, 2]), np.array([2, 3]),
    ...                np.array([0.5, 0.1]), np.array([0.01, np.nan])).round(3).tolist()
    [1.667]
    """
    values = np.asarray(values, dtype=float)
    period = np.asarray(period)
    impacts = np.asarray(impacts)
    vmin = np.asarray(min_impact_velocity, dtype=float)
    gap = np.asarray(min_gap, dtype=float)
    found = []
    for a in range(len(values) - 1):
        b = a + 1
        if min(period[a], period[b]) < 1 or min(impacts[a], impacts[b]) < 0:
            continue
        rate_a, rate_b = impacts[a] / period[a], impacts[b] / period[b]
        if rate_a == rate_b:
            continue
        imp, free = (a, b) if rate_a > rate_b else (b, a)
        g_free, g_imp = gap[free], -0.5 * vmin[imp] ** 2
        if np.isfinite(g_free) and np.isfinite(g_imp) and g_free > 0 > g_imp:
            w = g_free / (g_free - g_imp)
            found.append(values[free] + w * (values[imp] - values[free]))
        else:
            found.append(0.5 * (values[a] + values[b]))
    return np.array(found)


def stroboscopic_mask(t: np.ndarray, forcing_period: float, start: float | None = None,
                      end: float | None = None) -> np.ndarray:
    """True at outputs on stroboscopic times ``k 2 pi/omega`` within ``(start, end]``."""
    start, end = _optional_time("start", start), _optional_time("end", end)
    if not (math.isfinite(forcing_period) and forcing_period > 0):
        raise ValueError(f"forcing_period must be finite and > 0, got {forcing_period}")
    t = np.asarray(t, dtype=float)
    k = t / forcing_period
    mask = np.abs(k - np.round(k)) <= _STROBE_TOL * np.maximum(1.0, np.abs(k))
    if start is not None:
        mask &= t > start + 1e-9 * forcing_period
    if end is not None:
        mask &= t <= end + 1e-9 * forcing_period
    return mask


def impulse_times(t_end: float, omega1: float, *, impulse_at_zero: bool = True) -> np.ndarray:
    """Impulse times ``j 2 pi/omega1`` up to ``t_end``: ``opa._system.impulse_schedule``,
    the one place the schedule is computed."""
    return impulse_schedule(_finite("t_end", t_end), omega1, at_zero=impulse_at_zero)


def sticking_mask(t: np.ndarray, stick_time: np.ndarray, release_time: np.ndarray
                  ) -> np.ndarray:
    """True at output times inside a sticking phase [stick, next release]."""
    t = np.asarray(t, dtype=float)
    mask = np.zeros(len(t), dtype=bool)
    releases = np.sort(np.asarray(release_time, dtype=float))
    for ts in np.asarray(stick_time, dtype=float):
        later = releases[releases >= ts]
        mask |= (t >= ts) & (t <= (later[0] if len(later) else np.inf))
    return mask


@dataclass(frozen=True)
class Motion:
    """What a run's sections say about its motion after the transient.

    Attributes
    ----------
    period : smallest stroboscopic repeat p (forcing periods), 0 if none within tol.
    impacts : impacts per repeat, -1 when there is no period, no impact record (MC mean)
        or the count differs between repeats.
    label : the paper's z = n/p, e.g. "4/4"; "none" without a period.
    residual : relative repeat distance at ``period`` (or at ``nearest_period``).
    nearest_period : the p with the smallest repeat distance (== period when periodic).
    impact_rate : impacts per forcing period over the record (NaN for MC means).
    min_impact_velocity : slowest impact in the record (NaN if none).
    min_gap : ``delta`` minus the highest free-flight maximum of x (NaN if none or if the
        outputs are too sparse to resolve maxima, fewer than 8 per period).
    grazing : 1 if an impact (at either wall) is slower than ``graze_velocity`` or a free
        flight comes within ``graze_gap`` of a wall (``min_gap`` or ``min_gap_lower``),
        else 0.
    min_gap_lower : with a lower wall, the lowest free-flight minimum of x minus
        ``delta_minus`` (NaN as for ``min_gap``, and without a lower wall).
    """

    period: int
    impacts: int
    label: str
    residual: float
    nearest_period: int
    impact_rate: float
    min_impact_velocity: float
    min_gap: float
    grazing: int
    min_gap_lower: float = math.nan

    @property
    def nearest_gap(self) -> float:
        """The smaller of the two walls' gaps (``min_gap`` with one wall; NaN: none)."""
        return float(np.fmin(self.min_gap, self.min_gap_lower))

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class MotionTolerances:
    """The thresholds that name a motion (:func:`identify`, :func:`identify_motion`).

    Parameters
    ----------
    period_tol : relative stroboscopic repeat distance below which a period is taken.
    max_period : the longest period looked for (None: half the recorded periods).
    graze_velocity, graze_gap : a motion grazes where an impact is slower than
        ``graze_velocity`` or a free flight comes within ``graze_gap`` of a wall (either
        of two).
    """

    period_tol: float = PERIOD_TOL
    max_period: int | None = None
    graze_velocity: float = MOTION_GRAZE_VELOCITY
    graze_gap: float = MOTION_GRAZE_GAP

    def __post_init__(self):
        for name in ("period_tol", "graze_velocity", "graze_gap"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
                    or not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0, got {value!r}")
        if self.max_period is not None and (
                isinstance(self.max_period, bool)
                or not isinstance(self.max_period, (int, np.integer)) or self.max_period < 1):
            raise ValueError(f"max_period must be None or an integer >= 1, got "
                             f"{self.max_period!r}")


def identify(
    t: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    *,
    forcing_period: float,
    delta: float,
    start: float | None = None,
    impact_time: np.ndarray | None = None,
    impact_velocity: np.ndarray | None = None,
    breaks: np.ndarray = (),
    sticking: np.ndarray | None = None,
    tolerances: MotionTolerances | None = None,
    delta_minus: float = -math.inf,
) -> Motion:
    """Array form of ``identify_motion``: outputs ``t, x, v`` (n,), impacts (m,) or None
    when the run has no impact record (MC mean), ``breaks`` the times where the velocity
    or force jumps, ``sticking`` (n,) True while resting on the wall; ``tolerances`` the
    period and grazing thresholds (:class:`MotionTolerances`, default its defaults);
    ``delta_minus`` a lower wall (-inf: none), whose gap is that of the free-flight
    minima of x."""
    tol = MotionTolerances() if tolerances is None else tolerances
    period_tol, max_period = tol.period_tol, tol.max_period
    graze_velocity, graze_gap = tol.graze_velocity, tol.graze_gap
    t = np.asarray(t, dtype=float)
    T = float(forcing_period)
    start = _optional_time("start", start)
    lo = float(t[0]) if start is None else start
    hi = float(t[-1])
    strobe = stroboscopic_mask(t, T, start)
    period, residual, nearest = detect_period(x[strobe], v[strobe], tol=period_tol,
                                              max_period=max_period)
    span = max((hi - lo) / T, 1e-300)
    if impact_time is not None:
        ti = np.asarray(impact_time, dtype=float)
        window = (ti <= hi) & ((ti > lo) if start is not None else True)
        rec, vi = ti[window], np.asarray(impact_velocity, dtype=float)[window]
        repeats = round(span) // period if period else 0
        impacts = impacts_per_period(rec, hi, T, period, repeats)
        rate = len(rec) / span
        vmin = float(np.min(np.abs(vi))) if len(vi) else math.nan
    else:
        impacts, rate, vmin = -1, math.nan, math.nan
    in_rec = (t >= lo) & (t <= hi)
    gap = gap_lower = math.nan
    if (np.count_nonzero(in_rec) - 1) / span >= 8:
        free = in_rec if sticking is None else in_rec & ~np.asarray(sticking, dtype=bool)
        _, xm = free_flight_maxima(t[free], x[free], v[free], breaks)
        if len(xm):
            gap = float(delta - xm.max())
        if delta_minus > -math.inf:  # the minima of x are the maxima of -x
            _, negated = free_flight_maxima(t[free], -x[free], -v[free], breaks)
            if len(negated):
                gap_lower = float(-negated.max() - delta_minus)
    graze = int((np.isfinite(vmin) and vmin < graze_velocity)
                or (np.isfinite(gap) and gap < graze_gap)
                or (np.isfinite(gap_lower) and gap_lower < graze_gap))
    return Motion(period=int(period), impacts=int(impacts),
                  label=period_label(period, impacts), residual=float(residual),
                  nearest_period=int(nearest), impact_rate=float(rate),
                  min_impact_velocity=vmin, min_gap=gap, grazing=graze,
                  min_gap_lower=gap_lower)


# --------------------------------------------------------------------------- labelled layer


def mean_state(ds: xr.Dataset) -> tuple[np.ndarray, np.ndarray, str]:
    """The observed coordinate pair of a run: DMR ``(x, v)``, EMR ``(x_0, v_0)`` or the
    Monte Carlo mean, and its name."""
    if "x" in ds and "sample" not in ds.x.dims:
        return ds.x.values, ds.v.values, "DMR"
    if "x_coef" in ds and ds.attrs.get("model") == "opa":
        name = "EMR_0" if float(ds.attrs.get("sigma", 0.0)) == 0.0 else "EMR"
        return ds.x_coef.values[0], ds.v_coef.values[0], name
    if "x_mean" in ds:
        return ds.x_mean.values, ds.v_mean.values, "MC mean"
    raise ValueError("expected a dmr, opa or mc dataset (variables x/v, x_coef/v_coef or "
                     f"x_mean/v_mean), got variables {sorted(ds.data_vars)}")


def _forcing_period(ds: xr.Dataset) -> float:
    return 2.0 * math.pi / float(ds.attrs["omega"])


def phase_section(ds: xr.Dataset, *, start: float | None = None, end: float | None = None
                  ) -> xr.Dataset:
    """Stroboscopic (phase-plane) section: the state at ``t_k = k 2 pi/omega``.

    Only outputs that fall on stroboscopic times and lie in ``(start, end]`` are taken
    (``start``: the end of the transient; default: all of the run).

    Returns
    -------
    Dataset with ``section_x(point)``, ``section_v(point)``, ``section_time(point)``.
    """
    x, v, name = mean_state(ds)
    t = ds.time.values
    keep = stroboscopic_mask(t, _forcing_period(ds), start, end)
    return xr.Dataset(
        {
            "section_x": ("point", x[keep], {"long_name": f"{name} x at t = k 2 pi/omega",
                                             "units": "1"}),
            "section_v": ("point", v[keep], {"long_name": f"{name} dx/dt at t = k 2 pi/omega",
                                             "units": "1"}),
            "section_time": ("point", t[keep], {"long_name": "stroboscopic time",
                                                "units": "1"}),
        }
    )


def constraint_section(ds: xr.Dataset, *, start: float | None = None,
                       end: float | None = None) -> xr.Dataset:
    """Constraint-plane section ``x = delta``: forcing phase and velocity at each impact.

    Returns
    -------
    Dataset with ``impact_phase(point)`` = ``omega t mod 2 pi`` in [0, 2 pi) and
    ``impact_v(point)`` = pre-impact velocity x'(t-) > 0 (the rebound is ``-eta`` times
    it), for the impacts in ``(start, end]``; empty for Monte Carlo means.
    """
    start, end = _optional_time("start", start), _optional_time("end", end)
    if "impact_time" in ds:
        ti = ds.impact_time.values
        vi = ds.impact_velocity.values
        keep = np.ones(len(ti), dtype=bool)
        if start is not None:
            keep &= ti > start
        if end is not None:
            keep &= ti <= end
        ti, vi = ti[keep], vi[keep]
    else:
        ti = vi = np.zeros(0)
    omega = float(ds.attrs["omega"])
    return xr.Dataset(
        {
            "impact_phase": ("point", np.mod(omega * ti, 2 * math.pi),
                             {"long_name": "forcing phase omega t mod 2 pi at impact",
                              "units": "rad"}),
            "impact_v": ("point", vi, {"long_name": "pre-impact velocity x'(t-) at x = delta",
                                       "units": "1"}),
            "impact_time": ("point", ti, {"long_name": "impact time", "units": "1"}),
        }
    )


def run_breaks(ds: xr.Dataset) -> np.ndarray:
    """Times where the velocity or the force of a run jumps: impacts, impulses, pulse
    ends, sticking and release."""
    parts = [ds[name].values for name in ("impact_time", "stick_time", "release_time")
             if name in ds]
    a = ds.attrs
    if float(a.get("F0", 0.0)) != 0.0:
        tj = impulse_times(float(ds.time.values[-1]), float(a["omega1"]),
                           impulse_at_zero=bool(int(a.get("impulse_at_zero", 1))))
        parts.append(tj)
        if a.get("impulse") == "pulse":
            parts.append(tj + float(a.get("pulse_width", 0.0)))
    return np.concatenate(parts) if parts else np.zeros(0)


def identify_motion(
    ds: xr.Dataset,
    *,
    start: float | None = None,
    period_tol: float = PERIOD_TOL,
    max_period: int | None = None,
    graze_velocity: float = MOTION_GRAZE_VELOCITY,
    graze_gap: float = MOTION_GRAZE_GAP,
) -> Motion:
    """Period, impacts per period, label z = n/p and grazing of a run after ``start``.

    Parameters
    ----------
    ds : a ``dmr``, ``opa`` or ``mc`` dataset (``simulate_dmr`` etc.). The stroboscopic
        samples are the outputs at ``t = k 2 pi/omega``; outputs in between (e.g.
        ``per_period=16``) resolve free-flight maxima for grazing.
    start : end of the transient (a time); default: the whole run.
    period_tol, max_period : see ``detect_period``.
    graze_velocity, graze_gap : grazing thresholds (see ``Motion.grazing``).

    Notes
    -----
    When a stroboscopic time coincides with an impulse (omega/omega1 rational), the
    sample lies just after the velocity jump only if the output time equals the impulse
    time to the last bit; ``opa.dynamics._sweep.sweep_times`` builds such grids.

    Examples
    --------
    >>> from opa import preset, simulate_dmr
    >>> osc = preset("3.1", c=0.05, F0=0.0)
    >>> ds = simulate_dmr(osc, periods=300)
    >>> identify_motion(ds, start=200 * osc.forcing_period).label
    '2/2'
    """
    x, v, _ = mean_state(ds)
    t = ds.time.values
    has_impacts = "impact_time" in ds
    sticking = None
    if "stick_time" in ds:
        sticking = sticking_mask(t, ds.stick_time.values, ds.release_time.values)
    return identify(
        t, x, v, forcing_period=_forcing_period(ds), delta=float(ds.attrs["delta"]),
        delta_minus=float(ds.attrs.get("delta_minus", -math.inf)),
        start=start, impact_time=ds.impact_time.values if has_impacts else None,
        impact_velocity=ds.impact_velocity.values if has_impacts else None,
        breaks=run_breaks(ds), sticking=sticking, tolerances=MotionTolerances(
            period_tol=period_tol, max_period=max_period, graze_velocity=graze_velocity,
            graze_gap=graze_gap),
    )


__all__ = [
    "Motion",
    "MotionTolerances",
    "constraint_section",
    "detect_period",
    "free_flight_maxima",
    "grazing_points",
    "identify",
    "identify_motion",
    "impacts_per_period",
    "impulse_times",
    "mean_state",
    "period_doubling",
    "period_label",
    "phase_section",
    "repeat_distance",
    "run_breaks",
    "sticking_mask",
    "stroboscopic_mask",
]
