"""The trust map: where does OPA agree with Monte Carlo, where does it stop, and why?

Over a grid of the intensity sigma and one model parameter q (default: omega over the
section 3.2 range), each point runs

* a Monte Carlo ensemble of the true sampled impact system (scrambled Sobol, randomised-QMC
  standard errors of the mean and the variance), with more samples only where the verdict
  hangs on the MC noise (:func:`compare._trust.marginal`);
* the OPA equivalent system for every N and every variant (impact law x truncation),
  all compared with that one ensemble; under a law of xi other than the semicircle
  (``distribution``) the single element runs in that law's orthonormal basis and the
  ``paper`` truncation (eq. (27), the semicircle's) is left out;
* with ``elements`` (K, or ``"adaptive"`` with a budget), multi-element OPA under the
  mean, ensemble and saltation impact laws at N = Nmax, each with its own verdicts and
  sigma* beside the single-element ones. These are what ``simulate_opa`` with elements
  gives: an element whose OPA system diverges is computed by collocation of the true
  systems (counted in ``variant_collocated``). The single-element variants are the
  paper's OPA: a run that cannot be completed is NaN from there on, and disagrees;

and gives, per horizon, the RMS error of x_0 and of the variance (absolute, in MC standard
errors, relative to the spread) with the verdict of :mod:`compare._trust`. For each q,
``sigma*`` -- the largest sigma at which OPA at the highest N still agrees -- is located by
bisection in sigma between the last agreeing and the first failing grid value. The sampled
systems' impact sequences are scanned along the uncertain parameter
(:func:`opa._splits.scan_splits`): their splits, what happens there, and the distribution
of impact counts at every grid point say *why* the boundary is where it is.

Every piece of work is written to ``OUTDIR/parts/`` as it finishes (:class:`Parts`) and
reused by a rerun, so an interrupted map resumes and a finished one is reassembled without
integrating anything. Each file name ends in a hash of everything that determines its
content, and the file stores that hash too::

    mc_<q><value>_sigma<sigma>_M<samples>_<key>.nc   a Monte Carlo ensemble's moments
    opa_<q><value>_sigma<sigma>_N<order>_<key>.npz   OPA at one N, the single-element variants
    elements_<q><value>_sigma<sigma>_N<order>_<key>.npz  multi-element OPA (N = Nmax), per law
    splits_<q><value>_<key>.npz                      the split scan at one value
    details_<q><value>_sigma<sigma>_<key>.nc         phase portraits, EMR_0 against DMR
    frontier_<run>_<key>.npz                         one run of the cost-accuracy study

A part that cannot be read, or whose stored hash is not the expected one (a file copied
or left from other settings), is named in the log, moved aside to ``<name>.bad`` and
computed again; temporaries left by a killed run are removed when the next one starts.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import numbers
import os
import time
import tomllib
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from compare._trust import bisect_boundary, first_disagreement, marginal, window_errors
from mc._ensemble import simulate_mc
from mc._sampling import semicircle_cdf
from opa._dataset import atomic_write, clean_stale_temporaries, provenance_attrs, write_netcdf
from opa._elements import (MAX_ELEMENTS, adaptive_edges, collocate_element, run_elements,
                           uniform_edges)
from opa._measure import Measure, parse as parse_law
from opa._memory import check_memory
from opa._model import (MAX_GRID, PARAMETER_NAMES, Oscillator, SolverOptions, check_order, check_span,
                        preset, time_grid)
from opa._run import SimulationError
from opa._simulate import opa_variants, simulate_dmr, simulate_opa
from opa._system import IMPULSE_FIELDS, System
from opa._splits import (MAX_CROSSINGS, MAX_SPLITS, SPLIT_KINDS, Split, count_probabilities,
                         scan_splits)

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
PAPER_SIGMAS = (0.01, 0.014, 0.02, 0.03)

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
    horizons of 10 and 50 forcing periods, 8 outputs per period, Sobol ensembles of 1024
    samples doubled up to 8192 where the verdict hangs on the MC noise, tolerance 0.1 of
    the spread for the mean and 0.25 of the variance for the variance, 3 standard errors
    of allowance, sigma* to 1e-3, splits located to 1e-6 in xi at the smallest sigma.
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
    samples: int = 1024
    max_samples: int = 8192
    seed: int = 0
    tolerance: float = 0.1
    var_tolerance: float = 0.25
    z: float = 3.0
    resolution: float = 1e-3
    split_resolution: float = 1e-6
    outdir: str = "results"
    plots: bool = True
    scheduler: str | None = None
    frontier: bool = True
    # the law of xi (a name of opa._measure.DISTRIBUTIONS) and the multi-element variants:
    # None (single element only), K >= 2 equal-probability elements, or "adaptive" with a
    # budget of max_elements (default 64; refused without "adaptive")
    distribution: str = "semicircle"
    elements: int | str | None = None
    max_elements: int | None = None

    def __post_init__(self):
        self._check_law()
        for name in ("samples", "max_samples", "per_period", "seed"):
            value = getattr(self, name)
            if not isinstance(value, numbers.Integral) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if not -2**53 <= value <= 2**53:
                raise ValueError(f"{name} must be at most 2^53, got {value}")
        if self.scheduler is not None and (not isinstance(self.scheduler, str)
                                           or not self.scheduler.strip()):
            raise ValueError(f"scheduler must be an address such as tcp://host:8786, got "
                             f"{self.scheduler!r:.60}")
        if not isinstance(self.orders, tuple) or not all(
                isinstance(n, numbers.Integral) and not isinstance(n, bool)
                for n in self.orders):
            raise ValueError(f"orders must be a list of integers, got {self.orders!r:.80}")
        for name in ("tolerance", "var_tolerance", "z", "resolution", "split_resolution"):
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
        if self.uncertain not in ("mu", "a", "c"):
            raise ValueError(f"uncertain must be one of mu, a, c, got {self.uncertain!r}")
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
        if not (math.isfinite(self.z) and self.z >= 0):
            raise ValueError(f"z must be >= 0, got {self.z}")
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
        """(impact law, truncation) of the single-element variants."""
        return VARIANTS if self.semicircle else LAW_VARIANTS

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

    def measure(self) -> Measure:
        return parse_law(self.distribution)

    def oscillator_at(self, value: float) -> Oscillator:
        return self.oscillator.replace(**{self.parameter: float(value)})

    def system_at(self, value: float, **fields) -> System:
        """The :class:`opa.System` at one swept value (samples below zero allowed: the map
        crosses them on purpose), with ``fields`` (sigma, order, ...) and the law of xi
        (None for the semicircle, so that the default map runs as it always did)."""
        return System(self.oscillator_at(value), uncertain=self.uncertain, allow_negative=True,
                      impulse=self.impulse, pulse_width=self.pulse_width,
                      impulse_at_zero=self.impulse_at_zero,
                      distribution=None if self.semicircle else self.distribution, **fields)

    def impulse_key(self) -> list:
        """The impulse model, for the hashes of the parts (only when not the default, so
        that the parts of earlier versions stay valid)."""
        model = [self.impulse, self.pulse_width, self.impulse_at_zero]
        return [] if model == ["dirac", 0.1, True] else [model]

    def law_key(self) -> list:
        """The law of xi, for the hashes of the parts (only when not the semicircle, so
        that the default map's parts stay valid)."""
        return [] if self.semicircle else [["distribution", self.distribution]]

    def key(self, value: float, sigma: float, samples: int) -> str:
        """A hash of everything one Monte Carlo run of the map depends on."""
        return digest([self.oscillator_at(value).as_dict(), dataclasses.asdict(self.options),
                       sigma, self.uncertain, samples, self.seed, max(self.horizons),
                       self.per_period, self.nmax, *self.impulse_key(), *self.law_key()])

    def opa_key(self, value: float, sigma: float, order: int) -> str:
        """A hash of everything the single-element OPA runs of the map at one point and
        one N depend on."""
        return digest(["opa", self.oscillator_at(value).as_dict(),
                       dataclasses.asdict(self.options), float(sigma), int(order),
                       self.uncertain, self.single_variants, max(self.horizons),
                       self.per_period, *self.impulse_key(), *self.law_key()])

    def element_key(self, value: float, sigma: float, order: int) -> str:
        """A hash of everything the multi-element runs at one point and one N depend on."""
        return digest(["elements", self.oscillator_at(value).as_dict(),
                       dataclasses.asdict(self.options), float(sigma), int(order),
                       self.uncertain, self.distribution, self.element_laws, self.elements,
                       self.budget if self.elements == "adaptive" else None,
                       ELEMENT_TOLERANCE, "collocation of failed elements",
                       max(self.horizons), self.per_period, *self.impulse_key()])

    def splits_key(self, value: float) -> str:
        """A hash of everything the split scan at one swept value depends on."""
        return digest(["splits", self.oscillator_at(value).as_dict(),
                       dataclasses.asdict(self.options), self.uncertain, max(self.sigmas),
                       min(self.sigmas), self.horizons, self.split_resolution,
                       *self.impulse_key(), "complete", self.per_period,
                       MAX_SPLITS, MAX_CROSSINGS])


def digest(payload) -> str:
    """A 12-hex-digit hash of ``payload`` (anything ``json`` writes, floats exactly)."""
    blob = json.dumps(payload, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


# Largest ensemble the map may double up to (2^20 samples, hours per point).
MAX_SAMPLES = 2**20


#: the largest config file read (a validate config is a few hundred bytes)
MAX_CONFIG_BYTES = 1 << 20
#: the deepest nesting of arrays and tables a config may have ([model] holds numbers)
MAX_CONFIG_DEPTH = 4


def _read_toml(path) -> dict:
    """A config file's TOML: a regular file (not a FIFO, device or folder) of at most
    MAX_CONFIG_BYTES, nested at most MAX_CONFIG_DEPTH deep."""
    import stat

    try:
        info = os.stat(path)
    except OSError as err:
        raise ValueError(f"config file {path}: {err.strerror}") from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"config file {path}: not a regular file")
    if info.st_size > MAX_CONFIG_BYTES:
        raise ValueError(f"config file {path}: {info.st_size} bytes, more than the "
                         f"{MAX_CONFIG_BYTES} a config may have")
    try:
        with open(path, "rb") as fh:
            blob = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as err:
        raise ValueError(f"config file {path}: {err.strerror}") from None
    if len(blob) > MAX_CONFIG_BYTES:
        raise ValueError(f"config file {path}: more than the {MAX_CONFIG_BYTES} bytes a "
                         f"config may have")
    try:
        data = tomllib.loads(blob.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"config file {path} is not valid TOML: {err}") from None
    except RecursionError:
        raise ValueError(f"config file {path}: arrays or tables nested too deeply (at most "
                         f"{MAX_CONFIG_DEPTH} levels)") from None

    def depth(value) -> int:
        if isinstance(value, dict):
            return 1 + max(map(depth, value.values()), default=0)
        if isinstance(value, list):
            return 1 + max(map(depth, value), default=0)
        return 0

    for key, value in data.items():
        if depth(value) > MAX_CONFIG_DEPTH - 1:
            raise ValueError(f"config file {path}: key {key!r} is nested too deeply (at most "
                             f"{MAX_CONFIG_DEPTH} levels)")
    return data


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
        data = _read_toml(path)
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


# --------------------------------------------------------------------------- parts on disk

# Temporaries are named .tmp-opa-mc-<pid>-<random><suffix> (as opa._dataset names them), so
# that the next run can tell whether their writer is still alive.


class Parts:
    """Finished pieces of work in one directory, each found again by the hash of what
    determines it.

    :meth:`dataset` (netCDF) and :meth:`arrays` (``.npz``: arrays, numbers, strings) return
    the part stored under ``<stem>_<key>`` when it is readable and stores ``key``;
    otherwise they compute it, write it atomically (a temporary in the same directory,
    flushed, then renamed over the name) and return what was written, read back, so that
    a fresh result and a reused one are the same to the bit. A part that cannot be read
    or stores another key is logged, renamed to ``<name>.bad`` (replacing an older one)
    and computed again.
    """

    def __init__(self, directory: str, log):
        self.directory = directory
        self.log = log
        self.computed = 0  # parts written by this object
        self.set_aside = 0

    def clean(self) -> list[str]:
        """Remove the temporaries that killed writers left (see
        :func:`opa._dataset.clean_stale_temporaries`). Returns their names."""
        removed = sorted(os.path.basename(p) for p in clean_stale_temporaries(self.directory))
        if removed:
            self.log(f"parts: removed {len(removed)} temporary file(s) an interrupted run "
                     f"left behind: {', '.join(removed)}")
        return removed

    def dataset(self, stem: str, key: str, compute, *, check=None) -> xr.Dataset:
        """The netCDF part ``<stem>_<key>.nc``; ``compute()`` returns an ``xr.Dataset``.

        ``check(ds)`` judges a stored part that carries no key (written by an older
        version): it returns why the part does not fit, or None to accept it.
        """
        path = os.path.join(self.directory, f"{stem}_{key}.nc")

        def save(ds, tmp):
            ds.assign_attrs(part_key=key).to_netcdf(tmp, engine="netcdf4")

        ds = self._get(path, key, _read_dataset, compute, save, check)
        ds.attrs.pop("part_key", None)
        return ds

    def arrays(self, stem: str, key: str, compute) -> dict:
        """The ``.npz`` part ``<stem>_<key>.npz``; ``compute()`` returns a dict of arrays,
        numbers and strings (0-d entries come back as Python scalars)."""
        path = os.path.join(self.directory, f"{stem}_{key}.npz")

        def save(content, tmp):
            if "part_key" in content:
                raise ValueError("part_key is a reserved name in a part")
            with open(tmp, "wb") as fh:
                np.savez(fh, **content, part_key=np.str_(key))

        out = self._get(path, key, _read_arrays, compute, save, None)
        out.pop("part_key")
        return out

    def _get(self, path, key, read, compute, save, check):
        found = self._load(path, key, read, check)
        if found is not None:
            return found
        content = compute()  # before the temporary exists: a kill here leaves nothing
        self._write(path, lambda tmp: save(content, tmp))
        self.computed += 1
        return read(path)  # what the next run will read, not what was computed

    def _load(self, path, key, read, check):
        if not os.path.lexists(path):
            return None
        try:
            content = read(path)
        except Exception as err:  # noqa: BLE001 -- whatever makes it unreadable: recompute
            reason = f"cannot be read ({type(err).__name__}: {err})".replace("\n", " ")
        else:
            stored = _stored_key(content)
            if stored == key:
                return content
            if stored is None and check is not None:
                reason = check(content)
                if reason is None:
                    return content
            elif stored is None:
                reason = "stores no key"
            else:
                reason = f"stores the key {stored}, not {key}: it belongs to other settings"
        name = os.path.basename(path)
        os.replace(path, path + ".bad")
        self.set_aside += 1
        self.log(f"parts: {name} {reason}; moved aside to {name}.bad, computing it again")
        return None

    def _write(self, path, write):
        atomic_write(path, write, suffix=os.path.splitext(path)[1], clean=False)


def _read_dataset(path: str) -> xr.Dataset:
    with xr.open_dataset(path, engine="netcdf4") as ds:
        return ds.load()


def _read_arrays(path: str) -> dict:
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as npz:  # closed on errors too
        content = {name: npz[name] for name in npz.files}
    return {name: (a.item() if a.ndim == 0 else a) for name, a in content.items()}


def _stored_key(content) -> str | None:
    stored = content.attrs.get("part_key") if isinstance(content, xr.Dataset) \
        else content.get("part_key")
    return None if stored is None else str(stored)


def _plain(value):
    return value.item() if isinstance(value, np.generic) else value


@dataclass
class Point:
    """One (q, sigma) of the map: the MC reference, the OPA curves and their verdicts."""

    sigma: float
    samples: int
    mc: dict  # x_mean, x_var, x_sem, x_var_sem (over outputs), impacts (min, max), seconds
    opa_mean: np.ndarray  # (variant, N, output)
    opa_var: np.ndarray
    first_impact: np.ndarray  # (variant, N) in forcing periods
    errors: np.ndarray  # (variant, N, horizon, criterion, 3): abs, in SE, relative
    pre_impact: np.ndarray  # (variant, N) RMS error of the mean before OPA's first impact
    disagree: np.ndarray  # (variant, N, criterion) first time of disagreement [periods]
    agrees: np.ndarray  # (variant, N, horizon, criterion) bool
    seconds: float = 0.0
    elements: np.ndarray | None = None  # (variant,) elements at N = Nmax (0: failed)
    collocated: np.ndarray | None = None  # (variant,) of them computed by collocation
    failure: str = ""  # why a multi-element variant could not be run


class _Map:
    """The computation for one configuration (one object so that caches are shared)."""

    def __init__(self, cfg: ValidateConfig, *, progress: bool, log):
        self.cfg = cfg
        self.log = log
        self.progress = progress
        self.parts = Parts(os.path.join(cfg.outdir, "parts"), log)
        self.floor = noise_floor(cfg.options)
        self.n_h = [int(round(h * cfg.per_period)) + 1 for h in cfg.horizons]
        self.mc_runs = 0
        self.opa_runs = 0
        self.bar = None
        self.measure = cfg.measure()  # one object: its recurrences are cached

    def _name(self, value, sigma=None) -> str:
        name = f"{self.cfg.parameter}{value:g}"
        return name if sigma is None else f"{name}_sigma{sigma:.6g}"

    # -- one point ---------------------------------------------------------------------
    def _mc(self, osc, value, sigma, samples, times):
        cfg = self.cfg

        def compute():
            start = time.perf_counter()
            ds = simulate_mc(cfg.system_at(value, sigma=sigma, order=0), samples=samples,
                             sampler="sobol", seed=cfg.seed, times=times, options=cfg.options,
                             scheduler=cfg.scheduler, progress=False)
            self.mc_runs += 1
            return ds.drop_vars(["xi", "weight", "sample", "n_impacts"]).assign_attrs(
                impacts_min=int(ds.n_impacts.min()), impacts_max=int(ds.n_impacts.max()),
                wall_seconds=time.perf_counter() - start)

        def check(ds):  # a part of an older version, which stored no key
            expected = {**provenance_attrs("mc", cfg.system_at(value, sigma=sigma),
                                           cfg.options, seed=cfg.seed),
                        "samples": samples}
            wrong = [f"{name}={_plain(ds.attrs.get(name))!r} (expected {expected[name]!r})"
                     for name in (*PARAMETER_NAMES, "sigma", "uncertain", "seed", "samples",
                                  "rtol", "atol")
                     if ds.attrs.get(name) != expected[name]]
            if ds.sizes.get("time", 0) != len(times):
                wrong.append(f"{ds.sizes.get('time', 0)} outputs")
            return f"does not fit these settings ({', '.join(wrong)})" if wrong else None

        return self.parts.dataset(f"mc_{self._name(value, sigma)}_M{samples}",
                                  cfg.key(value, sigma, samples), compute, check=check)

    def _opa(self, osc, value, sigma, order, times) -> dict:
        """Every single-element variant of OPA at one N: x_mean, x_var (variant, output),
        first_impact (variant,) in time units, and the wall time. Under the semicircle the
        paper's system (:func:`opa.opa_variants`); under another law one element over
        the whole support, in that law's orthonormal basis (:func:`element_variants`)."""
        cfg = self.cfg

        def compute():
            start = time.perf_counter()
            system = cfg.system_at(value, sigma=sigma, order=order)
            if cfg.semicircle:
                mean, var, first = opa_variants(system, list(cfg.single_variants), times,
                                                cfg.options)
            else:
                whole = np.array([self.measure.lo, self.measure.hi])
                run = element_variants(system, cfg.options, self.measure,
                                       [law for law, _ in cfg.single_variants],
                                       [whole] * len(cfg.single_variants), times)
                mean, var, first = run["x_mean"], run["x_var"], run["first_impact"]
            self.opa_runs += 1
            return {"x_mean": mean, "x_var": var, "first_impact": first,
                    "seconds": time.perf_counter() - start}

        return self.parts.arrays(f"opa_{self._name(value, sigma)}_N{order}",
                                 cfg.opa_key(value, sigma, order), compute)

    def _elements(self, value, sigma, order, times) -> dict:
        """The multi-element variants at one N (one per law of ``cfg.element_laws``):
        x_mean, x_var (law, output), first_impact (law,), elements (law,) and the wall
        time. Adaptive edges are chosen per law (:func:`opa._elements.adaptive_edges`).
        As in ``simulate_opa`` with elements, an element whose OPA system cannot be
        completed is computed by collocation of the true systems (counted in
        ``collocated``); where even that fails the variant is NaN throughout and
        ``failure`` says why."""
        cfg = self.cfg

        def compute():
            start = time.perf_counter()
            system = cfg.system_at(value, sigma=sigma, order=order)
            L = len(cfg.element_laws)
            mean, var = np.full((L, len(times)), np.nan), np.full((L, len(times)), np.nan)
            first, count = np.full(L, np.nan), np.zeros(L, np.int64)
            collocated = np.zeros(L, np.int64)
            failures = []
            for ell, law in enumerate(cfg.element_laws):
                try:
                    if cfg.elements == "adaptive":
                        runs, _ = adaptive_edges(system.replace(impact_law=law), cfg.options,
                                                 self.measure, times=times,
                                                 tolerance=ELEMENT_TOLERANCE,
                                                 max_elements=cfg.budget)
                        edges = np.array([r.a for r in runs] + [runs[-1].b])
                    else:
                        edges = uniform_edges(self.measure, int(cfg.elements))
                    run = element_variants(system, cfg.options, self.measure, [law], [edges],
                                           times, fallback=True)
                except SimulationError as err:  # even the true systems' collocation failed
                    failures.append(f"{law}: {err}")
                    continue
                mean[ell], var[ell] = run["x_mean"][0], run["x_var"][0]
                first[ell], count[ell] = run["first_impact"][0], run["elements"][0]
                collocated[ell] = run["collocated"][0]
            self.opa_runs += 1
            return {"x_mean": mean, "x_var": var, "first_impact": first, "elements": count,
                    "collocated": collocated, "failure": " | ".join(failures),
                    "seconds": time.perf_counter() - start}

        return self.parts.arrays(f"elements_{self._name(value, sigma)}_N{order}",
                                 cfg.element_key(value, sigma, order), compute)

    def evaluate(self, value: float, sigma: float, orders=None) -> Point:
        """OPA (``orders``, default all) and Monte Carlo at one point, with verdicts.

        The multi-element variants run at N = Nmax only (NaN at the other N). The point's
        wall time is that of its runs (OPA, and every Monte Carlo ensemble it took), as
        stored in the parts: a reused point reports what it cost."""
        cfg = self.cfg
        osc = cfg.oscillator_at(value)
        times = time_grid(osc.omega, max(cfg.horizons), cfg.per_period)
        orders = cfg.orders if orders is None else orders
        S, V, N = len(cfg.single_variants), len(cfg.variants), len(orders)
        opa_mean = np.full((V, N, len(times)), np.nan)
        opa_var = np.full((V, N, len(times)), np.nan)
        first = np.full((V, N), np.nan)
        elements = np.zeros(V, np.int64)
        elements[:S] = 1
        collocated = np.zeros(V, np.int64)
        T = osc.forcing_period
        seconds = 0.0
        failure = ""
        for k, order in enumerate(orders):  # the variants of one N run in parallel
            run = self._opa(osc, value, sigma, order, times)
            opa_mean[:S, k], opa_var[:S, k] = run["x_mean"], run["x_var"]
            first[:S, k] = run["first_impact"] / T
            seconds += run["seconds"]
            if cfg.element_laws and order == cfg.nmax:
                run = self._elements(value, sigma, order, times)
                opa_mean[S:, k], opa_var[S:, k] = run["x_mean"], run["x_var"]
                first[S:, k] = run["first_impact"] / T
                elements[S:] = run["elements"]
                collocated[S:] = run["collocated"]
                failure = str(run["failure"])
                seconds += run["seconds"]
                if failure:
                    self.log(f"{self._name(value, sigma)}, N = {order}: multi-element "
                             f"variant not run ({failure})")
        samples = cfg.samples
        while True:
            mc = self._mc(osc, value, sigma, samples, times)
            seconds += float(mc.attrs["wall_seconds"])
            point = self._judge(sigma, samples, mc, opa_mean, opa_var, first, times / T)
            if samples * 2 > cfg.max_samples or not self._hangs_on_noise(point):
                break
            samples *= 2
        point.seconds = seconds
        point.elements = elements
        point.collocated = collocated
        point.failure = failure
        return point

    def _hangs_on_noise(self, point: Point) -> bool:
        cfg, k = self.cfg, -1  # the verdict that sigma* hangs on: N = Nmax
        mc = point.mc
        sd = np.sqrt(np.maximum(mc["x_var"], 0.0))
        for v in range(len(cfg.variants)):
            e_mean = point.opa_mean[v, k] - mc["x_mean"]
            e_var = point.opa_var[v, k] - mc["x_var"]
            for n in self.n_h:
                if marginal(e_mean, sd, mc["x_sem"], tol=cfg.tolerance, z=cfg.z,
                            floor=self.floor, upto=n):
                    return True
                if marginal(e_var, mc["x_var"], mc["x_var_sem"], tol=cfg.var_tolerance,
                            z=cfg.z, floor=self.floor**2, upto=n):
                    return True
        return False

    def _judge(self, sigma, samples, mc_ds, opa_mean, opa_var, first, periods) -> Point:
        cfg = self.cfg
        mc = {name: mc_ds[name].values for name in ("x_mean", "x_var", "x_sem", "x_var_sem")}
        mc["impacts"] = (int(mc_ds.attrs["impacts_min"]), int(mc_ds.attrs["impacts_max"]))
        mc["seconds"] = float(mc_ds.attrs["wall_seconds"])
        mc["rhs"] = int(mc_ds.attrs["rhs_evaluations"])
        sd = np.sqrt(np.maximum(mc["x_var"], 0.0))
        V, N = opa_mean.shape[:2]
        H = len(cfg.horizons)
        errors = np.empty((V, N, H, 2, 3))
        disagree = np.empty((V, N, 2))
        pre = np.empty((V, N))
        for v in range(V):
            for k in range(N):
                checks = (
                    (opa_mean[v, k] - mc["x_mean"], sd, mc["x_sem"], cfg.tolerance, self.floor),
                    (opa_var[v, k] - mc["x_var"], mc["x_var"], mc["x_var_sem"],
                     cfg.var_tolerance, self.floor**2),
                )
                for c, (err, scale, sem, tol, floor) in enumerate(checks):
                    disagree[v, k, c] = first_disagreement(periods, err, scale, sem, tol=tol,
                                                           z=cfg.z, floor=floor)
                    for h, n in enumerate(self.n_h):
                        errors[v, k, h, c] = window_errors(err, scale, sem, n)
                before = periods < first[v, k]
                e0 = opa_mean[v, k][before] - mc["x_mean"][before]
                pre[v, k] = float(np.sqrt(np.mean(e0**2))) if before.any() else np.nan
        horizons = np.array(cfg.horizons)
        agrees = disagree[:, :, None, :] > horizons[None, None, :, None]
        return Point(sigma, samples, mc, opa_mean, opa_var, first, errors, pre, disagree,
                     agrees)

    # -- one value of the swept parameter ------------------------------------------------
    def splits(self, value: float) -> tuple[float, list[HorizonSplits]]:
        """The centre of the ensembles and, per horizon (in ``cfg.horizons`` order), the
        splits of the sampled systems' event sequences over the largest ensemble."""
        cfg = self.cfg
        osc = cfg.oscillator_at(value)
        centre = getattr(osc, cfg.uncertain)

        def compute():
            smax = max(cfg.sigmas)
            T = osc.forcing_period
            cache: dict = {"t_end": max(cfg.horizons) * T}
            found = {}
            for h in sorted(cfg.horizons, reverse=True):
                found[h] = scan_splits(
                    cfg.system_at(value), cfg.options, cfg.uncertain, centre - smax, centre + smax, h * T,
                    tol=cfg.split_resolution * min(cfg.sigmas), center=centre, cache=cache,
                    outputs=time_grid(osc.omega, h, cfg.per_period))
            seq_centre = cache.get(centre) or _sequence(cfg.system_at(value), cfg, cache,
                                                        centre)
            scans = []
            for h in cfg.horizons:
                speed, when = seq_centre.slowest_impact(h * T)
                scan = found[h]
                scans.append(HorizonSplits(
                    h, sorted(scan.splits + scan.crossings, key=lambda sp: sp.value),
                    scan.truncated, speed, when / T, seq_centre.count(h * T),
                    scan.complete_within, scan.crossings_within))
            return _splits_to_arrays(scans)

        stored = self.parts.arrays(f"splits_{self._name(value)}", cfg.splits_key(value),
                                   compute)
        return centre, _splits_from_arrays(stored)

    def boundary(self, value, grid: dict[float, Point]):
        """sigma* for every (variant, horizon, criterion) at N = Nmax, by bisection."""
        cfg = self.cfg
        k = -1  # N = Nmax; the probes run that order only
        probes: dict[float, Point] = dict(grid)
        V, H, C = len(cfg.variants), len(cfg.horizons), 2
        star = np.full((V, H, C, 2), np.nan)
        steps = np.zeros((V, H, C), dtype=np.int64)
        for v in range(V):
            for h in range(H):
                for c in range(C):
                    def agrees(s, v=v, h=h, c=c):
                        s = float(np.round(s, 12))
                        if s not in probes:
                            probes[s] = self.evaluate(value, s, orders=(cfg.nmax,))
                            self._tick()
                        return bool(probes[s].agrees[v, k, h, c])

                    known = sorted(probes)
                    failing = [s for s in known if not probes[s].agrees[v, k, h, c]]
                    if not failing:
                        star[v, h, c] = (known[-1], np.nan)  # agrees at every sigma tried
                        continue
                    hi = failing[0]
                    lo = max([s for s in known if s < hi], default=0.0)
                    lo, hi, n = bisect_boundary(agrees, lo, hi, cfg.resolution)
                    # the probes are stored under sigma rounded to 12 digits
                    star[v, h, c] = (np.round(lo, 12), np.round(hi, 12))
                    steps[v, h, c] = n
        return star, steps, probes

    def _tick(self):
        if self.bar is not None:
            self.bar.total += 1
            self.bar.update(1)

    def run(self) -> xr.Dataset:
        from tqdm.auto import tqdm

        cfg = self.cfg
        os.makedirs(self.parts.directory, exist_ok=True)
        self.parts.clean()
        total = len(cfg.values) * len(cfg.sigmas)
        results = []
        start = time.perf_counter()
        with tqdm(total=total, unit="point", desc="trust map", disable=not self.progress) as bar:
            self.bar = bar
            for value in cfg.values:
                self.log(f"{cfg.parameter} = {value:g}: impact-sequence splits, then "
                         f"{len(cfg.sigmas)} sigmas x {len(cfg.variants) * len(cfg.orders)} OPA "
                         f"runs against Monte Carlo ...")
                split_info = self.splits(value)
                grid = {}
                for sigma in cfg.sigmas:
                    grid[float(sigma)] = self.evaluate(value, float(sigma))
                    bar.update(1)
                star, steps, probes = self.boundary(value, grid)
                results.append((value, split_info, grid, star, steps, probes))
        self.bar = None
        ds = _assemble(cfg, results)
        ds = xr.merge([ds, self.details(results)], combine_attrs="drop_conflicts")
        if cfg.frontier:
            self.log("cost-accuracy frontier at the largest sigma ...")
            ds = xr.merge([ds, frontier(cfg, parts=self.parts)], combine_attrs="drop_conflicts")
        ds.attrs.update(_attrs(cfg))
        ds = ds.rename({"value": cfg.parameter})  # the sweep dimension (docs/datasets.md)
        # what this run did (the rest of the dataset is the same for a rerun)
        ds.attrs["wall_seconds"] = time.perf_counter() - start
        ds.attrs["mc_runs_computed"] = self.mc_runs
        ds.attrs["opa_runs_computed"] = self.opa_runs
        ds.attrs["parts_computed"] = self.parts.computed
        ds.attrs["parts_set_aside"] = self.parts.set_aside
        return ds

    def details(self, results) -> xr.Dataset:
        """:func:`_details` at the first swept value, kept as a part."""
        cfg = self.cfg
        value, sigma = cfg.values[0], _phase_sigma(cfg, results[0][2])
        key = digest(["details", cfg.oscillator_at(value).as_dict(),
                      dataclasses.asdict(cfg.options), float(sigma), cfg.nmax, cfg.uncertain,
                      cfg.horizons, cfg.per_period, cfg.seed, DENSE_PER_PERIOD,
                      *cfg.impulse_key(), *cfg.law_key()])
        return self.parts.dataset(f"details_{self._name(value, sigma)}", key,
                                  lambda: _details(cfg, sigma))


FRONTIER_BUDGETS = (8, 16, 32, 64)
FRONTIER_SAMPLES = (256, 512, 1024, 2048, 4096, 8192)
FRONTIER_REFERENCE = 32768


def frontier(cfg: ValidateConfig, parts: Parts | None = None) -> xr.Dataset:
    """Cost against accuracy at the first swept value, the largest sigma and the first
    horizon, under the map's law of xi: the paper's OPA (N = 0..Nmax), adaptive multi-element OPA (mean and
    saltation laws, element budgets 8..64), multi-element collocation, single-element
    collocation, MC and scrambled Sobol, against a 2^15-sample Sobol reference
    (:func:`compare._convergence.run_convergence`). Variables are prefixed ``frontier_``.
    With ``parts``, every run of the study is kept there (``frontier_<run>_<key>.npz``)."""
    from compare._convergence import ConvergenceConfig, run_convergence

    conv = ConvergenceConfig(
        oscillator=cfg.oscillator_at(cfg.values[0]), options=cfg.options,
        sigma=float(max(cfg.sigmas)), uncertain=cfg.uncertain, periods=cfg.horizons[0],
        per_period=cfg.per_period, order=1, orders=tuple(sorted({0, 1, cfg.nmax})),
        uniform=(), budgets=FRONTIER_BUDGETS, order_budget=FRONTIER_BUDGETS[-1],
        single_nodes=(1, 2, 4, 8), mc_samples=FRONTIER_SAMPLES,
        reference=FRONTIER_REFERENCE, seed=cfg.seed + 1, outdir=cfg.outdir,
        allow_negative=True, impulse=cfg.impulse, pulse_width=cfg.pulse_width,
        impulse_at_zero=cfg.impulse_at_zero, distribution=cfg.distribution)
    memo = None
    if parts is not None:
        def memo(run, spec, compute):
            return parts.arrays(f"frontier_{run}", digest(spec), compute)
    ds = run_convergence(conv, log=lambda *a: None, write=False, memo=memo)
    out = ds.rename({name: f"frontier_{name}" for name in ds.data_vars} | {"run": "frontier_run"})
    out.attrs = {"frontier_" + k: v for k, v in ds.attrs.items()
                 if k in ("sigma", "periods", "reference_samples", "reference_sem",
                          "wall_seconds")}
    out.attrs["frontier_value"] = float(cfg.values[0])
    out.attrs["frontier_omega"] = float(cfg.oscillator_at(cfg.values[0]).omega)
    return out


def element_variants(system: System, options: SolverOptions, measure: Measure, laws,
                     edges, times: np.ndarray, *, fallback: bool = False):
    """Multi-element OPA (:mod:`opa._elements`) under several impact laws: law ``laws[l]``
    on the elements cut at ``edges[l]``, each element's system in the orthonormal basis of
    the law of xi conditioned on it (:func:`opa._elements.element_rule`), one parallel
    batch per law. Mean and variance are assembled exactly as
    :func:`opa._elements.assemble` does. An element whose OPA system cannot be completed
    is NaN from where it stopped, or with ``fallback`` computed by collocation of the true
    systems (:func:`opa._elements.collocate_element`, as ``simulate_opa`` does with
    elements). The first impact is the earliest of any element's mean (inf: none).

    Returns a dict of x_mean, x_var, v_mean (L, T), first_impact (L,), elements (L,) and
    collocated (L,): the elements computed by the fallback."""
    order = system.order
    L = len(laws)
    mean, var = np.empty((L, len(times))), np.empty((L, len(times)))
    v_mean = np.empty((L, len(times)))
    first, count = np.full(L, np.inf), np.zeros(L, np.int64)
    collocated = np.zeros(L, np.int64)
    for ell, (law, cuts) in enumerate(zip(laws, edges)):
        own = system.replace(impact_law=law, truncation="galerkin")
        cells = [measure.restrict(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
        runs = run_elements(own, options, cells, times=times, partial=True, events=True)
        out = np.stack([np.concatenate([r.x_coef, r.v_coef]).T for r in runs])
        for e, run in enumerate(runs):
            if run.failure and fallback:
                run = collocate_element(own, options, cells[e], times=times)
                out[e][:, : order + 1], out[e][:, order + 1:] = run.x_coef.T, run.v_coef.T
                collocated[ell] += 1
            first[ell] = min(first[ell], runs[e].first_impact)
        E = len(cells)
        P = np.array([m.probability() for m in cells])
        P = P / P.sum()
        m = out[:, :, 0]
        s = (out[:, :, 1: order + 1] ** 2).sum(axis=2)
        mean[ell] = P @ m
        var[ell] = np.maximum(P @ (s + (m - mean[ell]) ** 2), 0.0)
        v_mean[ell] = P @ out[:, :, order + 1]
        count[ell] = E
    return {"x_mean": mean, "x_var": var, "v_mean": v_mean, "first_impact": first,
            "elements": count, "collocated": collocated}


def _sequence(system, cfg, cache, value):
    from opa._splits import event_sequence

    seq = event_sequence(system.replace(**{cfg.uncertain: value}), cfg.options,
                         cache["t_end"])
    cache[value] = seq
    return seq


@dataclass
class HorizonSplits:
    """What the split scan at one swept value found up to one horizon."""

    horizon: float  # forcing periods
    splits: list[Split]  # sorted by value
    truncated: bool  # the split limit left changes unlocated
    slowest_speed: float  # the nominal system's slowest impact within the horizon (NaN: none)
    slowest_time: float  # its time, forcing periods
    count: int  # the nominal system's impacts up to the horizon
    complete_within: float = math.inf  # every split with |value - centre| below it is listed
    crossings_within: float = math.inf  # the same for the output crossings


_SPLIT_FIELDS = ("value", "tol", "kind", "time", "speed", "left", "right")


def _splits_to_arrays(scans: list[HorizonSplits]) -> dict:
    every = [(h, sp) for h, scan in enumerate(scans) for sp in scan.splits]
    out = {"horizon": np.array([s.horizon for s in scans], float),
           "truncated": np.array([s.truncated for s in scans], np.int8),
           "slowest_speed": np.array([s.slowest_speed for s in scans], float),
           "slowest_time": np.array([s.slowest_time for s in scans], float),
           "count": np.array([s.count for s in scans], np.int64),
           "complete_within": np.array([s.complete_within for s in scans], float),
           "crossings_within": np.array([s.crossings_within for s in scans], float),
           "split_horizon": np.array([h for h, _ in every], np.int64)}
    for name in _SPLIT_FIELDS:
        dtype = str if name == "kind" else (np.int64 if name in ("left", "right") else float)
        out[f"split_{name}"] = np.array([getattr(sp, name) for _, sp in every], dtype=dtype)
    return out


def _splits_from_arrays(stored: dict) -> list[HorizonSplits]:
    scans = []
    for h in range(len(stored["horizon"])):
        idx = np.flatnonzero(stored["split_horizon"] == h)
        splits = [Split(**{name: stored[f"split_{name}"][i].item() for name in _SPLIT_FIELDS})
                  for i in idx]
        scans.append(HorizonSplits(float(stored["horizon"][h]), splits,
                                   bool(stored["truncated"][h]),
                                   float(stored["slowest_speed"][h]),
                                   float(stored["slowest_time"][h]), int(stored["count"][h]),
                                   float(stored["complete_within"][h]),
                                   float(stored["crossings_within"][h])))
    return scans


def count_distribution(centre, sigma, splits, count_at_centre, cdf=None,
                       complete_within=math.inf) -> dict[int, float]:
    """P(impacts up to the horizon = k) for the ensemble ``centre + sigma xi``, exact
    between the located changes of the count (``splits`` sorted by value, each with the
    counts on its two sides); ``cdf`` is that of the law of xi on [-1, 1] (default the
    semicircle). Only the samples with ``|value - centre| < complete_within`` (where the
    split list is complete) are counted: the probabilities then sum to less than 1
    (:func:`opa._splits.count_probabilities`)."""
    cdf = semicircle_cdf if cdf is None else cdf
    return count_probabilities(splits, centre, sigma, count_at_centre, cdf, complete_within)[0]


def _assemble(cfg: ValidateConfig, results) -> xr.Dataset:
    Q, S, V, N, H = (len(cfg.values), len(cfg.sigmas), len(cfg.variants), len(cfg.orders),
                     len(cfg.horizons))
    cdf = None if cfg.semicircle else cfg.measure().cdf
    element_count = np.zeros((Q, S, V), np.int64)
    collocated = np.zeros((Q, S, V), np.int64)
    failures = []
    n_out = int(round(max(cfg.horizons) * cfg.per_period)) + 1
    f = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    errors, agrees, disagree = f(Q, S, V, N, H, 2, 3), np.zeros((Q, S, V, N, H, 2), np.int8), \
        f(Q, S, V, N, 2)
    pre, first = f(Q, S, V, N), f(Q, S, V, N)
    opa_mean, opa_var = f(Q, S, V, N, n_out), f(Q, S, V, N, n_out)
    mc = {k: f(Q, S, n_out) for k in ("x_mean", "x_var", "x_sem", "x_var_sem")}
    samples, imin, imax = (np.zeros((Q, S), np.int64) for _ in range(3))
    mc_seconds, mc_rhs, seconds = f(Q, S), np.zeros((Q, S), np.int64), f(Q, S)
    star = f(Q, V, H, 2, 2)
    steps = np.zeros((Q, V, H, 2), np.int64)
    max_split = max(1, max(len(scan.splits) for r in results for scan in r[1][1]))
    sv, skind, stime, sspeed = f(Q, H, max_split), np.full((Q, H, max_split), -1, np.int8), \
        f(Q, H, max_split), f(Q, H, max_split)
    sleft, sright = (np.full((Q, H, max_split), -1, np.int64) for _ in range(2))
    struncated = np.zeros((Q, H), np.int8)
    complete, crossing_complete = np.full((Q, H), np.inf), np.full((Q, H), np.inf)
    unknown = np.zeros((Q, S, H))
    slow_speed, slow_time = f(Q, H), f(Q, H)
    sigma_split = f(Q, H)
    split_kind_nearest = np.full((Q, H), -1, np.int8)
    max_probes = max(len(r[5]) for r in results)
    probe_sigma = f(Q, max_probes)
    probe_agrees = np.full((Q, max_probes, V, H, 2), -1, np.int8)
    counts: dict = {}
    for q, (value, (centre, scans), grid, st, stp, probes) in enumerate(results):
        T = cfg.oscillator_at(value).forcing_period
        for s, sigma in enumerate(cfg.sigmas):
            p = grid[float(sigma)]
            errors[q, s], agrees[q, s], disagree[q, s] = p.errors, p.agrees, p.disagree
            pre[q, s], first[q, s] = p.pre_impact, p.first_impact
            opa_mean[q, s], opa_var[q, s] = p.opa_mean, p.opa_var
            for k in mc:
                mc[k][q, s] = p.mc[k]
            samples[q, s] = p.samples
            element_count[q, s] = p.elements
            collocated[q, s] = p.collocated
            if p.failure:
                failures.append(f"{cfg.parameter} = {value:g}, sigma = {sigma:g}: {p.failure}")
            imin[q, s], imax[q, s] = p.mc["impacts"]
            mc_seconds[q, s], mc_rhs[q, s], seconds[q, s] = p.mc["seconds"], p.mc["rhs"], \
                p.seconds
        star[q], steps[q] = st, stp
        for j, (sig, point) in enumerate(sorted(probes.items())):
            probe_sigma[q, j] = sig
            probe_agrees[q, j] = point.agrees[:, -1]
        for h, scan in enumerate(scans):
            splits = scan.splits
            struncated[q, h] = scan.truncated
            complete[q, h], crossing_complete[q, h] = scan.complete_within, \
                scan.crossings_within
            slow_speed[q, h], slow_time[q, h] = scan.slowest_speed, scan.slowest_time
            real = [sp for sp in splits if sp.kind not in ("horizon", "output crossing")]
            if real:
                near = min(real, key=lambda sp: abs(sp.value - centre))
                sigma_split[q, h] = abs(near.value - centre)
                split_kind_nearest[q, h] = SPLIT_KINDS.index(near.kind)
            for j, sp in enumerate(splits):
                sv[q, h, j], stime[q, h, j], sspeed[q, h, j] = sp.value, sp.time / T, sp.speed
                skind[q, h, j] = SPLIT_KINDS.index(sp.kind)
                sleft[q, h, j], sright[q, h, j] = sp.left, sp.right
            for s, sigma in enumerate(cfg.sigmas):
                counts[(q, s, h)] = count_distribution(centre, sigma, splits, scan.count, cdf,
                                                       scan.complete_within)
                if scan.complete_within < sigma:
                    unknown[q, s, h] = 1.0 - sum(counts[(q, s, h)].values())
    kmax = max(max(d, default=0) for d in counts.values())
    count_prob = np.zeros((Q, S, H, kmax + 1))
    for (q, s, h), dist in counts.items():
        for n, prob in dist.items():
            count_prob[q, s, h, n] = prob
    dims = ("value", "sigma", "variant", "N")
    one = {"units": "1"}
    ran = np.zeros((V, N), np.int8)
    ran[: len(cfg.single_variants)] = 1
    ran[len(cfg.single_variants):, -1] = 1
    kinds = {"flag_values": np.arange(len(SPLIT_KINDS), dtype=np.int8),
             "flag_meanings": " ".join(k.replace(" ", "_") for k in SPLIT_KINDS),
             "units": "1"}
    data = {
        "err_mean": (dims + ("horizon",), errors[..., 0, 0],
                     {"long_name": "RMS error of x_0 against the MC mean", **one}),
        "err_mean_se": (dims + ("horizon",), errors[..., 0, 1],
                        {"long_name": "RMS error of x_0 in RMS MC standard errors", **one}),
        "err_mean_rel": (dims + ("horizon",), errors[..., 0, 2],
                         {"long_name": "RMS error of x_0 relative to the RMS MC spread", **one}),
        "err_var": (dims + ("horizon",), errors[..., 1, 0],
                    {"long_name": "RMS error of the OPA variance against the MC variance",
                     **one}),
        "err_var_se": (dims + ("horizon",), errors[..., 1, 1],
                       {"long_name": "RMS variance error in RMS MC standard errors", **one}),
        "err_var_rel": (dims + ("horizon",), errors[..., 1, 2],
                        {"long_name": "RMS variance error relative to the RMS MC variance",
                         **one}),
        "agrees": (dims + ("horizon", "criterion"), agrees,
                   {"long_name": "1 where OPA agrees with MC over the horizon", **one}),
        "disagree_time": (dims + ("criterion",), disagree,
                          {"long_name": "first time of disagreement (inf: never within the "
                           "longest horizon)", "units": "forcing periods"}),
        "pre_impact_err": (dims, pre, {"long_name": "RMS error of x_0 before OPA's first "
                                       "impact", **one}),
        "first_impact": (dims, first, {"long_name": "time of OPA's first impact",
                                       "units": "forcing periods"}),
        "opa_x_mean": (dims + ("time",), opa_mean, {"long_name": "OPA mean x_0", **one}),
        "opa_x_var": (dims + ("time",), opa_var, {"long_name": "OPA variance", **one}),
        "mc_x_mean": (("value", "sigma", "time"), mc["x_mean"],
                      {"long_name": "MC mean E[x]", **one}),
        "mc_x_var": (("value", "sigma", "time"), mc["x_var"],
                     {"long_name": "MC variance Var[x]", **one}),
        "mc_x_sem": (("value", "sigma", "time"), mc["x_sem"],
                     {"long_name": "MC standard error of E[x]", **one}),
        "mc_x_var_sem": (("value", "sigma", "time"), mc["x_var_sem"],
                         {"long_name": "MC standard error of Var[x]", **one}),
        "mc_samples": (("value", "sigma"), samples, {"long_name": "MC samples used", **one}),
        "mc_impacts_min": (("value", "sigma"), imin,
                           {"long_name": "fewest impacts of an MC sample (longest horizon)",
                            **one}),
        "mc_impacts_max": (("value", "sigma"), imax,
                           {"long_name": "most impacts of an MC sample (longest horizon)",
                            **one}),
        "mc_seconds": (("value", "sigma"), mc_seconds, {"long_name": "MC wall time",
                                                        "units": "s"}),
        "mc_rhs_evaluations": (("value", "sigma"), mc_rhs,
                               {"long_name": "MC right-hand sides", **one}),
        "point_seconds": (("value", "sigma"), seconds,
                          {"long_name": "wall time of the point (OPA + MC)", "units": "s"}),
        "sigma_star": (("value", "variant", "horizon", "criterion"), star[..., 0],
                       {"long_name": "largest sigma at which OPA (N = Nmax) agrees: lower end "
                        "of the bisection bracket", **one}),
        "sigma_star_upper": (("value", "variant", "horizon", "criterion"), star[..., 1],
                             {"long_name": "upper end of the bisection bracket (NaN: agrees at "
                              "every sigma tried)", **one}),
        "bisection_steps": (("value", "variant", "horizon", "criterion"), steps,
                            {"long_name": "bisection evaluations", **one}),
        "probe_sigma": (("value", "probe"), probe_sigma,
                        {"long_name": "every sigma evaluated (grid and bisection)", **one}),
        "probe_agrees": (("value", "probe", "variant", "horizon", "criterion"), probe_agrees,
                         {"long_name": "verdict at N = Nmax at each evaluated sigma (-1: none)",
                          **one}),
        "split_value": (("value", "horizon", "split"), sv,
                        {"long_name": f"value of {cfg.uncertain} where the sampled systems' "
                         "event sequence changes", **one}),
        "split_kind": (("value", "horizon", "split"), skind,
                       {"long_name": "what happens at the split (-1: none)", **kinds}),
        "split_time": (("value", "horizon", "split"), stime,
                       {"long_name": "time of the first differing event (output "
                        "crossing: the output time)", "units": "forcing periods"}),
        "split_speed": (("value", "horizon", "split"), sspeed,
                        {"long_name": "speed of the first differing event (output "
                         "crossing: of the impact)", **one}),
        "split_left": (("value", "horizon", "split"), sleft,
                       {"long_name": "impacts up to the horizon just below the split", **one}),
        "split_right": (("value", "horizon", "split"), sright,
                        {"long_name": "impacts up to the horizon just above the split", **one}),
        "split_truncated": (("value", "horizon"), struncated,
                            {"long_name": "1 where the split limit left changes unlocated "
                             "(the list is complete within split_complete_sigma)", **one}),
        "split_complete_sigma": (("value", "horizon"), complete,
                                 {"long_name": "every split with |value - nominal| below "
                                  "this is listed (inf: the whole scan)", **one}),
        "crossing_complete_sigma": (("value", "horizon"), crossing_complete,
                                    {"long_name": "every output crossing with |value - "
                                     "nominal| below this is listed (inf: the whole scan)",
                                     **one}),
        "nominal_slowest_speed": (("value", "horizon"), slow_speed,
                                  {"long_name": "slowest impact of the nominal system within "
                                   "the horizon: its speed (NaN: no impact)", **one}),
        "nominal_slowest_time": (("value", "horizon"), slow_time,
                                 {"long_name": "time of that impact",
                                  "units": "forcing periods"}),
        "sigma_split": (("value", "horizon"), sigma_split,
                        {"long_name": "smallest sigma whose ensemble contains a split "
                         "(NaN: none within the largest sigma)", **one}),
        "sigma_split_kind": (("value", "horizon"), split_kind_nearest,
                             {"long_name": "kind of that nearest split", **kinds}),
        "count_prob": (("value", "sigma", "horizon", "count"), count_prob,
                       {"long_name": "probability of k impacts up to the horizon (exact "
                        "where the split list is complete)", **one}),
        "count_unknown": (("value", "sigma", "horizon"), unknown,
                          {"long_name": "probability of the samples beyond "
                           "split_complete_sigma, whose count is not known (0: complete)",
                           **one}),
        "variant_ran": (("variant", "N"), ran,
                        {"long_name": "1 where the variant is run at this N (multi-element "
                         "variants: N = Nmax only)", **one}),
        "variant_elements": (("value", "sigma", "variant"), element_count,
                             {"long_name": "elements of the variant at N = Nmax (0: not "
                              "computed, see the attribute element_failures)", **one}),
        "variant_collocated": (("value", "sigma", "variant"), collocated,
                               {"long_name": "elements whose OPA system could not be "
                                "completed, computed by collocation of the true systems "
                                "(as simulate_opa does)", **one}),
    }
    if failures:  # grid points only; bisection probes say so in the log
        attrs = {"element_failures": " | ".join(failures)}
    else:
        attrs = {}
    unc = cfg.uncertain
    index = lambda dim, text: (dim, np.arange(sizes[dim]), {"long_name": text, **one})  # noqa: E731
    sizes = {"probe": max_probes, "split": max_split}
    return xr.Dataset(
        data,
        coords={
            "value": ("value", np.array(cfg.values, float),
                      {"long_name": f"swept parameter {cfg.parameter}", **one}),
            "sigma": ("sigma", np.array(cfg.sigmas, float),
                      {"long_name": f"intensity of the uncertainty: {unc} = nominal {unc} + "
                       "sigma xi", **one}),
            "variant": ("variant", np.array(cfg.variants, dtype=object),
                        {"long_name": "OPA variant: impact law/truncation, or impact "
                         "law/ME-<elements> for multi-element OPA"}),
            "N": ("N", np.array(cfg.orders), {"long_name": "order of the OPA expansion",
                                               **one}),
            "horizon": ("horizon", np.array(cfg.horizons, float),
                        {"long_name": "length of the comparison window",
                         "units": "forcing periods"}),
            "criterion": ("criterion", np.array(CRITERIA, dtype=object),
                          {"long_name": "quantity compared with Monte Carlo"}),
            "time": ("time", np.arange(n_out) / cfg.per_period,
                     {"long_name": "time in forcing periods t omega / (2 pi) (the forcing "
                      "period differs along the sweep)", "units": "forcing periods"}),
            "count": ("count", np.arange(kmax + 1),
                      {"long_name": "number of impacts up to the horizon", **one}),
            "probe": index("probe", "index of an evaluated sigma (ascending; NaN-padded)"),
            "split": index("split", "index of a located split (kind -1: padding)"),
        },
        attrs=attrs,
    )


DENSE_PER_PERIOD = 64


def _phase_sigma(cfg: ValidateConfig, grid: dict[float, Point]) -> float:
    """The first grid sigma where mean/galerkin fails over the first horizon, else the last."""
    return next((s for s in cfg.sigmas if not grid[float(s)].agrees[0, -1, 0, 0]),
                cfg.sigmas[-1])


def _details(cfg: ValidateConfig, sig: float) -> xr.Dataset:
    """Dense-output phase portraits at the first swept value and ``sig``, and how far EMR_0
    (sigma = 0, N = Nmax) stays from the DMR, at each horizon."""
    value = cfg.values[0]
    osc = cfg.oscillator_at(value)
    times = time_grid(osc.omega, cfg.horizons[0], DENSE_PER_PERIOD)
    curves = {}
    laws = ("mean", "ensemble")
    if cfg.semicircle:
        for law in laws:
            ds = simulate_opa(cfg.system_at(value, sigma=sig, order=cfg.nmax, impact_law=law),
                              times=times, options=cfg.options)
            curves[law] = (ds.x_mean.values, ds.v_mean.values)
    else:  # one element in the law's own basis
        measure = cfg.measure()
        run = element_variants(cfg.system_at(value, sigma=sig, order=cfg.nmax), cfg.options,
                               measure, laws, [np.array([measure.lo, measure.hi])] * 2, times)
        for ell, law in enumerate(laws):
            curves[law] = (run["x_mean"][ell], run["v_mean"][ell])
    ens = simulate_mc(cfg.system_at(value, sigma=sig, order=0), samples=256, sampler="sobol",
                      seed=cfg.seed, times=times, options=cfg.options, progress=False,
                      keep_paths=True)
    pick = np.argsort(ens.xi.values)[np.linspace(0, 255, 7).astype(int)]
    long = time_grid(osc.omega, max(cfg.horizons), cfg.per_period)
    dmr = simulate_dmr(cfg.system_at(value), times=long, options=cfg.options).x.values
    # sigma = 0: the law of xi plays no part (the higher coefficients stay zero)
    emr0 = simulate_opa(cfg.system_at(value, sigma=0.0, order=cfg.nmax).replace(
        distribution=None), times=long, options=cfg.options).x_mean.values
    diff = [float(np.max(np.abs(emr0[: int(round(h * cfg.per_period)) + 1]
                                - dmr[: int(round(h * cfg.per_period)) + 1])))
            for h in cfg.horizons]
    emr1 = simulate_opa(cfg.system_at(value, sigma=0.0, order=0).replace(distribution=None),
                        times=long, options=cfg.options).x_mean.values
    one = {"units": "1"}
    return xr.Dataset(
        {
            "phase_opa_x": (("law", "phase_time"), np.stack([curves[k][0] for k in curves]),
                            {"long_name": "OPA x_0 at N = Nmax", **one}),
            "phase_opa_v": (("law", "phase_time"), np.stack([curves[k][1] for k in curves]),
                            {"long_name": "OPA v_0 at N = Nmax", **one}),
            "phase_mc_x": ("phase_time", ens.x_mean.values, {"long_name": "MC mean E[x]",
                                                             **one}),
            "phase_mc_v": ("phase_time", ens.v_mean.values, {"long_name": "MC mean E[x']",
                                                             **one}),
            "phase_sample_x": (("phase_sample", "phase_time"), ens.x.values[pick],
                               {"long_name": "sample paths x", **one}),
            "phase_sample_v": (("phase_sample", "phase_time"), ens.v.values[pick],
                               {"long_name": "sample paths x'", **one}),
            "phase_sample_xi": ("phase_sample", ens.xi.values[pick],
                                {"long_name": "xi of the sample path", **one}),
            "emr0_dmr_difference": ("horizon", np.array(diff),
                                    {"long_name": "max |x_0 - x_DMR| with sigma = 0, N = Nmax",
                                     **one}),
            "emr0_n0_dmr_difference": ((), float(np.max(np.abs(emr1 - dmr))),
                                       {"long_name": "max |x_0 - x_DMR| with sigma = 0, N = 0, "
                                        "longest horizon", **one}),
        },
        coords={"law": ("law", np.array(["mean", "ensemble"], dtype=object),
                        {"long_name": "impact law of the phase portrait's OPA run"}),
                "phase_time": ("phase_time", times / osc.forcing_period,
                               {"long_name": "dense-output time in forcing periods",
                                "units": "forcing periods"}),
                "phase_sample": ("phase_sample", np.arange(len(pick)),
                                 {"long_name": "index of a drawn sample path (ascending xi)",
                                  **one})},
        attrs={"phase_value": float(value), "phase_sigma": float(sig)},
    )


def _attrs(cfg: ValidateConfig) -> dict:
    attrs = provenance_attrs("validate", cfg.system_at(cfg.values[0], sigma=max(cfg.sigmas),
                                                        order=cfg.nmax),
                             cfg.options, seed=cfg.seed, sampler="sobol")
    # a grid dataset: sigma, N and the swept parameter are coordinates, not one value
    for name in ("sigma", "N", cfg.parameter):
        if name != cfg.uncertain:
            attrs.pop(name, None)
    attrs.update({"truncation": ",".join(dict.fromkeys(t for _, t in cfg.single_variants)),
                  "impact_law": "mean,ensemble,saltation"})
    attrs.update(
        distribution=cfg.distribution,
        elements=("none" if cfg.elements is None else str(cfg.elements)),
        variants_dropped=(", ".join(cfg.dropped_variants) + " (eq. (27) truncates the "
                          "semicircle's basis; under another law only the Galerkin projection "
                          "exists)") if cfg.dropped_variants else "none",
    )
    if cfg.elements is not None:
        attrs.update(element_order=int(cfg.nmax), element_text=(
            "Galerkin truncation, every element its own OPA system in the orthonormal basis "
            "of the law of xi conditioned on it, run at N = Nmax only"))
    if cfg.elements == "adaptive":
        attrs.update(max_elements=int(cfg.budget), element_tolerance=ELEMENT_TOLERANCE)
    attrs.update(
        preset=cfg.preset, parameter=cfg.parameter, samples=int(cfg.samples),
        max_samples=int(cfg.max_samples), per_period=int(cfg.per_period),
        tolerance=float(cfg.tolerance), var_tolerance=float(cfg.var_tolerance), z=float(cfg.z),
        resolution=float(cfg.resolution), split_resolution=float(cfg.split_resolution),
        floor=noise_floor(cfg.options),
        criterion_text=(
            "agrees over H when, at every output t <= H, the running RMS error <= tol x the "
            "running RMS of the MC spread (variance: of the MC variance) + z x the running "
            "RMS MC standard error + floor (variance: floor squared)"),
    )
    return attrs


def run_validation(cfg: ValidateConfig, *, progress: bool = True, log=print,
                   started: float | None = None) -> xr.Dataset:
    """Run the trust map and return its dataset (also written to OUTDIR/validate.nc).

    ``started``: the ``time.perf_counter()`` reading at which the command started (the
    one clock of a run); the attribute ``wall_seconds`` is the time from it to the
    finished dataset (default: from the call)."""
    started = time.perf_counter() if started is None else started
    ds = _Map(cfg, progress=progress, log=log).run()
    for dim in ds.dims:  # every dimension has a coordinate (parts of older versions)
        if dim not in ds.coords:
            ds = ds.assign_coords({dim: (dim, np.arange(ds.sizes[dim]),
                                         {"long_name": f"index along {dim}", "units": "1"})})
    if "frontier_run" in ds.dims:
        ds["frontier_run"].attrs.update(long_name="index of a run of the cost-accuracy study",
                                        units="1")
        for name, text in (("frontier_method", "method of the run"),
                           ("frontier_law", "impact law of the run (true system: none)")):
            if name in ds and "long_name" not in ds[name].attrs:
                ds[name].attrs["long_name"] = text
    ds.attrs["wall_seconds"] = time.perf_counter() - started
    write_netcdf(ds, os.path.join(cfg.outdir, "validate.nc"))
    return ds


__all__ = ["CRITERIA", "SWEEPS", "VARIANTS", "ValidateConfig", "count_distribution",
           "load_config", "run_validation"]
