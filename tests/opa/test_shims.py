"""Tests for ``opa._shims``: ``opa.sweep`` is ``opa.dynamics.sweep`` with the Monte Carlo
trajectory source ``mc.sweep_source`` filled in for the model "mc" (and only then), and
``opa.reproduce`` warns that it moved and hands its arguments to ``compare.reproduce``."""

from __future__ import annotations

import pytest

import opa
from opa import _shims


@pytest.fixture
def calls(monkeypatch):
    seen = []
    monkeypatch.setattr(_shims, "_sweep", lambda *args, **kwargs: seen.append((args, kwargs)))
    return seen


def test_sweep_fills_in_the_mc_source_for_the_mc_model_only(calls):
    import mc

    osc = opa.Oscillator()
    opa.sweep("mc", "c", [0.1, 0.2], osc, samples=4)
    opa.sweep("dmr", "c", [0.1, 0.2], osc)
    mine = object()
    opa.sweep("mc", "c", [0.1], osc, source=mine)
    assert calls[0] == (("mc", "c", [0.1, 0.2], osc), {"samples": 4, "source": mc.sweep_source})
    assert calls[1] == (("dmr", "c", [0.1, 0.2], osc), {})
    assert calls[2][1]["source"] is mine


def test_reproduce_warns_and_delegates_to_compare(monkeypatch, tmp_path):
    import compare._figures

    seen = []
    monkeypatch.setattr(compare._figures, "reproduce",
                        lambda *args, **kwargs: seen.append((args, kwargs)) or ["a.png"])
    with pytest.warns(DeprecationWarning, match="compare.reproduce"):
        assert opa.reproduce("fig2", tmp_path, workers=1) == ["a.png"]
    assert seen == [(("fig2", tmp_path), {"workers": 1})]
