"""The vibro-impact oscillator (paper eq. (1)) and the options of its solution.

    x'' - mu (1 - x'^2) x' + a x + c x^3 = f cos(omega t) + F(t),   x < delta
    x'(t+) = -eta x'(t-)                                            at x = delta
    x'(t+) = -eta_minus x'(t-)         at x = delta_minus (an optional lower wall)
    F(t) = sum_j delta_Dirac(t - j T1) F0 (1 + a1 sin(omega1 t / n)),   T1 = 2 pi / omega1

Everything here is validated once, in ``__post_init__``, with messages that name the
parameter and the value; the compiled kernels never see unchecked input.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings
from dataclasses import InitVar, dataclass

from opa._forcelaw import ForceLaw, _finite

PARAMETER_NAMES = ("mu", "a", "c", "f", "omega", "eta", "delta", "F0", "a1", "omega1", "n",
                   "x0", "v0")
UNCERTAIN_PARAMETERS = ("mu", "a", "c")
#: the impact's parameters, which may be uncertain too (the impact law reads them per node)
IMPACT_PARAMETERS = ("eta", "delta")
#: the drive's parameters, which may be uncertain too (each node has its own drive)
DRIVE_PARAMETERS = ("f", "omega", "F0")
METHODS = ("dop853", "dp5")
IMPULSE_MODELS = ("dirac", "pulse")
TRUNCATIONS = ("galerkin", "paper")
IMPACT_LAWS = ("mean", "ensemble", "saltation")

PARAMETER_DOCS = {
    "mu": "van der Pol damping coefficient (mean value mu_bar when uncertain)",
    "a": "linear stiffness",
    "c": "cubic stiffness",
    "f": "amplitude of the harmonic forcing f cos(omega t)",
    "omega": "frequency of the harmonic forcing",
    "eta": "coefficient of restitution, 0 < eta <= 1",
    "delta": "position of the rigid wall (x < delta)",
    "F0": "impulse amplitude F0 (1 + a1 sin(omega1 t / n))",
    "a1": "modulation depth of the impulse amplitude",
    "omega1": "impulse train frequency (impulses every 2 pi / omega1)",
    "n": "modulation divisor n of the impulse amplitude",
    "x0": "initial displacement",
    "v0": "initial velocity",
}


# Largest truncation order N: the OPA system has 2(N+1) states and 2N+1 Gauss nodes, so
# one right-hand side costs O(N^2); N = 500 is already ~10^6 operations per evaluation.
MAX_ORDER = 500
# Runs longer than this many time units are refused: at the paper's frequencies that is
# about 10^7 forcing periods, far past any study in the paper, and it keeps t well inside
# the range where a step of 1e-6 still changes t in floating point.
MAX_TIME = 1e8
# Forcing and impulse periods shorter than this cannot be resolved by the integrator.
MIN_PERIOD = 1e-6
# At most this many impulses in one run (each one restarts the integrator).
MAX_IMPULSES = 10**7
# Largest grid of swept values, sigmas or orders of a validation study: every point of a
# trust map runs Monte Carlo ensembles, so even this is days of work.
MAX_GRID = 1000


#: where runs may go: this process's CPU cores, or a CUDA GPU (:mod:`opa._gpu`)
DEVICES = ("cpu", "cuda")


def check_device(device) -> str:
    """``device`` as given ("cpu" or "cuda"), or ValueError naming it."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {', '.join(map(repr, DEVICES))}, got "
                         f"{device!r:.60}")
    return device


def check_scheduler_address(address: str) -> str:
    """``address`` if it reads as a Dask scheduler's (``tcp://host:port``, ``tls://``,
    ``ws://``, ``wss://`` or ``ucx://`` with a port, ``inproc://...``, or ``host:port``),
    else one line naming it; nothing is contacted.

    >>> check_scheduler_address("tcp://10.0.0.5:8786")
    'tcp://10.0.0.5:8786'
    """
    import re

    text = address.strip() if isinstance(address, str) else ""
    if re.fullmatch(r"inproc://\S+", text) or re.fullmatch(
            r"(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9a-fA-F:.]+\]|[\w.-]+):\d{1,5}", text):
        return text
    raise ValueError(f"scheduler must be a Dask scheduler address such as tcp://host:8786 "
                     f"(a host and a port), got {address!r:.60}")


def check_order(order, maximum: int = MAX_ORDER) -> int:
    """The truncation order N as an int, refusing bools, non-integers, N < 0 and
    N > ``maximum``."""
    return check_count("order (N)", order, minimum=0, maximum=maximum)


