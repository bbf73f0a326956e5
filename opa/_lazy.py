"""Heavy libraries imported on first use, so that ``import opa`` stays cheap.

``xr = lazy("xarray")`` gives an object whose attribute access imports xarray once and
then behaves as the module (``xr.Dataset``, ``xr.open_dataset``); a module that only
names xarray in annotations (``from __future__ import annotations``) never imports it.
"""

from __future__ import annotations

import importlib


class LazyModule:
    """A stand-in for a module, imported on its first attribute access."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        module = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r}>"


def lazy(name: str) -> LazyModule:
    return LazyModule(name)
