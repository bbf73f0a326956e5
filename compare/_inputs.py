"""Entry checks of what a user hands to ``compare``: datasets and keywords.

One place for the refusals of issue 45 (SPEC section 7): a dataset that is not one, lacks
a variable, an attribute or its ``time`` coordinate, or holds a non-finite number or a
negative standard error where its data contract (docs/datasets.md) has none, is refused
with one ValueError that names the dataset, the culprit and what was found
(``"the mc dataset's x_sem is negative at 2 outputs"``), never a KeyError, an
AttributeError or a result computed from NaN. The NaNs the contracts document are the
callers' to allow (``allowed=``): each caller knows which.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import xarray as xr


def _plural(count: int, word: str) -> str:
    return f"{count} {word}{'' if count == 1 else 's'}"


def check_dataset(ds, name: str, kind: str) -> None:
    """Refuse what is not an ``xarray.Dataset`` (a path, a DataArray): ``name`` is the
    argument's name, ``kind`` what it should hold (``"an opa run"``)."""
    if not isinstance(ds, xr.Dataset):
        raise ValueError(f"{name} must be an xarray.Dataset of {kind}, got "
                         f"{type(ds).__name__}")


def require_variables(ds: xr.Dataset, name: str, variables, *, hint: str = "") -> None:
    """Refuse ``ds`` (called ``name`` in the message) lacking one of ``variables`` (names;
    a tuple of names: any one of them will do, the first is named)."""
    missing = [v if isinstance(v, str) else v[0] for v in variables
               if not any(n in ds.variables for n in ((v,) if isinstance(v, str) else v))]
    if missing:
        raise ValueError(f"{name} lacks the variable{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)}{hint}")


def require_attributes(ds: xr.Dataset, name: str, attributes, *, hint: str = "") -> None:
    """Refuse ``ds`` lacking one of the global ``attributes``."""
    missing = [a for a in attributes if a not in ds.attrs]
    if missing:
        raise ValueError(f"{name} lacks the attribute{'s' if len(missing) > 1 else ''} "
                         f"{', '.join(missing)}{hint}")


def require_time(ds: xr.Dataset, name: str, *, old_name: bool = False) -> str:
    """The name of ``ds``'s time coordinate: ``time``, or with ``old_name`` also
    ``periods`` (trust maps written before issue 26). Refuse a dataset with neither,
    saying what it has instead."""
    if "time" in ds.coords:
        return "time"
    if "periods" in ds.coords:
        if old_name:
            return "periods"
        raise ValueError(f"{name} has no coordinate time (it has periods, the name in "
                         f"files written before issue 26): run it again with this "
                         f"version")
    raise ValueError(f"{name} has no coordinate time (dimensions: "
                     f"{', '.join(map(str, ds.dims)) or 'none'})")


def check_attribute_number(ds: xr.Dataset, name: str, attribute: str, *,
                           positive: bool = False) -> float:
    """The global attribute ``attribute`` of ``ds`` as a finite float (``positive``:
    > 0), or a refusal naming it and its value."""
    value = ds.attrs[attribute]
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, (str, bool)) or not math.isfinite(number) or (positive
                                                                      and number <= 0):
        raise ValueError(f"{name}'s attribute {attribute} = {value!r} is not a "
                         f"{'positive' if positive else 'finite'} number")
    return number


def check_finite(ds: xr.Dataset, name: str, variable: str, *, allowed=None,
                 where: str = "") -> None:
    """Refuse a non-finite value of ``ds[variable]`` outside ``allowed`` (a boolean mask
    broadcastable to it: where the data contract documents NaN); ``where`` says, after
    the count, which values were looked at (``" before the run stopped"``)."""
    values = np.asarray(ds[variable].values)
    if values.dtype.kind not in "fc":
        return
    bad = ~np.isfinite(values)
    if allowed is not None:
        bad &= ~np.broadcast_to(np.asarray(allowed, dtype=bool), bad.shape)
    if bad.any():
        raise ValueError(f"{name}'s {variable} has {int(bad.sum())} non-finite "
                         f"value{'' if bad.sum() == 1 else 's'} of {values.size}{where}")


def check_standard_error(ds: xr.Dataset, name: str, variable: str, *,
                         nan: bool = False) -> None:
    """Refuse a standard error that is negative, infinite, or NaN unless ``nan`` (a
    quadrature, which has no sampling error)."""
    values = np.asarray(ds[variable].values, dtype=float)
    check_finite(ds, name, variable, allowed=np.isnan(values) if nan else None)
    negative = int((values < 0).sum())
    if negative:
        raise ValueError(f"{name}'s {variable} is negative at "
                         f"{_plural(negative, 'output')} (a standard error is >= 0)")


def check_number(name: str, value, *, least: float = 0.0, strict: bool = False,
                 finite: bool = True) -> float:
    """``value`` as a float if it is a number (not a bool), not NaN, finite unless
    ``finite`` is False, and >= ``least`` (> with ``strict``); else a refusal naming the
    keyword ``name`` and the value."""
    ok = (isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
          and not math.isnan(value) and (math.isfinite(value) or not finite)
          and (value > least if strict else value >= least))
    if not ok:
        bound = "" if least == -math.inf else f" {'>' if strict else '>='} {least:g}"
        raise ValueError(f"{name} must be a {'finite ' if finite else ''}number{bound}, "
                         f"got {value!r}")
    return float(value)


__all__ = ["check_attribute_number", "check_dataset", "check_finite", "check_number",
           "check_standard_error", "require_attributes", "require_time",
           "require_variables"]


def run_fields(attrs) -> dict:
    """The System fields a run records besides its oscillator and uncertainty: the
    impulse model and whether negative samples were allowed."""
    return dict(allow_negative=bool(attrs.get("allow_negative", 0)),
                impulse=str(attrs["impulse"]), pulse_width=float(attrs["pulse_width"]),
                impulse_at_zero=bool(attrs["impulse_at_zero"]))


def lower_wall(attrs) -> dict[str, float]:
    """A run's lower wall (its attributes delta_minus, eta_minus, present only where the
    oscillator has one), for the Oscillator of the true systems."""
    return {name: float(attrs[name]) for name in ("delta_minus", "eta_minus") if name in attrs}


def run_options(attrs, options=None):
    """The solver options a run was computed with, from its attributes (``options``
    instead, when given)."""
    if options is not None:
        return options
    from opa import SolverOptions

    return SolverOptions(rtol=float(attrs["rtol"]), atol=float(attrs["atol"]),
                         method=str(attrs.get("method", "dop853")),
                         chatter_velocity=float(attrs.get("chatter_velocity", 1e-6)))


def several(run: xr.Dataset) -> bool:
    """Whether a run has several uncertain parameters (its ``uncertain`` = "mu,c")."""
    return "," in str(run.attrs.get("uncertain", ""))