#: largest whole number a count, a seed or a step limit may be: floats are exact to here
MAX_WHOLE = 2**53


def _is_bool(value) -> bool:
    return isinstance(value, bool) or (type(value).__module__ == "numpy"
                                       and type(value).__name__ in ("bool_", "bool"))


def check_count(name: str, value, minimum: int = 1, maximum: int | None = None) -> int:
    """A whole number in [minimum, maximum] (and at most 2^53): bools (numpy's too),
    strings, fractions, inf and NaN refused; a 0-d array is its element."""
    if type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
        value = value.item() if hasattr(value, "item") else value
    whole = False
    if not _is_bool(value) and not isinstance(value, (str, bytes)):
        if isinstance(value, numbers.Integral):
            whole = True
        else:
            try:
                f = float(value)
                whole = math.isfinite(f) and f.is_integer()
            except (TypeError, ValueError, OverflowError):
                whole = False
    if not whole or int(value) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    top = MAX_WHOLE if maximum is None else min(maximum, MAX_WHOLE)
    if int(value) > top or (not isinstance(value, numbers.Integral) and abs(value) >= MAX_WHOLE
                            and top == MAX_WHOLE):
        raise ValueError(f"{name} must be at most {top}"
                         + (" (2^53, where floats stop being exact)" if top == MAX_WHOLE
                            else "") + f", got {value!r}")
    return int(value)


def check_instance(name: str, value, kind, default=None):
    """``value`` if it is a ``kind`` (``default`` when None), else a ValueError naming it."""
    if value is None:
        return default
    if not isinstance(value, kind):
        raise ValueError(f"{name} must be a {kind.__name__}, got {type(value).__name__} "
                         f"{value!r:.60}")
    return value


def check_flag(name: str, value) -> bool:
    """``value`` if it is True or False (numpy's bools too); 1, 0.0 and "no" refused."""
    if not _is_bool(value):
        raise ValueError(f"{name} must be True or False, got {value!r:.60}")
    return bool(value)


def _choice(name: str, value: str, options: tuple[str, ...]) -> str:
    if value not in options:
        allowed = ", ".join(repr(o) for o in options)
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
    return value


