"""The trust map's configuration: :class:`ValidateConfig` (what ``opa-mc validate`` runs,
checked once), its TOML file (:func:`load_config`) and the sets and defaults it draws on.
The computation and the dataset are :mod:`compare._trustmap`'s."""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
from dataclasses import dataclass, field

import numpy as np

from opa.engine import (
    IMPULSE_FIELDS, MAX_ELEMENTS, MAX_GRID, PARAMETER_NAMES, check_memory, check_order,
    check_span, Measure, Oscillator, parse as parse_law, preset, read_toml, SolverOptions,
    System,
)

# The single-element variants (impact law, truncation) under the semicircle law. Under
# another law of xi the `paper` truncation (eq. (27), written in the semicircle's basis)
# does not exist: the map runs the three impact laws with the exact Galerkin projection
# in that law's orthonormal basis (LAW_VARIANTS).
VARIANTS = (("mean", "galerkin"), ("ensemble", "galerkin"), ("mean", "paper"),
            ("ensemble", "paper"), ("saltation", "galerkin"))
ELEMENT_LAWS = ("mean", "ensemble", "saltation")
LAW_VARIANTS = tuple((law, "galerkin") for law in ELEMENT_LAWS)
# Multi-element variants: the impact laws of ELEMENT_LAWS, Galerkin truncation, run at
# N = Nmax only (the order sigma* is read at); adaptive refinement stops when every
# element's variance share is below ELEMENT_TOLERANCE (simulate's default) or the budget
# is spent.
ELEMENT_TOLERANCE = 1e-6
DEFAULT_MAX_ELEMENTS = 64
CRITERIA = ("mean", "variance")

# The swept parameter's default range for each of the paper's sets (sections 3.1-3.3).
SWEEPS = {
    "3.1": ("c", tuple(np.round(np.linspace(0.01, 0.1, 7), 6))),
    "3.2": ("omega", (3.98, 4.035, 4.09, 4.145, 4.2)),
    "3.3": ("omega", tuple(np.round(np.linspace(3.9, 5.9, 6), 6))),
}
DEFAULT_SIGMAS = (0.005, 0.01, 0.014, 0.02, 0.025, 0.03, 0.04, 0.05)
SIGMAS_33 = (0.01, 0.02, 0.05, 0.1, 0.14, 0.16, 0.18, 0.2)


