"""Tests for ``opa._lazy``: a lazy module imports its module on the first attribute access,
not before, and then behaves as that module."""

from __future__ import annotations

import subprocess
import sys

from opa._lazy import LazyModule, lazy


def test_the_module_is_imported_on_first_attribute_access_only():
    # in a fresh interpreter, with a standard module that nothing else imports
    code = ("import sys\n"
            "from opa._lazy import lazy\n"
            "m = lazy('colorsys')\n"
            "before = 'colorsys' in sys.modules\n"
            "h = m.rgb_to_hsv(1.0, 0.0, 0.0)\n"
            "print(before, 'colorsys' in sys.modules, h)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().split(maxsplit=2)
    assert out == ["False", "True", "(0.0, 1.0, 1.0)"]


def test_a_lazy_module_behaves_as_the_module():
    import json

    m = lazy("json")
    assert isinstance(m, LazyModule) and repr(m) == "<lazy module 'json'>"
    assert m.dumps is json.dumps and m.loads("[1, 2]") == [1, 2]
