"""Which system: the oscillator with its impulse model, the uncertainty and the OPA order
with its closures (:class:`System`); the one packer that turns a System into the kernel's
arguments; and the impulse schedule, computed here and nowhere else.

Every entry point (``simulate_dmr``, ``simulate_opa``, ``simulate_mc``, ``sweep``,
``ImpactSystem``, the CLI) takes a System or builds one from the same keywords
(:func:`as_system`), so each choice has one name, one default and one check.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from opa._model import (
    IMPACT_LAWS,
    IMPULSE_MODELS,
    PARAMETER_NAMES,
    TRUNCATIONS,
    DRIVE_PARAMETERS,
    IMPACT_PARAMETERS,
    UNCERTAIN_PARAMETERS,
    Oscillator,
    SolverOptions,
    Uncertainty,
    _choice,
    _finite,
    check_flag,
    check_order,
)
from opa._problem import Problem
from opa._run import Inputs, pack, quadrature, sampled

#: the intensity of the uncertain parameter when none is given (every entry point)
DEFAULT_SIGMA = 0.01
#: the OPA order N when none is given (every entry point)
DEFAULT_ORDER = 4
#: the names a System can vary: each parameter of the oscillator, and sigma
SWEEPABLE = PARAMETER_NAMES + ("sigma",)
#: most impulse times :meth:`System.impulse_times` lists (a bound on what it allocates)
MAX_IMPULSE_TIMES = 10_000_000


def impulse_schedule(t_end: float, omega1: float, *, at_zero: bool = True,
                     t_start: float = 0.0) -> np.ndarray:
    """The impulse times ``t_j = j 2 pi/omega1`` in ``[t_start, t_end]``, j >= 0 (j >= 1
    without the impulse at zero), exactly as the kernel computes them.

    Examples
    --------
    >>> impulse_schedule(7.0, 1.0).round(4).tolist()
    [0.0, 6.2832]
    >>> impulse_schedule(7.0, 1.0, at_zero=False).round(4).tolist()
    [6.2832]
    """
    t_end = _finite("t_end", t_end)
    t_start = _finite("t_start", t_start)
    if not (math.isfinite(omega1) and omega1 > 0):
        raise ValueError(f"omega1 must be finite and > 0, got {omega1}")
    T1 = 2.0 * math.pi / omega1
    if (t_end - min(t_start, 0.0)) / T1 > MAX_IMPULSE_TIMES:
        raise ValueError(f"t_end = {t_end:g} holds {t_end / T1:.3g} impulse times, more than "
                         f"{MAX_IMPULSE_TIMES:g}")
    first = max(0 if at_zero else 1, math.ceil(t_start / T1) - 1)
    j = np.arange(first, int(t_end // T1) + 2)
    tj = j * T1
    return tj[(tj >= t_start) & (tj <= t_end)]


@dataclass(frozen=True)
class System:
    """Which system: the oscillator of eq. (1) with its impulse model, the uncertain
    parameter ``p = p_bar + sigma xi`` and the OPA order N with its closures.

    Parameters
    ----------
    oscillator : the parameters of eq. (1) (the paper's section 3.2 set when omitted).
    sigma, uncertain : intensity and name (``mu``, ``a`` or ``c``, the impact's ``eta``
        or ``delta``, or a constant of a user's force law) of the uncertain parameter,
        or several (``"mu,c"`` and a tuple of scales, or an :class:`opa.Problem`);
        ``uncertain`` defaults to ``mu``, or to the first constant of a user's force law.
        The DMR ignores them (:meth:`deterministic`).
    distribution : the law of xi: None (the semicircle of the paper), a name of
        ``opa._measure.DISTRIBUTIONS``, a chaospy distribution with bounded support or an
        ``opa._measure.Measure``.
    allow_negative : permit samples ``p_bar + sigma xi < 0`` (e.g. negative damping).
    order : the OPA order N (the number of MC coefficients E[x U_i] estimated, i <= N).
    truncation : ``galerkin`` (exact projection) or ``paper`` (eq. (27) drops the
        ``sigma/2 Y_{N+1}`` term).
    impact_law : ``mean`` (eq. (28): only x_0' jumps), ``ensemble`` (every velocity
        coefficient times -eta) or ``saltation``.
    impulse : ``dirac`` (velocity jumps at t_j = j 2 pi/omega1) or ``pulse`` (a
        rectangular force of the same height and width ``pulse_width`` from t_j).
    impulse_at_zero : whether the train includes j = 0 (an impulse at t = 0).

    Examples
    --------
    >>> from opa import preset
    >>> s = System(preset("3.1"), sigma=0.02, order=8)
    >>> s.order, s.sigma, s.impulse
    (8, 0.02, 'dirac')
    >>> s.deterministic().order, s.deterministic().sigma
    (0, 0.0)
    """

    oscillator: Oscillator = field(default_factory=Oscillator)
    sigma: float = DEFAULT_SIGMA
    uncertain: str | None = None
    distribution: object = None
    allow_negative: bool = False
    order: int = DEFAULT_ORDER
    truncation: str = "galerkin"
    impact_law: str = "mean"
    impulse: str = "dirac"
    pulse_width: float = 0.1
    impulse_at_zero: bool = True

    def __post_init__(self):
        if not isinstance(self.oscillator, Oscillator):
            raise ValueError(f"oscillator must be an opa.Oscillator, got {self.oscillator!r:.80}")
        if self.uncertain is None:  # mu, or the first constant of a user's force law
            object.__setattr__(self, "uncertain", "mu" if self.oscillator.force is None
                               else self.oscillator.uncertain_names[0])
        if isinstance(self.uncertain, Problem):
            if (self.sigma, self.distribution, self.allow_negative) != (DEFAULT_SIGMA, None,
                                                                       False):
                raise ValueError("give the uncertain parameters as a Problem or as sigma, "
                                 "distribution and allow_negative, not both")
            problem = self.uncertain
        else:
            problem = Problem(self.uncertain, self.sigma, self.distribution,
                              self.allow_negative, _allowed(self.oscillator, self.sigma))
        if problem.dimension == 1:  # the fields as they always were
            unc = Uncertainty(problem.scales[0], problem.names[0], problem.allow_negative)
            object.__setattr__(self, "uncertain", unc.parameter)
            object.__setattr__(self, "sigma", unc.sigma)
            object.__setattr__(self, "distribution", problem.laws[0])
        else:
            object.__setattr__(self, "uncertain", problem.names)
            object.__setattr__(self, "sigma", problem.scales)
            object.__setattr__(self, "distribution", problem.laws)
            if self.truncation == "paper":
                raise ValueError("truncation 'paper' (eq. (27)) closes the system of one "
                                 f"uncertain parameter; this system has {problem.dimension} "
                                 f"({','.join(problem.names)}): use truncation 'galerkin'")
        object.__setattr__(self, "allow_negative", problem.allow_negative)
        _check_law(self.oscillator, problem, self.truncation)
        object.__setattr__(self, "order", check_order(self.order))
        _choice("truncation", self.truncation, TRUNCATIONS)
        _choice("impact_law", self.impact_law, IMPACT_LAWS)
        _choice("impulse", self.impulse, IMPULSE_MODELS)
        check_flag("impulse_at_zero", self.impulse_at_zero)
        object.__setattr__(self, "impulse_at_zero", bool(self.impulse_at_zero))
        tau = _finite("pulse_width", self.pulse_width)
        if tau <= 0.0:
            raise ValueError(f"pulse_width must be > 0, got {tau}")
        if self.impulse == "pulse" and tau >= self.impulse_period:
            raise ValueError(
                f"pulse_width must be shorter than the impulse period 2 pi/omega1 = "
                f"{self.impulse_period:.6g}, got {tau}")
        object.__setattr__(self, "pulse_width", tau)
        if self.impulse == "pulse" and any(name == "F0" and scale != 0.0 for name, scale in
                                           zip(problem.names, problem.scales)):
            raise ValueError("an uncertain F0 takes Dirac impulses (impulse 'dirac'): a pulse's "
                             "height is one force for every node of the equivalent system")

    # ------------------------------------------------------------------ the uncertainty
    @functools.cached_property
    def problem(self) -> Problem:
        """The uncertain parameters, their scales and joint law (:class:`opa.Problem`),
        made once per System (every chunk of samples asks for it)."""
        return Problem(self.uncertain, self.sigma, self.distribution, self.allow_negative,
                       _allowed(self.oscillator, self.sigma))

    def __getstate__(self):
        # the problem's parsed laws may hold closures; a copy in another process rebuilds it
        return {k: v for k, v in self.__dict__.items() if k != "problem"}

    @property
    def dimension(self) -> int:
        """d, the number of uncertain parameters."""
        return 1 if isinstance(self.uncertain, str) else len(self.uncertain)

    def one_dimensional(self, where: str) -> System:
        """This system, when it has one uncertain parameter; else one line saying that
        ``where`` takes one."""
        if self.dimension > 1:
            raise ValueError(f"{where} takes one uncertain parameter; this system has "
                             f"{self.dimension} ({','.join(self.uncertain)})")
        return self

    @property
    def measure(self):
        """The law of xi as an ``opa._measure.Measure`` (one uncertain parameter)."""
        from opa._measure import parse

        self.one_dimensional("the law of xi as one Measure")
        return parse(self.distribution)

    @property
    def semicircle(self) -> bool:
        """Whether xi has the paper's law, the semicircle on [-1, 1]."""
        problem = self.problem
        return all(problem.is_semicircle(j) for j in range(problem.dimension))

    @property
    def support(self) -> tuple[float, float]:
        """The interval xi lies in."""
        if self.distribution is None:
            return -1.0, 1.0
        return self.measure.lo, self.measure.hi

    def check_samples(self) -> None:
        """Refuse samples ``p_bar + sigma xi < 0`` over xi's support unless allowed."""
        self.problem.check(self.oscillator)

    def deterministic(self) -> System:
        """The same oscillator and impulse model without uncertainty: the DMR (N = 0,
        sigma = 0, the default closures)."""
        first = self.uncertain if self.dimension == 1 else self.uncertain[0]
        return dataclasses.replace(self, uncertain=first, sigma=0.0, order=0,
                                   distribution=None, truncation="galerkin",
                                   impact_law="mean")

    def replace(self, **changes) -> System:
        """A copy with some fields changed (validated again); the oscillator's parameters
        may be given by name too (``replace(c=0.05, sigma=0.02)``)."""
        own = {k: v for k, v in changes.items() if k in SYSTEM_FIELDS}
        physical = {k: v for k, v in changes.items() if k not in SYSTEM_FIELDS}
        if physical:
            own["oscillator"] = own.get("oscillator", self.oscillator).replace(**physical)
        return dataclasses.replace(self, **own)

    # ------------------------------------------------------------------ the impulse train
    @property
    def impulse_period(self) -> float:
        """T1 = 2 pi/omega1, the spacing of the impulse times."""
        return 2.0 * math.pi / self.oscillator.omega1

    @property
    def impulsive(self) -> bool:
        """Whether the train acts at all (F0 != 0)."""
        return self.oscillator.F0 != 0.0

    def impulse_times(self, t_end: float, t_start: float = 0.0) -> np.ndarray:
        """The impulse times in ``[t_start, t_end]`` (empty when F0 = 0)."""
        if not self.impulsive:
            return np.zeros(0)
        return impulse_schedule(t_end, self.oscillator.omega1, at_zero=self.impulse_at_zero,
                                t_start=t_start)

    def impulse_heights(self, times) -> np.ndarray:
        """The strength ``F0 (1 + a1 sin(omega1 t / n))`` of the impulse at each time."""
        o = self.oscillator
        return o.F0 * (1.0 + o.a1 * np.sin(o.omega1 * np.asarray(times, float) / o.n))

    def impulse_breaks(self, t_end: float) -> np.ndarray:
        """The times where the impulse force changes: the impulse times, and for pulses
        their ends too, sorted."""
        tj = self.impulse_times(t_end)
        if self.impulse == "pulse":
            tj = np.sort(np.concatenate([tj, tj + self.pulse_width]))
        return tj

    def impulse_interval(self, times) -> np.ndarray:
        """The index j of the impulse interval ``[t_j, t_{j+1})`` holding each time (all
        zero when F0 = 0)."""
        times = np.asarray(times, dtype=float)
        if not self.impulsive:
            return np.zeros(times.shape, dtype=int)
        return np.floor(times / self.impulse_period).astype(int)

    def snap_to_impulses(self, times, tolerance: float) -> np.ndarray:
        """``times`` with each one within ``tolerance`` of an impulse time moved onto it,
        so that it is sampled just after the impulse (outputs are right-continuous)."""
        times = np.asarray(times, dtype=float)
        if not self.impulsive:
            return times
        T1 = self.impulse_period
        j = np.round(times / T1)
        near = (np.abs(times - j * T1) <= tolerance) & (j >= (0 if self.impulse_at_zero else 1))
        return np.where(near, j * T1, times)

    # ------------------------------------------------------------------ the kernel's inputs
    def kernel_inputs(self, options: SolverOptions, rule=None) -> Inputs:
        """The kernel's inputs (parameter vector, configuration and Gauss rule of order
        N): the one packer. ``rule`` (nodes, weights, basis (N + 2, Q)) replaces the
        semicircle's rule (an element's own law, ``opa._elements.element_rule``)."""
        o = self.oscillator
        values = dict(mu=o.mu, a=o.a, c=o.c, f=o.f, omega=o.omega, eta=o.eta, delta=o.delta,
                      F0=o.F0, a1=o.a1, omega1=o.omega1, n=o.n, pulse_width=self.pulse_width,
                      # the paper's closure's sigma (one uncertain parameter)
                      sigma=self.sigma if self.dimension == 1 else 0.0,
                      chatter_velocity=options.chatter_velocity,
                      max_step=options.max_step)
        if o.two_walls:
            values.update(delta_minus=o.delta_minus, eta_minus=o.lower_restitution)
        rule = quadrature(self.order) if rule is None else rule
        law = o.law_coefficients()
        return pack(values, max_steps=options.max_steps,
                    impulse_at_zero=self.impulse_at_zero, rule=rule,
                    table=self.problem.table(rule[0], o), impulse=self.impulse,
                    closure=self.closure, impact_law=self.impact_law,
                    method=options.method, coefficients=None if law is None else law[0],
                    force="paper" if law is None else (
                        "polynomial" if o.force.kind == "polynomial" else "function"),
                    function_address=0 if law is None else o.force.address(),
                    wall_nodes=self.problem.varies_at_the_wall(),
                    drive_nodes=self.problem.varies_in_the_drive())

    @property
    def closure(self) -> str:
        """The truncation's closure term in the kernel's words: ``none`` (Galerkin), or
        the paper's (eq. (27)) on the velocities (uncertain mu) or positions (uncertain
        c); the paper's has no such term for an uncertain a."""
        if self.truncation != "paper" or self.uncertain == "a":
            return "none"
        return "velocity" if self.uncertain == "mu" else "position"

    def sampled_inputs(self, options: SolverOptions, *, xi=None, values=None) -> Inputs:
        """The kernel's inputs of the sampled deterministic systems: the uncertain
        parameters at ``p_bar + sigma xi`` (``xi`` (M,) or (M, d)), or the one uncertain
        parameter at ``values`` (absolute)."""
        if values is None:
            columns = self.problem.values(xi, self.oscillator)
        else:
            columns = {self.one_dimensional("values=").uncertain: np.asarray(values, float)}
        return sampled(self.deterministic().kernel_inputs(options), columns,
                       self.oscillator.law_coefficients(columns))

    def initial_state(self, initial=None) -> np.ndarray:
        """The start of a run: x_0 = x0, v_0 = v0 and the higher coefficients 0, or
        ``initial`` (shape (2, N + 1): rows x_coef, v_coef), which must be finite and not
        beyond the wall."""
        n = self.order + 1
        y = np.zeros(2 * n)
        if initial is None:
            y[0] = self.oscillator.x0
            y[n] = self.oscillator.v0
            return y
        initial = np.asarray(initial, dtype=float)
        if initial.shape != (2, n) or not np.all(np.isfinite(initial)):
            raise ValueError(f"initial must be a finite array of shape (2, {n}), got shape "
                             f"{initial.shape}")
        if initial[0, 0] > self.oscillator.delta:
            raise ValueError(f"initial x_0 must not be beyond the wall, got {initial[0, 0]}")
        if initial[0, 0] < self.oscillator.delta_minus:
            raise ValueError(f"initial x_0 must not be below the lower wall (delta_minus = "
                             f"{self.oscillator.delta_minus}), got {initial[0, 0]}")
        y[:] = initial.ravel()
        return y

    def dataset_attrs(self) -> dict:
        """The system's dataset attributes (docs/datasets.md; netCDF-safe types): with
        several uncertain parameters ``uncertain`` is their comma-separated names and
        ``sigma`` the vector of their scales."""
        if self.dimension > 1:
            return dict(self.problem.attrs(), N=int(self.order), impulse=self.impulse,
                        pulse_width=float(self.pulse_width),
                        impulse_at_zero=int(self.impulse_at_zero),
                        truncation=self.truncation, impact_law=self.impact_law)
        return dict(sigma=float(self.sigma), N=int(self.order), uncertain=self.uncertain,
                    impulse=self.impulse, pulse_width=float(self.pulse_width),
                    impulse_at_zero=int(self.impulse_at_zero), truncation=self.truncation,
                    impact_law=self.impact_law, allow_negative=int(self.allow_negative))


def _allowed(oscillator: Oscillator, sigma) -> tuple | None:
    """The names a problem may make uncertain: None (mu, a, c) for the paper's law, a
    user's law's constants, and mu, a, c too while every scale is 0 (the deterministic
    system, whose default ``uncertain="mu"`` names nothing the law uses)."""
    if oscillator.force is None:
        return None
    names = oscillator.uncertain_names
    try:
        zero = not np.any(np.asarray(sigma, dtype=float))
    except (TypeError, ValueError):
        zero = False  # the Problem refuses it, naming it
    return names + tuple(n for n in UNCERTAIN_PARAMETERS if n not in names) if zero else names


def _check_law(oscillator: Oscillator, problem: Problem, truncation: str) -> None:
    """The uncertain parameters are coefficients of the oscillator's force law (mu, a, c
    of the paper's, the named constants of a user's; any name at scale 0), and the
    paper's truncation is the paper's law's."""
    if truncation == "paper" and any(name in IMPACT_PARAMETERS + DRIVE_PARAMETERS
                                     for name in problem.names):
        raise ValueError("truncation 'paper' (eq. (27)) closes a force law's coefficient; an "
                         "uncertain eta, delta, f, omega or F0 takes truncation 'galerkin'")
    if oscillator.two_walls and oscillator.eta_minus is None and any(
            name == "eta" and scale != 0.0 for name, scale in zip(problem.names, problem.scales)):
        raise ValueError("an uncertain eta is the upper wall's restitution: with a lower wall, "
                         "give the lower wall's own eta_minus (it is eta when left out)")
    names = oscillator.uncertain_names
    for name, scale in zip(problem.names, problem.scales):
        if name not in names and scale != 0.0:
            law = ("the paper's force law" if oscillator.force is None
                   else f"the force law {oscillator.force.expression!r:.60}")
            raise ValueError(f"uncertain must name parameters among {', '.join(names)} (the "
                             f"coefficients of {law}), got {name!r:.40}")
    if truncation == "paper" and oscillator.force is not None:
        raise ValueError("truncation 'paper' (eq. (27)) closes the paper's force law; a "
                         "user's force law takes truncation 'galerkin'")


SYSTEM_FIELDS = tuple(f.name for f in dataclasses.fields(System))
IMPULSE_FIELDS = ("impulse", "pulse_width", "impulse_at_zero")


def as_system(system=None, options: SolverOptions | None = None, *, allowed=SYSTEM_FIELDS,
              where: str = "", several: bool = False, **fields) -> System:
    """The System an entry point works on.

    ``system`` is a :class:`System` (then no ``fields`` may be given), or an
    :class:`Oscillator` or None (the paper's defaults) from which a System is built with
    ``fields``, the keywords of :class:`System` (``allowed`` of them; None values count as
    not given). A system of several uncertain parameters is refused in one line unless
    the entry point takes them (``several``). A ``SolverOptions`` that still carries the
    deprecated impulse model (``SolverOptions(impulse=...)``) passes it on when the
    fields do not set it.

    Examples
    --------
    >>> as_system(None, sigma=0.02, order=2).order
    2
    >>> as_system(System(order=3), order=2)
    Traceback (most recent call last):
    ...
    ValueError: give either a System or its fields (order), not both
    """
    given = {k: v for k, v in fields.items() if v is not None}
    if "oscillator" in given and system is None:  # the former keyword of the entry points
        system = given.pop("oscillator")
    unknown = [k for k in given if k not in allowed]
    if unknown:
        name = f"{where}() " if where else ""
        raise TypeError(f"{name}got unexpected keyword(s) {', '.join(unknown)} (the system's "
                        f"fields here: {', '.join(allowed)})")
    legacy = getattr(options, "legacy_impulse", None) or {}
    if isinstance(system, System):
        if given:
            raise ValueError(f"give either a System or its fields ({', '.join(given)}), "
                             f"not both")
        clash = [k for k, v in legacy.items() if getattr(system, k) != v]
        if clash:
            raise ValueError(f"SolverOptions and the System disagree on {', '.join(clash)}: "
                             f"the impulse model belongs to the System (System(impulse=...))")
    else:
        if system is not None and not isinstance(system, Oscillator):
            raise ValueError(f"oscillator must be an opa.Oscillator (or the system an "
                             f"opa.System), got {system!r:.80}")
        for name, value in legacy.items():
            given.setdefault(name, value)
        system = System(system if system is not None else Oscillator(), **given)
    return system if several else system.one_dimensional(f"{where or 'this analysis'}()")