@dataclass(frozen=True)
class Oscillator:
    """Parameters of the impact oscillator, eq. (1), with the paper's defaults.

    The defaults are the section 3.2 set at omega = 3.98 (Figs. 5-6) with the impulse
    train of section 2 (a1 = 1, F0 = 0.1, omega1 = 1, n = 2) and the initial state
    x0 = -1, v0 = 0 of section 3.1.

    ``delta_minus`` (default -inf, none) adds a lower wall with restitution ``eta_minus``
    (None: eta): the motion is then in delta_minus < x < delta. It is not one of
    ``PARAMETER_NAMES`` (not sweepable, not uncertain); the CLI's ``--delta-minus`` and
    ``--eta-minus`` and a model file's [oscillator] keys give it; datasets and manifests
    carry it only where it exists.

    Examples
    --------
    >>> Oscillator(c=0.035, omega=2.8, a=1.0, f=2.0).c
    0.035
    """

    mu: float = 0.8
    a: float = 0.5
    c: float = 0.05
    f: float = 1.5
    omega: float = 3.98
    eta: float = 0.8
    delta: float = 0.0
    F0: float = 0.1
    a1: float = 1.0
    omega1: float = 1.0
    n: float = 2.0
    x0: float = -1.0
    v0: float = 0.0
    force: ForceLaw | None = None
    #: an optional lower wall x = delta_minus < delta (motion in delta_minus < x < delta,
    #: e.g. a gear pair rattling in its backlash): -inf is none
    delta_minus: float = -math.inf
    #: the lower wall's restitution, 0 < eta_minus <= 1; None: the same as eta
    eta_minus: float | None = None

    # added after parts were written: a digest (opa._dataset.digest) counts them when set
    _digest_optional = ("force", "delta_minus", "eta_minus")

    def __post_init__(self):
        for name in PARAMETER_NAMES:
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        if self.force is not None and not isinstance(self.force, ForceLaw):
            if not isinstance(self.force, str):
                raise ValueError(f"force must be an opa.ForceLaw or an expression in x and v, "
                                 f"got {self.force!r:.60}")
            object.__setattr__(self, "force", ForceLaw(self.force))
        if not 0.0 < self.eta <= 1.0:
            raise ValueError(f"eta must be in (0, 1], got {self.eta}")
        if self.omega <= 0.0:
            raise ValueError(f"omega must be > 0, got {self.omega}")
        if self.omega1 <= 0.0:
            raise ValueError(f"omega1 must be > 0, got {self.omega1}")
        if self.n == 0.0:
            raise ValueError(f"n must be non-zero, got {self.n}")
        if self.x0 > self.delta:
            raise ValueError(
                f"x0 must not be beyond the wall (x0 <= delta = {self.delta}), got {self.x0}"
            )
        if self.x0 == self.delta and self.v0 > 0.0:
            raise ValueError(f"v0 must be <= 0 when x0 is at the wall, got {self.v0}")
        self._check_lower_wall()

    def _check_lower_wall(self) -> None:
        """delta_minus: -inf (no lower wall) or a finite wall below delta with x0 not below
        it (at it only moving up); eta_minus in (0, 1] or None (eta's value)."""
        dm = self.delta_minus
        if isinstance(dm, (bool, str, bytes)) or not isinstance(dm, numbers.Real) \
                or math.isnan(dm) or dm == math.inf:
            raise ValueError(f"delta_minus must be a real number or -inf (no lower wall), got "
                             f"{dm!r:.60}")
        object.__setattr__(self, "delta_minus", float(dm))
        if self.eta_minus is not None:
            object.__setattr__(self, "eta_minus", _finite("eta_minus", self.eta_minus))
            if not 0.0 < self.eta_minus <= 1.0:
                raise ValueError(f"eta_minus must be in (0, 1], got {self.eta_minus}")
        if self.delta_minus >= self.delta:
            raise ValueError(f"delta_minus must be below the wall delta = {self.delta}, got "
                             f"{self.delta_minus}")
        if self.x0 < self.delta_minus:
            raise ValueError(f"x0 must not be below the lower wall (x0 >= delta_minus = "
                             f"{self.delta_minus}), got {self.x0}")
        if self.x0 == self.delta_minus and self.v0 < 0.0:
            raise ValueError(f"v0 must be >= 0 when x0 is at the lower wall (delta_minus), got "
                             f"{self.v0}")

    @property
    def two_walls(self) -> bool:
        """Whether the lower wall exists (delta_minus > -inf)."""
        return self.delta_minus > -math.inf

    @property
    def lower_restitution(self) -> float:
        """The lower wall's restitution: eta_minus, or eta where it is None."""
        return self.eta if self.eta_minus is None else self.eta_minus

    def replace(self, **changes) -> Oscillator:
        """A copy with some parameters changed (validated again); a change may name a
        constant of the force law."""
        law = changes.get("force", self.force)
        if isinstance(law, ForceLaw):
            own = {name: changes.pop(name) for name in list(changes) if name in law.constants}
            if own:
                changes["force"] = law.with_constants(**own)
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict:
        """Every parameter by name (what resume keys, run manifests and checkpoints hash),
        with the lower wall's delta_minus and eta_minus only where it exists and a user's
        force law's expression and constants (``law_attrs``) only where one is given: a
        one-wall oscillator of the paper's law gives what it always did."""
        values = {name: getattr(self, name) for name in PARAMETER_NAMES}
        return {**values, **self.lower_wall_attrs(), **self.law_attrs()}

    @classmethod
    def from_attrs(cls, attrs) -> Oscillator:
        """The oscillator a dataset was computed with, from its attributes: every
        ``PARAMETER_NAMES`` value and, for a user's force law, ``force_law`` and
        ``force_constants`` (``name=value,...``, as ``opa._dataset.provenance_attrs``
        writes them), and a lower wall's ``delta_minus``, ``eta_minus`` where present."""
        values = {name: float(attrs[name]) for name in PARAMETER_NAMES}
        values.update({name: float(attrs[name]) for name in ("delta_minus", "eta_minus")
                       if name in attrs})
        if "force_law" in attrs:
            values["force"] = law_from_attrs(attrs, cls.constants_from_attrs(attrs))
        return cls(**values)

    @staticmethod
    def constants_from_attrs(attrs) -> dict[str, float]:
        """A user's force law's constants from a dataset's ``force_constants``
        (``name=value,...``; empty for the paper's law)."""
        constants = {}
        for item in filter(None, str(attrs.get("force_constants", "")).split(",")):
            name, _, value = item.partition("=")
            constants[name.strip()] = float(value)
        return constants

    def law_attrs(self) -> dict:
        """The force law as dataset attributes (none for the paper's law)."""
        if self.force is None:
            return {}
        kind = {} if self.force.kind == "polynomial" else {"force_kind": self.force.kind}
        return dict(force_law=self.force.expression, force_constants=",".join(
            f"{name}={value!r}" for name, value in self.force.constants.items()), **kind)

    def lower_wall_attrs(self) -> dict[str, float]:
        """{delta_minus, eta_minus} as floats with a lower wall, else {} (dataset attributes
        and manifests carry them only then)."""
        if not self.two_walls:
            return {}
        return {"delta_minus": float(self.delta_minus), "eta_minus": self.lower_restitution}

    @property
    def uncertain_names(self) -> tuple[str, ...]:
        """The parameters that may be uncertain: the force law's coefficients and the
        impact's restitution eta and wall delta."""
        return self.coefficient_names + IMPACT_PARAMETERS + DRIVE_PARAMETERS

    @property
    def sweepable_names(self) -> tuple[str, ...]:
        """The parameters a sweep may vary: every ``PARAMETER_NAMES`` value and a user's
        force law's own constants."""
        own = () if self.force is None else tuple(self.force.constants)
        return PARAMETER_NAMES + own

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """The named coefficients of the force law, the parameters that may be uncertain
        in it: mu, a, c for the paper's law, the names a user's law uses otherwise."""
        return UNCERTAIN_PARAMETERS if self.force is None else self.force.names

    def value(self, name: str) -> float:
        """The value of a parameter: one of ``PARAMETER_NAMES`` or a constant of the
        force law."""
        if name in PARAMETER_NAMES:
            return float(getattr(self, name))
        if self.force is not None and name in self.force.constants:
            return self.force.constants[name]
        raise ValueError(f"{name!r:.40} is not a parameter of this oscillator (its force "
                         f"law's constants: {', '.join(self.coefficient_names)})")

    def law_coefficients(self, values: dict | None = None):
        """The force law's coefficients C[j, k] (``opa._forcelaw``) at the oscillator's
        values, or at ``values`` (name -> array) where given; None for the paper's law."""
        if self.force is None:
            return None
        own = {name: self.value(name) for name in self.force.names}
        return self.force.coefficients({**own, **(values or {})})

    @property
    def forcing_period(self) -> float:
        """T = 2 pi / omega, the period used for stroboscopic sections."""
        return 2.0 * math.pi / self.omega