@dataclass(frozen=True)
class ValidateConfig:
    """What ``opa-mc validate`` runs; the defaults are the embedded default job.

    The section 3.2 set, omega in {3.98, 4.035, 4.09, 4.145, 4.2}, sigma from 0.005 to
    0.05 (the paper's 0.01, 0.014, 0.02, 0.03 included), N = 0..8, all five variants,
    horizons of 10 and 50 forcing periods, 8 outputs per period, Sobol ensembles of 128
    samples (16 replicates) paired with every OPA run as a control variate and doubled up
    to 8192 while a verdict is undecided, tolerance 0.1 of the spread for the mean and
    0.25 of the variance for the variance, each verdict wrong with probability at most
    alpha = 0.01, sigma* to 1e-3, splits located to 1e-6 in xi at the smallest sigma.
    """

    preset: str = "3.2"
    oscillator: Oscillator = field(default_factory=lambda: preset("3.2"))
    options: SolverOptions = field(default_factory=lambda: SolverOptions(rtol=1e-9, atol=1e-9))
    parameter: str = "omega"
    values: tuple[float, ...] = SWEEPS["3.2"][1]
    sigmas: tuple[float, ...] = DEFAULT_SIGMAS
    orders: tuple[int, ...] = tuple(range(9))
    uncertain: str = "mu"
    impulse: str = "dirac"  # the impulse model: opa.System's fields of the same names
    pulse_width: float = 0.1
    impulse_at_zero: bool = True
    horizons: tuple[float, ...] = (10.0, 50.0)
    per_period: int = 8
    samples: int = 128
    max_samples: int = 8192
    seed: int = 0
    tolerance: float = 0.1
    var_tolerance: float = 0.25
    alpha: float = 0.01
    resolution: float = 1e-3
    split_resolution: float = 1e-6
    # the most splits one scan locates over each horizon longer than the shortest (the
    # shortest: opa._splits.MAX_SPLITS); past it the list is complete only within a
    # radius, reported, and the impact counts beyond it are marked unknown
    long_splits: int = 128
    outdir: str = "results"
    plots: bool = True
    scheduler: str | None = None
    # local processes for the map's tasks (compare._mapflow): 1 runs the values one after
    # the other in this process, numba's threads sharing the cores; 0: one per core up to
    # the number of tasks, where the values and the frontier are at least 3 (auto_workers)
    workers: int = 0
    frontier: bool = True
    # the law of xi (a name of opa._measure.DISTRIBUTIONS) and the multi-element variants:
    # None (single element only), K >= 2 equal-probability elements, or "adaptive" with a
    # budget of max_elements (default 64; refused without "adaptive")
    distribution: str = "semicircle"
    elements: int | str | None = None
    max_elements: int | None = None

    @property
    def execution(self):
        """Where the map's tasks run (:class:`opa.Execution`): :attr:`processes` local
        processes, or the Dask cluster ``scheduler``."""
        from opa.engine import Execution

        if self.scheduler is not None:
            return Execution(scheduler=self.scheduler)
        return Execution(workers=self.processes)

    @property
    def processes(self) -> int:
        """The local processes the map runs on (``workers``, 0 resolved by
        :func:`compare._scaleout.auto_workers`: a pool where the values and the frontier
        are at least 3, of one process per core up to the map's first tasks,
        :attr:`first_tasks`)."""
        from compare._scaleout import auto_workers

        if self.workers:
            return int(self.workers)
        if auto_workers(len(self.values) + bool(self.frontier)) == 1:
            return 1
        return auto_workers(self.first_tasks)

    @property
    def first_tasks(self) -> int:
        """The tasks of the map's first stages on a pool or a cluster
        (:class:`compare._mapflow.MapFlow`: every value's split scan, then its grid
        points, and the frontier's reference): what the cores are shared among."""
        return len(self.values) * (1 + len(self.sigmas)) + bool(self.frontier)

    def __post_init__(self):
        # what the configuration builds once: the law of xi, and each System it is asked
        # for (system_at), kept here (not fields: equality and replace() ignore them)
        object.__setattr__(self, "_built", {})
        self._check_law()
        for name in ("samples", "max_samples", "per_period", "seed", "long_splits",
                     "workers"):
            value = getattr(self, name)
            if not isinstance(value, numbers.Integral) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if not -2**53 <= value <= 2**53:
                raise ValueError(f"{name} must be at most 2^53, got {value}")
        if not 0 <= self.workers <= 4 * (os.cpu_count() or 1):
            raise ValueError(f"workers must be between 0 (auto) and "
                             f"{4 * (os.cpu_count() or 1)} (4 per CPU), got {self.workers}")
        if self.scheduler is not None and self.workers > 1:
            raise ValueError("workers has no effect with a scheduler (the Dask cluster's "
                             "workers run the tasks): give one or the other")
        if self.scheduler is not None:
            from mc import check_scheduler_address

            check_scheduler_address(self.scheduler)
        if not isinstance(self.orders, tuple) or not all(
                isinstance(n, numbers.Integral) and not isinstance(n, bool)
                for n in self.orders):
            raise ValueError(f"orders must be a list of integers, got {self.orders!r:.80}")
        for name in ("tolerance", "var_tolerance", "alpha", "resolution", "split_resolution"):
            value = getattr(self, name)
            if not isinstance(value, numbers.Real) or isinstance(value, bool):
                raise ValueError(f"{name} must be a number, got {value!r}")
        for name in ("outdir", "preset", "parameter", "uncertain"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ValueError(f"{name} must be a non-empty string, got "
                                 f"{getattr(self, name)!r}")
        if self.parameter not in PARAMETER_NAMES or self.parameter in ("x0", "v0"):
            raise ValueError(f"parameter must be a model parameter, got {self.parameter!r}")
        if self.parameter == self.uncertain:
            raise ValueError(f"the swept parameter must differ from the uncertain one, got "
                             f"{self.parameter!r} for both")
        allowed = getattr(self.oscillator, "uncertain_names", ("mu", "a", "c"))
        if self.uncertain not in allowed:
            raise ValueError(f"uncertain must be one of {', '.join(allowed)}, got "
                             f"{self.uncertain!r}")
        for name in ("values", "sigmas", "horizons"):
            seq = getattr(self, name)
            if not isinstance(seq, tuple) or not seq or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                    for v in seq):
                raise ValueError(f"{name} must be a non-empty list of finite numbers, got {seq!r}")
            if len(set(seq)) != len(seq) or list(seq) != sorted(seq):
                raise ValueError(f"{name} must be strictly increasing, got {seq}")
        if self.sigmas[0] <= 0:
            raise ValueError(f"sigmas must be > 0, got {self.sigmas}")
        if self.horizons[0] <= 0:
            raise ValueError(f"horizons must be > 0 forcing periods, got {self.horizons}")
        if not self.orders or any(int(n) != n or n < 0 for n in self.orders):
            raise ValueError(f"orders must be non-negative integers, got {self.orders}")
        if list(self.orders) != sorted(set(self.orders)):
            raise ValueError(f"orders must be strictly increasing, got {self.orders}")
        if int(self.per_period) != self.per_period or self.per_period < 1:
            raise ValueError(f"per_period must be a positive integer, got {self.per_period}")
        for h in self.horizons:
            if abs(h * self.per_period - round(h * self.per_period)) > 1e-9:
                raise ValueError(f"horizon {h} is not a whole number of outputs at "
                                 f"per_period = {self.per_period}")
        if int(self.samples) != self.samples or self.samples < 64 or self.samples % 16:
            raise ValueError(f"samples must be a multiple of 16 and >= 64, got {self.samples}")
        if self.max_samples < self.samples:
            raise ValueError(f"max_samples must be >= samples, got {self.max_samples}")
        if self.long_splits < 1:
            raise ValueError(f"long_splits must be >= 1, got {self.long_splits}")
        for name in ("tolerance", "var_tolerance", "resolution", "split_resolution"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        # bisections that doubles cannot finish are refused, not run for ever
        if self.resolution < 1e-12 * max(self.sigmas):
            raise ValueError(f"resolution must be >= 1e-12 x the largest sigma (sigma* cannot "
                             f"be bisected finer in floating point), got {self.resolution:g}")
        if not 1e-12 <= self.split_resolution <= 1.0:
            raise ValueError(f"split_resolution must be in [1e-12, 1] (in xi, whose support "
                             f"is [-1, 1]), got {self.split_resolution:g}")
        if not 1e-9 <= self.alpha <= 0.5:
            raise ValueError(f"alpha (the error rate of a verdict) must be in [1e-9, 0.5], "
                             f"got {self.alpha:g}")
        for name in ("plots", "frontier"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        self._check_sizes()

    def _check_law(self) -> None:
        """The law of xi (stored under its canonical name) and the element settings."""
        if not isinstance(self.distribution, str) or not self.distribution:
            raise ValueError(f"distribution must be a name such as uniform or beta:2,3, got "
                             f"{self.distribution!r}")
        try:
            law = parse_law(self.distribution)
        except ValueError as err:
            text = str(err)
            raise ValueError(text if text.startswith("distribution") else
                             f"distribution {self.distribution!r}: {text}") from None
        if (law.lo, law.hi) != (-1.0, 1.0):
            raise ValueError(f"distribution must have the support [-1, 1], got "
                             f"[{law.lo:g}, {law.hi:g}] for {self.distribution!r}")
        object.__setattr__(self, "distribution", law.name)
        el = self.elements
        if el is not None and not (el == "adaptive" if isinstance(el, str) else (
                isinstance(el, numbers.Integral) and not isinstance(el, bool)
                and 2 <= el <= MAX_ELEMENTS)):
            raise ValueError(f"elements must be an integer in 2..{MAX_ELEMENTS} or 'adaptive' "
                             f"(one element is the single-element map), got {el!r}")
        if self.max_elements is not None:
            if el != "adaptive":
                raise ValueError(f"max_elements = {self.max_elements!r} is the budget of "
                                 f"adaptive elements and has no effect without elements = "
                                 f"'adaptive' (got elements = {el!r})")
            m = self.max_elements
            if not (isinstance(m, numbers.Integral) and not isinstance(m, bool)
                    and 2 <= m <= MAX_ELEMENTS):
                raise ValueError(f"max_elements must be an integer in 2..{MAX_ELEMENTS}, got "
                                 f"{m!r}")

    def _check_sizes(self) -> None:
        """Refuse maps that cannot finish or fit: grid sizes, orders, run lengths, memory."""
        if not isinstance(self.oscillator, Oscillator):
            raise ValueError(f"oscillator must be an Oscillator, got {self.oscillator!r:.60}")
        if not isinstance(self.options, SolverOptions):
            raise ValueError(f"options must be a SolverOptions, got {self.options!r:.60}")
        for name in ("values", "sigmas", "orders", "horizons"):
            if len(getattr(self, name)) > MAX_GRID:
                raise ValueError(f"{name}: at most {MAX_GRID} entries, got "
                                 f"{len(getattr(self, name))}")
        check_order(self.nmax)
        if self.max_samples > MAX_SAMPLES:
            raise ValueError(f"max_samples must be at most {MAX_SAMPLES}, got {self.max_samples}")
        for value in self.values:
            osc = self.oscillator_at(value)
            try:
                check_span(osc, max(self.horizons) * osc.forcing_period)
            except ValueError as err:
                raise ValueError(f"horizons up to {max(self.horizons):g} forcing periods at "
                                 f"{self.parameter} = {value:g}: {err}") from None
        outputs = round(max(self.horizons) * self.per_period) + 1
        check_memory(f"horizons up to {max(self.horizons):g} periods x per_period "
                     f"{self.per_period}", outputs * (2 * self.nmax + 8) * 8 * len(self.variants))
        for value in self.values:  # checks the impulse model (e.g. pulse_width < 2 pi/omega1)
            self.system_at(value)
        from opa.engine import check_work

        # the grid's ensembles at their largest (the bisections' probes come on top)
        check_work("this trust map", len(self.values) * len(self.sigmas) * self.max_samples
                   * max(self.horizons),
                   [("values", len(self.values)), ("sigmas", len(self.sigmas)),
                    ("max_samples", self.max_samples), ("horizons", f"{max(self.horizons):g}")])

    @property
    def nmax(self) -> int:
        return max(self.orders)

    @property
    def semicircle(self) -> bool:
        """Whether xi has the paper's law (the single-element variants then include the
        paper's truncation)."""
        return self.distribution == "semicircle"

    @property
    def single_variants(self) -> tuple[tuple[str, str], ...]:
        """(impact law, truncation) of the single-element variants: the paper's
        truncation only for the paper's law of xi and force law, and an uncertain mu, a
        or c (eq. (27) closes a coefficient of that law)."""
        paper = (self.semicircle and self.oscillator.force is None
                 and self.uncertain in ("mu", "a", "c"))
        return VARIANTS if paper else LAW_VARIANTS

    @property
    def element_laws(self) -> tuple[str, ...]:
        """Impact laws of the multi-element variants (none without ``elements``)."""
        return () if self.elements is None else ELEMENT_LAWS

    @property
    def budget(self) -> int:
        """The element budget of adaptive elements."""
        return DEFAULT_MAX_ELEMENTS if self.max_elements is None else int(self.max_elements)

    @property
    def element_label(self) -> str:
        """'K8' or 'adaptive64' ('' without elements)."""
        if self.elements is None:
            return ""
        return f"adaptive{self.budget}" if self.elements == "adaptive" else f"K{self.elements}"

    @property
    def variants(self) -> list[str]:
        """Names of every variant: 'law/truncation' (one element), then 'law/ME-K8' or
        'law/ME-adaptive64' (multi-element, Galerkin)."""
        return ([f"{law}/{trunc}" for law, trunc in self.single_variants]
                + [f"{law}/ME-{self.element_label}" for law in self.element_laws])

    @property
    def dropped_variants(self) -> list[str]:
        """The single-element variants of the semicircle map this law cannot run."""
        return [f"{law}/{trunc}" for law, trunc in VARIANTS
                if (law, trunc) not in self.single_variants]

    def _once(self, key, build):
        """``build()``, built once per configuration and ``key``."""
        built = self._built
        if key not in built:
            built[key] = build()
        return built[key]

    def measure(self) -> Measure:
        """The law of xi (one object: its recurrences are cached)."""
        return self._once("measure", lambda: parse_law(self.distribution))

    def oscillator_at(self, value: float) -> Oscillator:
        value = float(value)
        return self._once(("oscillator", value),
                          lambda: self.oscillator.replace(**{self.parameter: value}))

    def system_at(self, value: float, **fields) -> System:
        """The :class:`opa.System` at one swept value (samples below zero allowed: the map
        crosses them on purpose), with ``fields`` (sigma, order, ...) and the law of xi
        (None for the semicircle, so that the default map runs as it always did). Each is
        built once per configuration and kept (a System is frozen)."""
        value = float(value)
        base = self._once(("system", value), lambda: System(
            self.oscillator_at(value), uncertain=self.uncertain, allow_negative=True,
            impulse=self.impulse, pulse_width=self.pulse_width,
            impulse_at_zero=self.impulse_at_zero,
            distribution=None if self.semicircle else self.distribution))
        if not fields:
            return base
        return self._once(("system", value, tuple(sorted(fields.items()))),
                          lambda: base.replace(**fields))


# Largest ensemble the map may double up to (2^20 samples, hours per point).
MAX_SAMPLES = 2**20


def load_config(path: str | None, **overrides) -> ValidateConfig:
    """A configuration from a TOML file (all keys optional) and keyword overrides.

    TOML layout::

        preset = "3.2"            # 3.1 sweeps c, 3.2 and 3.3 sweep omega
        parameter = "omega"
        values = [3.98, 4.09, 4.2]
        sigmas = [0.005, 0.01, 0.02]
        horizons = [10, 50]
        [model]                   # any Oscillator parameter
        F0 = 0.1
        [solver]                  # any SolverOptions field
        rtol = 1e-9
    """
    data: dict = {}
    if path is not None:
        data = read_toml(path)
    model = data.pop("model", {})
    solver = data.pop("solver", {})
    for name, table in (("model", model), ("solver", solver)):
        if not isinstance(table, dict):
            raise ValueError(f"config [{name}] must be a table, got {table!r}")
    model = {**model, **(overrides.pop("model", None) or {})}
    solver = {**solver, **(overrides.pop("solver", None) or {})}
    for name in IMPULSE_FIELDS:  # the impulse model is the system's ([solver] still works)
        if name in solver:
            data.setdefault(name, solver.pop(name))
    known = {f.name for f in dataclasses.fields(ValidateConfig)} - {"oscillator", "options"}
    unknown = set(data) - known
    if "z" in unknown or overrides.get("z") is not None:
        raise ValueError("config key z is gone: a verdict no longer adds z standard errors to "
                         "the tolerance; give alpha, the error rate of each verdict "
                         "(default 0.01)")
    if unknown:
        raise ValueError(f"unknown config key(s) {sorted(unknown)}; known: {sorted(known)}")
    data.update({k: v for k, v in overrides.items() if v is not None})
    name = data.setdefault("preset", model.pop("preset", "3.2"))
    if name not in SWEEPS:
        raise ValueError(f"preset must be one of {', '.join(SWEEPS)}, got {name!r}")
    parameter, values = SWEEPS[name]
    data.setdefault("parameter", parameter)
    if "values" not in data and data["parameter"] in model:
        data["values"] = (model[data["parameter"]],)  # e.g. --omega 4.0: a one-column map
    if "values" not in data:
        if data["parameter"] != parameter:
            raise ValueError(f"values are needed when sweeping {data['parameter']!r}")
        data["values"] = values
    if name == "3.3":
        data.setdefault("sigmas", SIGMAS_33)
    for key in ("values", "sigmas", "orders", "horizons"):
        if key in data:
            if not isinstance(data[key], (list, tuple)):
                raise ValueError(f"{key} must be a list, got {data[key]!r}")
            data[key] = tuple(data[key])
    try:
        options = dataclasses.replace(SolverOptions(rtol=1e-9, atol=1e-9), **solver)
        osc = preset(name, **model)
    except TypeError as err:
        raise ValueError(f"unknown model or solver key: {err}") from None
    return ValidateConfig(oscillator=osc, options=options, **data)


def noise_floor(options: SolverOptions) -> float:
    """Absolute error of x below which a difference is the solvers' own: 10 (rtol + atol)."""
    return 10.0 * (options.rtol + options.atol)


__all__ = ["CRITERIA", "SWEEPS", "VARIANTS", "ValidateConfig", "load_config", "noise_floor"]
