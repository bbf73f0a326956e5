"""The memory budget: sizes are checked against it before any work starts.

``$OPA_MC_MEMORY_BUDGET`` (bytes, or with a K/M/G/T/P suffix) sets it; the default is
half the physical memory."""

from __future__ import annotations

import os
import re

MEMORY_BUDGET_ENV = "OPA_MC_MEMORY_BUDGET"
_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40, "P": 2**50}


def parse_bytes(text: str) -> int:
    """A size in bytes from ``"1073741824"``, ``"512M"``, ``"8G"``, ``"1.5GiB"`` or ``"8GB"``.

    Suffixes are binary (K = 1024, M = 1024^2, ...), with or without a trailing ``B`` or
    ``iB``.

    >>> parse_bytes("8G") == 8 * 2**30
    True
    """
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kKmMgGtTpP]?)(?:i?[bB])?\s*", str(text))
    if match is None:
        raise ValueError(f"a size must be a number of bytes with an optional suffix K, M, G, "
                         f"T or P, got {text!r}")
    return int(float(match[1]) * _UNITS[match[2].upper()])


def _half_physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):  # no sysconf (Windows) or no such name
        return 8 * 2**30


def _budget_from_environment() -> int | None:
    text = os.environ.get(MEMORY_BUDGET_ENV)
    if text is None or not text.strip():
        return None
    try:
        return parse_bytes(text)
    except ValueError as err:
        raise ValueError(f"{MEMORY_BUDGET_ENV}: {err}") from None


def _initial_budget() -> int:
    try:
        budget = _budget_from_environment()
    except ValueError:  # reported by memory_budget() when a size is checked
        budget = None
    return _half_physical_memory() if budget is None else budget


# The largest allocation a run may plan, in bytes: $OPA_MC_MEMORY_BUDGET at import if set,
# else half the physical memory. memory_budget() reads the variable again at each check.
MEMORY_BUDGET_BYTES = _initial_budget()


def memory_budget() -> int:
    """The budget in bytes: ``$OPA_MC_MEMORY_BUDGET`` if set now, else MEMORY_BUDGET_BYTES."""
    budget = _budget_from_environment()
    return MEMORY_BUDGET_BYTES if budget is None else budget


def format_bytes(nbytes: float) -> str:
    """``"17.9 GiB"``, ``"12 GiB"``, ``"512 B"``: binary units, one decimal at most."""
    value, unit = float(nbytes), "B"
    for name in ("KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if value < 1023.95:  # would not round to 1024.0
            break
        value, unit = value / 1024, name
    return f"{value:.1f}".removesuffix(".0") + f" {unit}"


def check_memory(what: str, nbytes: int, detail: str | None = None) -> None:
    """Refuse, before any work starts, an allocation larger than the memory budget.

    Parameters
    ----------
    what : what would be allocated, as the message's subject (``"keep_paths"``,
        ``"1001 output times (periods 1000 x per_period 1)"``).
    nbytes : its size in bytes (a Python int: it may be far beyond 2^63).
    detail : how ``nbytes`` was counted, put in brackets after the size
        (``"samples 100000 x 12001 outputs x 2 states"``).

    Raises
    ------
    ValueError
        One line such as ``keep_paths needs 17.9 GiB (samples 100000 x 12001 outputs x 2
        states), more than the memory budget of 12 GiB (set OPA_MC_MEMORY_BUDGET to change
        it)``. The budget is :func:`memory_budget`: ``$OPA_MC_MEMORY_BUDGET`` (bytes, or
        with a suffix such as ``8G``) if set, else half the physical memory.

    Examples
    --------
    >>> check_memory("a small array", 800)
    """
    budget = memory_budget()
    if nbytes > budget:
        counted = f" ({detail})" if detail else ""
        raise ValueError(f"{what} needs {format_bytes(nbytes)}{counted}, more than the memory "
                         f"budget of {format_bytes(budget)} (set {MEMORY_BUDGET_ENV} to "
                         f"change it)")