# Presets of the paper's section 3 (the section 3.3 value of c is our choice: the paper
# says "as 3.1 except a = 3.5, f = 3.5", which leaves c open; c = 0.05).
PRESETS = {
    "3.1": dict(f=2.0, omega=2.8, a=1.0, mu=0.8, eta=0.8, delta=0.0, n=2.0, F0=0.1, c=0.05),
    "3.2": dict(a=0.5, c=0.05, F0=0.1, f=1.5, mu=0.8, eta=0.8, delta=0.0, n=2.0, omega=3.98),
    "3.3": dict(f=3.5, omega=4.00495, a=3.5, mu=0.8, eta=0.8, delta=0.0, n=2.0, F0=0.1, c=0.05),
    "3.4": dict(f=2.0, omega=2.8, a=1.0, mu=0.8, eta=0.8, delta=0.0, n=2.0, F0=10.0, c=0.0356),
}


def preset(name: str, **changes) -> Oscillator:
    """The paper's parameter set of section ``name`` ("3.1" .. "3.4"), with changes."""
    _choice("preset", name, tuple(PRESETS))
    return Oscillator(**{**PRESETS[name], **changes})


@dataclass(frozen=True)
class SolverOptions:
    """Numerical choices of the integrator (README, 'Choices the paper leaves open').

    The impulse model (``impulse``, ``pulse_width``, ``impulse_at_zero``) belongs to the
    system (``opa.System``); passing it here still works but is deprecated.

    Attributes
    ----------
    rtol, atol : tolerances of the error control (max-norm over the components).
    method : the Runge-Kutta pair: "dop853" (Dormand-Prince 8(5,3) with its seventh-order
        dense output, the default: fewer steps at the tolerances of this project, 1e-8 to
        1e-12) or "dp5" (Dormand-Prince 5(4) with Shampine's quartic dense output).
    max_steps : hard cap on steps (accepted and rejected) of one trajectory.
    chatter_velocity : an impact slower than this, with the net force pushing into the
        wall, ends a chatter sequence: the oscillator is put at rest on the wall at the
        accumulation point and sticks until the force turns.
    max_step : upper bound on the step size.
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    max_steps: int = 50_000_000
    chatter_velocity: float = 1e-6
    max_step: float = math.inf
    method: str = "dop853"
    impulse: InitVar[str | None] = None
    pulse_width: InitVar[float | None] = None
    impulse_at_zero: InitVar[bool | None] = None

    def __post_init__(self, impulse, pulse_width, impulse_at_zero):
        legacy = {name: value for name, value in (("impulse", impulse),
                                                  ("pulse_width", pulse_width),
                                                  ("impulse_at_zero", impulse_at_zero))
                  if value is not None}
        if legacy:
            given = ", ".join(f"{name}=..." for name in legacy)
            warnings.warn(
                f"SolverOptions({given}) is deprecated: the impulse model belongs to the "
                f"system, opa.System({given}), or the same keywords of simulate_dmr, "
                f"simulate_opa, simulate_mc and sweep", DeprecationWarning, stacklevel=3)
            if "impulse" in legacy:
                _choice("impulse", impulse, IMPULSE_MODELS)
            if "pulse_width" in legacy and not _finite("pulse_width", pulse_width) > 0.0:
                raise ValueError(f"pulse_width must be > 0, got {pulse_width}")
            if "impulse_at_zero" in legacy:
                check_flag("impulse_at_zero", impulse_at_zero)
        # read by opa._system.as_system, which hands it to the System it builds
        object.__setattr__(self, "legacy_impulse", legacy)
        _choice("method", self.method, METHODS)
        for name in ("rtol", "atol"):
            value = _finite(name, getattr(self, name))
            if not 1e-15 <= value < 1.0:
                raise ValueError(f"{name} must be in [1e-15, 1), got {value}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "max_steps", check_count("max_steps", self.max_steps))
        chatter = _finite("chatter_velocity", self.chatter_velocity)
        if not chatter > 0.0:
            raise ValueError(f"chatter_velocity must be > 0, got {chatter}")
        object.__setattr__(self, "chatter_velocity", chatter)
        if isinstance(self.max_step, (bool, str, bytes)):
            raise ValueError(f"max_step must be a number > 0, got {self.max_step!r}")
        try:
            max_step = float(self.max_step)
        except (TypeError, ValueError):
            raise ValueError(f"max_step must be a number > 0, got {self.max_step!r}") from None
        if not max_step > 0.0 or math.isnan(max_step):
            raise ValueError(f"max_step must be > 0, got {max_step}")
        object.__setattr__(self, "max_step", max_step)


def _legacy(name: str) -> property:
    return property(lambda self: self.legacy_impulse.get(name),
                    doc=f"Deprecated: the {name} given to SolverOptions, or None (the system's "
                        f"is opa.System.{name}).")


# the deprecated impulse keywords are init-only; reading them back gives what was given
# (None when nothing was), so dataclasses.replace carries them over
for _name in ("impulse", "pulse_width", "impulse_at_zero"):
    setattr(SolverOptions, _name, _legacy(_name))
del _name


@dataclass(frozen=True)
class Uncertainty:
    """The uncertain parameter ``p = p_bar + sigma * xi``, xi semicircle on [-1, 1].

    ``allow_negative`` permits ``p_bar - sigma < 0`` (e.g. negative damping samples); the
    samples are checked against it where the law of xi is known
    (``opa.System.check_samples``, over xi's support).
    """

    sigma: float = 0.0
    parameter: str = "mu"
    allow_negative: bool = False

    def __post_init__(self):
        sigma = _finite("sigma", self.sigma)
        if sigma < 0.0:
            raise ValueError(f"sigma must be >= 0, got {sigma}")
        object.__setattr__(self, "sigma", sigma)
        if not (isinstance(self.parameter, str) and self.parameter.isidentifier()
                and (self.parameter in UNCERTAIN_PARAMETERS + IMPACT_PARAMETERS
                     + DRIVE_PARAMETERS or self.parameter not in PARAMETER_NAMES)):
            # a user's force law's constants are checked against the law by opa.System
            _choice("uncertain", self.parameter,
                    UNCERTAIN_PARAMETERS + IMPACT_PARAMETERS + DRIVE_PARAMETERS)
        check_flag("allow_negative", self.allow_negative)


def _denominator(value: float) -> int:
    """The smallest K <= 1000 with K x value whole (1000 if none)."""
    for k in range(1, 1001):
        if abs(k * value - round(k * value)) <= 1e-9 * max(1.0, abs(k * value)):
            return k
    return 1000


def time_grid(omega: float, periods: float, per_period: int):
    """Output times t_j = j (2 pi / omega) / K, j = 0 .. P K (the ``--per-period`` grid)."""
    import numpy as np

    periods = _finite("periods", periods)
    if periods <= 0:
        raise ValueError(f"periods must be > 0, got {periods}")
    per_period = check_count("per_period", per_period)
    count = round(periods * per_period)
    if count < 1:
        raise ValueError(f"periods * per_period must be >= 1, got {periods} * {per_period}")
    # the run ends on its last output time: a fraction of an output interval would be cut
    if abs(periods * per_period - count) > 1e-9 * max(1.0, count):
        raise ValueError(f"periods = {periods:g} with per_period = {per_period} is "
                         f"{periods * per_period:g} output intervals: the run ends on an "
                         f"output time, so periods x per_period must be a whole number "
                         f"(e.g. periods = {max(count, 1)}, or per_period a multiple of "
                         f"{_denominator(periods)})")
    span = periods * 2.0 * math.pi / omega
    if span > MAX_TIME:
        raise ValueError(f"periods = {periods:g} forcing periods of 2 pi/omega = "
                         f"{2 * math.pi / omega:.3g} span t = {span:.3g}, beyond the longest "
                         f"run of {MAX_TIME:g} time units")
    from opa._memory import check_memory

    check_memory(f"{count + 1} output times (periods {periods:g} x per_period "
                 f"{per_period})", (count + 1) * 8 * 4)
    return np.arange(count + 1) * (2.0 * math.pi / omega / per_period)


def check_span(oscillator: Oscillator, t_end: float, impulse: bool = True,
               t_start: float = 0.0) -> None:
    """Refuse runs the integrator cannot resolve or finish: a forcing or impulse period
    below MIN_PERIOD, a span beyond MAX_TIME, or more than MAX_IMPULSES impulses."""
    t_start = _finite("the start time", t_start)
    if abs(t_start) > MAX_TIME:
        raise ValueError(f"the run starts at t = {t_start:.3g}, beyond the longest run of "
                         f"{MAX_TIME:g} time units")
    t_end = _finite("the end time", t_end)
    if abs(t_end) > MAX_TIME or abs(t_end - t_start) > MAX_TIME:
        raise ValueError(f"the run spans t = {t_end:.3g}, beyond the longest run of "
                         f"{MAX_TIME:g} time units")
    period = 2.0 * math.pi / oscillator.omega
    if oscillator.f != 0.0 and period < MIN_PERIOD:
        raise ValueError(f"omega = {oscillator.omega:g} gives a forcing period 2 pi/omega = "
                         f"{period:.3g}, below the resolvable {MIN_PERIOD:g}")
    if impulse and oscillator.F0 != 0.0:
        period1 = 2.0 * math.pi / oscillator.omega1
        if period1 < MIN_PERIOD:
            raise ValueError(f"omega1 = {oscillator.omega1:g} gives an impulse period 2 pi/"
                             f"omega1 = {period1:.3g}, below the resolvable {MIN_PERIOD:g}")
        count = abs(t_end - min(t_start, 0.0)) / period1
        if count > MAX_IMPULSES:
            raise ValueError(f"omega1 = {oscillator.omega1:g} puts {count:.3g} impulses in "
                             f"t in [0, {t_end:.3g}], more than {MAX_IMPULSES:g}")


__all__ = [
    "Oscillator",
    "SolverOptions",
    "Uncertainty",
    "preset",
    "time_grid",
    "PARAMETER_NAMES",
]


def law_from_attrs(attrs, constants: dict) -> ForceLaw:
    """A user's force law from a dataset's ``force_law`` and ``force_kind`` (absent: a
    polynomial; "compiled": the expression compiled; "function": ``module:name`` of a
    function, imported)."""
    kind = str(attrs.get("force_kind", "polynomial"))
    text = str(attrs["force_law"])
    if kind == "function":
        from opa._forcefunction import imported_function

        return ForceLaw.from_function(imported_function(text), **constants)
    if kind == "compiled":
        return ForceLaw.compiled(text, **constants)
    if kind != "polynomial":
        raise ValueError(f"force_kind {kind!r:.40} is none of polynomial, compiled, function")
    return ForceLaw(text, **constants)
