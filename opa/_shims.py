"""Public names of ``opa`` whose work lives in a higher layer (ARCHITECTURE: ``opa`` never
imports ``mc`` or ``compare``). These two functions are the only exception, and they
import upward only when called; ``tests/test_architecture.py`` allows exactly them.

- ``opa.sweep`` is ``opa.dynamics.sweep``, with ``mc.sweep_source`` filled in for the
  model ``"mc"``.
- ``opa.reproduce`` moved to ``compare.reproduce`` (the figures need the Monte Carlo
  truth beside the EMR); this name still works and warns.
"""

from __future__ import annotations

import functools
import warnings

from opa.dynamics._sweep import sweep as _sweep


@functools.wraps(_sweep)
def sweep(model, param, values, oscillator=None, **kwargs):
    if model == "mc" and kwargs.get("source") is None:
        from mc import sweep_source

        kwargs["source"] = sweep_source
    return _sweep(model, param, values, oscillator, **kwargs)


def reproduce(figure: str, outdir="figures", **kwargs):
    """Deprecated: use ``compare.reproduce`` (same arguments)."""
    warnings.warn("opa.reproduce moved to compare.reproduce", DeprecationWarning, stacklevel=2)
    from compare._figures import reproduce as _reproduce

    return _reproduce(figure, outdir, **kwargs)
