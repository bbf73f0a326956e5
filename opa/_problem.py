r"""The uncertain parameters of a study: their names, scales and joint law.

A study with d uncertain parameters writes each one as

.. math::

    p_j = \bar p_j + \sigma_j \xi_j, \qquad j = 1 \dots d,

with :math:`\xi = (\xi_1, \dots, \xi_d)` distributed as the product of d one-dimensional
laws (the marginals of :mod:`opa._measure`: the paper's semicircle, uniform, Beta, a
truncated normal or a bounded chaospy law). A :class:`Problem` holds the names, the
scales :math:`\sigma_j` and the marginals, and it is the one place that turns points
:math:`\xi` of shape (M, d) into parameter values: the kernel receives a table of the
force law's coefficients at each quadrature node or sample (:meth:`Problem.table`) and
never learns which parameters are uncertain, nor how many.

With d = 1 it is exactly the single uncertain parameter of the paper (``System(sigma=,
uncertain=, distribution=)``): the values :math:`\bar p + \sigma \xi` are computed by
the same floating-point operations, so every one-dimensional result is unchanged bit for
bit.

Which parameters may be uncertain: the coefficients of the force law the kernel
evaluates at each node, :math:`\mu`, :math:`a` and :math:`c` (``UNCERTAIN_PARAMETERS``)
of the paper's law or the named constants of a user's law (``opa.ForceLaw``;
``opa.System`` checks the names against its oscillator's law); the impact's restitution
:math:`\eta` and wall :math:`\delta` (``IMPACT_PARAMETERS``: the impact law reads them at
each node); and the drive's f, :math:`\omega` and F0 (``DRIVE_PARAMETERS``: each node adds
its own :math:`f_k \cos(\omega_k t)` and its own impulse height; the output times stay
those of the nominal :math:`\omega`). The table has a column for each.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from opa._forcelaw import N_COEFFICIENTS
from opa._model import (
    DRIVE_PARAMETERS,
    IMPACT_PARAMETERS,
    UNCERTAIN_PARAMETERS,
    _finite,
    check_flag,
)

#: the first columns of the kernel's parameter table (``opa._kernel.T_MU, T_A, T_C``), by
#: name; then a user's force law's N_COEFFICIENTS coefficients C[j, k] (``T_POLY``)
TABLE_COLUMNS = ("mu", "a", "c")
#: then the restitution and the wall at each point (``T_ETA, T_DELTA``)
WALL_COLUMNS = IMPACT_PARAMETERS
#: the last columns: the forcing amplitude, frequency and impulse height (``T_F`` ...)
DRIVE_COLUMNS = DRIVE_PARAMETERS
#: the width of the kernel's parameter table (``opa._kernel.N_TABLE``)
TABLE_WIDTH = len(TABLE_COLUMNS) + N_COEFFICIENTS + len(WALL_COLUMNS) + len(DRIVE_COLUMNS)


def split_list(text: str) -> tuple[str, ...]:
    """A comma-separated list, where a bare number joins the item before it as one more
    argument of a law (``"beta:2,3,uniform"`` is two laws).

    >>> split_list("mu, c")
    ('mu', 'c')
    >>> split_list("beta:2,3,uniform")
    ('beta:2,3', 'uniform')
    """
    items: list[str] = []
    for part in (p.strip() for p in text.split(",")):
        try:
            float(part)
            number = True
        except ValueError:
            number = False
        if number and items and ":" in items[-1]:
            items[-1] += "," + part
        else:
            items.append(part)
    return tuple(items)


def _as_tuple(name: str, value, d: int | None) -> tuple:
    """``value`` as a tuple: one value (applies to all ``d``), or a sequence of ``d``."""
    if isinstance(value, str) and "," in value:
        value = split_list(value)
    if isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1):
        value = tuple(value)
        if d is not None and len(value) == 1:
            return value * d
        if d is not None and len(value) != d:
            raise ValueError(f"{name} must give one value, or one per uncertain parameter "
                             f"({d}), got {len(value)}")
        return value
    return (value,) * (1 if d is None else d)


@dataclass(frozen=True)
class Problem:
    """d uncertain parameters ``p_j = p_bar_j + scale_j xi_j`` with a product law of xi.

    Parameters
    ----------
    names : one name (``"mu"``), a comma-separated list (``"mu,c"``) or a sequence, of
        ``UNCERTAIN_PARAMETERS``, each at most once.
    scales : sigma_j >= 0: one value (applies to all) or one per name.
    laws : the law of each xi_j: None (the paper's semicircle), a name of
        ``opa._measure`` (``uniform``, ``beta:2,3``, ``normal-trunc:3``), a bounded chaospy
        distribution or a ``Measure``; one (applies to all) or one per name.
    allow_negative : permit values ``p_bar + sigma xi < 0`` over the support.
    coefficients : the names that may be uncertain: None for the paper's force law's
        ``UNCERTAIN_PARAMETERS``, a user's force law's names (``ForceLaw.names``).

    Examples
    --------
    >>> from opa import Oscillator
    >>> problem = Problem("mu,c", scales=(0.02, 0.005), laws="uniform")
    >>> problem.dimension, problem.names, problem.scales
    (2, ('mu', 'c'), (0.02, 0.005))
    >>> xi = np.array([[0.0, 0.0], [1.0, -1.0]])
    >>> problem.table(xi, Oscillator(mu=0.1, a=1.0, c=0.05))[:, :3].round(4).tolist()
    [[0.1, 1.0, 0.05], [0.12, 1.0, 0.045]]
    """

    names: tuple = ("mu",)
    scales: tuple = (0.01,)
    laws: tuple = (None,)
    allow_negative: bool = False
    coefficients: tuple | None = None

    # added after parts were written: a digest (opa._dataset.digest) counts it when set
    _digest_optional = ("coefficients",)

    def __post_init__(self):
        names = _as_tuple("uncertain", self.names, None)
        allowed = UNCERTAIN_PARAMETERS + IMPACT_PARAMETERS + DRIVE_PARAMETERS \
            if self.coefficients is None else tuple(self.coefficients)
        for name in names:
            if name not in allowed:
                raise ValueError(f"uncertain must name parameters among "
                                 f"{', '.join(allowed)}, got {name!r:.40}")
        if len(set(names)) != len(names):
            raise ValueError(f"uncertain names a parameter twice: {','.join(names)}")
        d = len(names)
        scales = tuple(_finite("sigma", s) for s in _as_tuple("sigma", self.scales, d))
        for s in scales:
            if s < 0.0:
                raise ValueError(f"sigma must be >= 0, got {s}")
        laws = _as_tuple("distribution", self.laws, d)
        check_flag("allow_negative", self.allow_negative)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "scales", scales)
        object.__setattr__(self, "laws", laws)
        object.__setattr__(self, "allow_negative", bool(self.allow_negative))
        if any(law is not None for law in laws):
            self.measures  # noqa: B018 -- parses (and so checks) every law given

    # ------------------------------------------------------------------ from a table
    @classmethod
    def from_table(cls, table: dict, where: str = "the problem",
                   coefficients: tuple | None = None) -> Problem:
        """The problem of a TOML-style table: one sub-table per uncertain parameter, in
        order, each with ``sigma`` and optionally ``distribution``; optionally
        ``allow_negative`` at the top. ``coefficients``: the names allowed (a user's
        force law's, ``Oscillator.uncertain_names``; None: the paper's).

        >>> Problem.from_table({"mu": {"sigma": 0.016},
        ...                     "c": {"sigma": 0.005, "distribution": "uniform"}}).laws
        (None, 'uniform')
        """
        if not isinstance(table, dict):
            raise ValueError(f"{where} must be a table, got {type(table).__name__}")
        allow = table.get("allow_negative", False)
        names, scales, laws = [], [], []
        for name, entry in table.items():
            if name == "allow_negative":
                continue
            if not isinstance(entry, dict):
                raise ValueError(f"{where}: {name!r:.40} must be a table [{name}] with sigma "
                                 f"and distribution (or allow_negative at the top)")
            unknown = sorted(set(entry) - {"sigma", "distribution"})
            if unknown:
                raise ValueError(f"{where}: [{name}] has unknown key(s) "
                                 f"{', '.join(map(repr, unknown))} (it takes sigma and "
                                 f"distribution)")
            if "sigma" not in entry:
                raise ValueError(f"{where}: [{name}] needs sigma")
            names.append(name)
            scales.append(entry["sigma"])
            laws.append(entry.get("distribution"))
        if not names:
            raise ValueError(f"{where} names no uncertain parameter (one table [name] each)")
        return cls(tuple(names), tuple(scales), tuple(laws), allow, coefficients)

    @classmethod
    def from_toml(cls, path) -> Problem:
        """The problem of a TOML file (:meth:`from_table`)."""
        from opa._dataset import read_toml

        return cls.from_table(read_toml(path, "problem file"), f"problem file {path}")

    # ------------------------------------------------------------------ the law
    @property
    def dimension(self) -> int:
        """d, the number of uncertain parameters."""
        return len(self.names)

    @functools.cached_property
    def measures(self) -> tuple:
        """The marginal law of each xi_j as an ``opa._measure.Measure`` (parsed once: a
        law's scipy distribution is costly to build)."""
        from opa._measure import parse

        return tuple(parse(law) for law in self.laws)

    def __getstate__(self):
        # the parsed laws may hold closures; a copy in another process parses again
        return {k: v for k, v in self.__dict__.items() if k != "measures"}

    @property
    def support(self) -> np.ndarray:
        """The box xi lies in: shape (d, 2), rows (lo, hi)."""
        if all(law is None for law in self.laws):  # the paper's semicircle, unparsed
            return np.tile([-1.0, 1.0], (self.dimension, 1))
        return np.array([(m.lo, m.hi) for m in self.measures], dtype=float)

    def is_semicircle(self, j: int = 0) -> bool:
        """Whether xi_j has the paper's law, the whole semicircle on [-1, 1]."""
        if self.laws[j] is None:
            return True
        measure = self.measures[j]
        return measure.name == "semicircle" and measure.is_whole

    # ------------------------------------------------------------------ xi -> values
    def _points(self, xi) -> np.ndarray:
        xi = np.asarray(xi, dtype=float)
        if xi.ndim == 1 and self.dimension == 1:
            xi = xi[:, None]
        if xi.ndim != 2 or xi.shape[1] != self.dimension:
            raise ValueError(f"xi must have shape (M, {self.dimension}), got {xi.shape}")
        return xi

    def values(self, xi, oscillator) -> dict:
        """Each uncertain parameter's values ``p_bar_j + sigma_j xi_j`` at the points
        ``xi`` (M, d) (or (M,) when d = 1), by name."""
        xi = self._points(xi)
        return {name: oscillator.value(name) + scale * xi[:, j]
                for j, (name, scale) in enumerate(zip(self.names, self.scales))}

    def table(self, xi, oscillator) -> np.ndarray:
        """The kernel's parameter table at the points ``xi``: shape (M, TABLE_WIDTH), the
        columns mu, a, c (``TABLE_COLUMNS``), the oscillator's own value where a column is
        not uncertain, then a user's force law's coefficients C[j, k] at each point (zeros
        for the paper's law)."""
        xi = self._points(xi)
        table = np.zeros((len(xi), TABLE_WIDTH))
        columns = (*TABLE_COLUMNS, *[None] * N_COEFFICIENTS, *WALL_COLUMNS, *DRIVE_COLUMNS)
        values = self.values(xi, oscillator)
        for col, name in enumerate(columns):
            if name is not None:
                table[:, col] = values.get(name, float(getattr(oscillator, name)))
        if oscillator.force is not None:
            table[:, len(TABLE_COLUMNS):len(TABLE_COLUMNS) + N_COEFFICIENTS] = \
                oscillator.law_coefficients(values)
        return table

    def varies_in_the_drive(self) -> bool:
        """Whether f, omega or F0 is uncertain (at a non-zero scale): each node then has its
        own harmonic drive and impulse height."""
        return any(name in DRIVE_COLUMNS and scale != 0.0
                   for name, scale in zip(self.names, self.scales))

    def varies_at_the_wall(self) -> bool:
        """Whether the restitution or the wall is uncertain (at a non-zero scale): the
        impact law then reads them at each node."""
        return any(name in WALL_COLUMNS and scale != 0.0
                   for name, scale in zip(self.names, self.scales))

    def check(self, oscillator) -> None:
        """Refuse values ``p_bar + sigma xi < 0`` over the support unless allowed (a
        parameter whose mean is already negative is the user's choice); a restitution
        outside (0, 1] or a wall below the start x0 anywhere on the support always."""
        self._check_wall(oscillator)
        if self.allow_negative:
            return
        for (name, scale), (lo, _) in zip(zip(self.names, self.scales), self.support):
            if name in (*WALL_COLUMNS, *DRIVE_COLUMNS):
                continue  # a wall, a forcing or an impulse may be negative; eta, omega above
            mean = oscillator.value(name)
            lowest = mean + scale * lo
            if lowest < 0.0 <= mean:
                raise ValueError(
                    f"sigma = {scale} with xi down to {lo:g} makes {name} = {mean:g} + sigma "
                    f"xi = {lowest:.6g} negative for some samples; pass allow_negative=True "
                    f"(--allow-negative) if that is intended")

    def _check_wall(self, oscillator) -> None:
        for (name, scale), (lo, hi) in zip(zip(self.names, self.scales), self.support):
            if name not in (*WALL_COLUMNS, "omega") or scale == 0.0:
                continue
            mean = oscillator.value(name)
            low, high = sorted((mean + scale * lo, mean + scale * hi))
            if name == "eta" and not (0.0 < low and high <= 1.0):
                raise ValueError(f"sigma = {scale} with xi in [{lo:g}, {hi:g}] makes eta = "
                                 f"{mean:g} + sigma xi leave (0, 1] (from {low:.6g} to "
                                 f"{high:.6g}): every restitution must be in (0, 1]")
            if name == "omega" and low <= 0.0:
                raise ValueError(f"sigma = {scale} with xi in [{lo:g}, {hi:g}] makes omega = "
                                 f"{mean:g} + sigma xi reach {low:.6g}: every frequency must "
                                 f"be > 0")
            if name == "delta" and oscillator.two_walls and low <= oscillator.delta_minus:
                raise ValueError(f"sigma = {scale} with xi in [{lo:g}, {hi:g}] puts the wall "
                                 f"delta = {mean:g} + sigma xi down to {low:.6g}, at or below "
                                 f"the lower wall delta_minus = {oscillator.delta_minus:g}")
            if name == "delta" and low < oscillator.x0:
                raise ValueError(f"sigma = {scale} with xi in [{lo:g}, {hi:g}] puts the wall "
                                 f"delta = {mean:g} + sigma xi down to {low:.6g}, below the start "
                                 f"x0 = {oscillator.x0:g}: every sampled system must start "
                                 f"below its wall")

    # ------------------------------------------------------------------ sampling
    def sample(self, samples: int, sampler: str = "sobol", seed: int | None = 0,
               replicates: int = 1) -> np.ndarray:
        """``samples`` points of xi, shape (M, d): ``sobol`` (scrambled Sobol' in d
        dimensions; a power of two keeps its balance; ``replicates`` R independent
        scramblings of M/R points each, concatenated), ``lhs`` (Latin hypercube) or
        ``random``, each uniform point sent through the marginals' quantile functions.
        The same seed gives the same points."""
        from scipy.stats import qmc

        from opa._model import check_count

        samples = check_count("samples", samples)
        replicates = check_count("replicates", replicates)
        d = self.dimension
        rng = np.random.default_rng(seed)
        if sampler == "sobol":
            if samples % replicates:
                raise ValueError(f"samples must be a multiple of replicates = {replicates}, "
                                 f"got {samples}")
            per = samples // replicates
            streams = ([rng] if replicates == 1 else
                       [np.random.default_rng(c)
                        for c in np.random.SeedSequence(seed).spawn(replicates)])
            u = np.concatenate([
                qmc.Sobol(d=d, scramble=True, seed=r).random_base2(
                    int(math.ceil(math.log2(per))))[:per] for r in streams])
        elif sampler == "lhs":
            u = qmc.LatinHypercube(d=d, seed=rng).random(samples)
        elif sampler == "random":
            u = rng.random((samples, d))
        else:
            raise ValueError(f"sampler must be one of sobol, lhs, random, got {sampler!r:.40}")
        return np.column_stack([m.ppf(u[:, j]) for j, m in enumerate(self.measures)])

    def attrs(self) -> dict:
        """The problem as netCDF-safe dataset attributes (docs/datasets.md)."""
        return dict(uncertain=",".join(self.names),
                    sigma=np.asarray(self.scales, dtype=float),
                    distribution=",".join("semicircle" if law is None else str(law)
                                          for law in self.laws),
                    allow_negative=int(self.allow_negative))
