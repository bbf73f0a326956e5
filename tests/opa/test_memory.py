"""Tests for opa._memory: sizes in bytes read and written, and the memory budget that
sizes are checked against before computing (README, 'Errors, limits and resuming')."""

from __future__ import annotations

import os

import pytest

from opa import _memory
from opa._memory import check_memory, format_bytes, memory_budget, parse_bytes


@pytest.mark.parametrize(
    ("text", "nbytes"),
    [("1073741824", 2**30), ("8G", 8 * 2**30), ("8GiB", 8 * 2**30), ("8gb", 8 * 2**30),
     ("512M", 512 * 2**20), ("1.5K", 1536), (" 2T ", 2 * 2**40), ("0", 0)],
)  # fmt: skip
def test_parse_bytes(text, nbytes):
    assert parse_bytes(text) == nbytes


@pytest.mark.parametrize("text", ["", "eight", "8X", "-1G", "1e9", "8 G B"])
def test_parse_bytes_refuses_what_is_not_a_size(text):
    with pytest.raises(ValueError, match=r"a size must be a number of bytes"):
        parse_bytes(text)


@pytest.mark.parametrize(
    ("nbytes", "text"),
    [(512, "512 B"), (1536, "1.5 KiB"), (12 * 2**30, "12 GiB"),
     (100000 * 12001 * 2 * 8, "17.9 GiB"), (2**20 - 1, "1 MiB"), (3 * 2**60, "3 EiB")],
)  # fmt: skip
def test_format_bytes(nbytes, text):
    assert format_bytes(nbytes) == text


def test_check_memory_message_names_the_size_the_budget_and_the_variable(monkeypatch):
    monkeypatch.setenv("OPA_MC_MEMORY_BUDGET", "12G")
    assert memory_budget() == 12 * 2**30
    check_memory("keep_paths", 12 * 2**30)  # at the budget: allowed
    with pytest.raises(ValueError) as err:
        check_memory("keep_paths", 100000 * 12001 * 2 * 8,
                     "samples 100000 x 12001 outputs x 2 states")
    assert str(err.value) == (
        "keep_paths needs 17.9 GiB (samples 100000 x 12001 outputs x 2 states), more than "
        "the memory budget of 12 GiB (set OPA_MC_MEMORY_BUDGET to change it)")
    with pytest.raises(ValueError, match=r"^1001 output times needs 1 TiB, more than"):
        check_memory("1001 output times", 2**40)


def test_memory_budget_defaults_to_half_the_physical_memory(monkeypatch):
    monkeypatch.delenv("OPA_MC_MEMORY_BUDGET", raising=False)
    half = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    assert _memory._half_physical_memory() == half
    monkeypatch.setattr(_memory, "MEMORY_BUDGET_BYTES", 1000)
    assert memory_budget() == 1000
    with pytest.raises(ValueError, match=r"needs 1001 B, more than the memory budget of "
                                         r"1000 B"):  # fmt: skip
        check_memory("something", 1001)


def test_a_bad_budget_variable_is_named(monkeypatch):
    monkeypatch.setenv("OPA_MC_MEMORY_BUDGET", "lots")
    with pytest.raises(ValueError, match=r"^OPA_MC_MEMORY_BUDGET: a size must be .* got "
                                         r"'lots'$"):  # fmt: skip
        check_memory("x", 1)
