"""argparse pieces shared by every subcommand: the parser class and whole-number types."""

from __future__ import annotations

import argparse
import math
import re

EXIT_USAGE = 2
# A sweep of more values than this is refused: at the paper's 600 periods per value it
# would run for days on two cores (the paper's diagrams use 200 values).
MAX_SWEEP_VALUES = 100_000

# argparse reads "-1e-3" or "-inf" as an option unless told these are numbers
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
_NEGATIVE_NUMBER = re.compile(rf"^-{_NUMBER}(,-?{_NUMBER})*$|^-(inf|infinity|nan)$",
                              re.IGNORECASE)
# Whole numbers above 2^53 are not exact as floats, and no count or seed needs them.
MAX_WHOLE = 2**53


class Parser(argparse.ArgumentParser):
    """argparse with negative numbers in any notation as values, and one-line errors."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _whole(text: str, minimum: int) -> int:
    """``text`` as a whole number in [minimum, 2^53], also written as 1e3."""
    try:
        value = float(text)
        if not (math.isfinite(value) and value == int(value) and minimum <= value <= MAX_WHOLE):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number in {minimum}..2^53, got "
                                         f"{text!r}") from None
    return int(value)


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1, also written as 1e3."""
    return _whole(text, 1)


def whole_number(text: str) -> int:
    """An argparse type: a whole number >= 0, also written as 1e3."""
    return _whole(text, 0)


__all__ = ["EXIT_USAGE", "MAX_SWEEP_VALUES", "Parser", "positive_int", "whole_number"]
