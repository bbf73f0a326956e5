"""argparse pieces shared by every subcommand: the parser class and whole-number types."""

from __future__ import annotations

import argparse
import math
import re

import numpy as np

from opa import MAX_WHOLE  # whole numbers above 2^53 are not exact as floats

EXIT_USAGE = 2
# A sweep of more values than this is refused: at the paper's 600 periods per value it
# would run for days on two cores (the paper's diagrams use 200 values).
MAX_SWEEP_VALUES = 100_000

# argparse reads "-1e-3" or "-inf" as an option unless told these are numbers
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
_NEGATIVE_NUMBER = re.compile(rf"^-{_NUMBER}(,-?{_NUMBER})*$|^-(inf|infinity|nan)$",
                              re.IGNORECASE)


_TRACKED: dict[type, type] = {}


def _tracked(cls: type) -> type:
    """``cls`` whose calls (argparse calls an action only for a flag on the command line,
    never for a default) record the flag as typed in ``namespace.given_flags``; a flag
    that takes one value and is given twice is refused (argparse would keep the last
    one without a word)."""
    if cls not in _TRACKED:
        def __call__(self, parser, namespace, values, option_string=None):
            if option_string:
                given = vars(namespace).setdefault("given_flags", {})
                if self.dest in given and issubclass(cls, argparse._StoreAction):
                    parser.error(f"{option_string} given twice ({given[self.dest]} "
                                 f"{getattr(namespace, self.dest, '')!s}, then "
                                 f"{option_string} {values!s}): give it once")
                given[self.dest] = option_string
            cls.__call__(self, parser, namespace, values, option_string)

        _TRACKED[cls] = type(cls.__name__, (cls,), {"__call__": __call__})
    return _TRACKED[cls]


class Parser(argparse.ArgumentParser):
    """argparse with negative numbers in any notation as values, and one-line errors.

    The flags given on the command line (not their defaults) are recorded in
    ``args.given_flags`` (dest -> the flag as typed), so that a flag that has no effect
    in the given combination can be refused (``opa.cli._flags.given``). ``foreign`` maps
    flags of sibling subcommands to why they do not apply here: such a flag is refused
    with that reason instead of argparse's "unrecognized arguments"."""

    def __init__(self, *args, foreign: dict[str, str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER
        self.foreign = dict(foreign or {})

    def parse_known_args(self, args=None, namespace=None):
        for action in self._actions:
            if action.option_strings and not isinstance(action, argparse._HelpAction):
                action.__class__ = _tracked(type(action))
        namespace, extras = super().parse_known_args(args, namespace)
        for token in extras:
            flag = token.split("=", 1)[0]
            if flag in self.foreign:
                self.error(f"{flag} {self.foreign[flag]}")
        return namespace, extras

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _whole(text: str, minimum: int) -> int:
    """``text`` as a whole number in [minimum, 2^53], also written as 1e3 (digits are
    read exactly: 2^53 + 1 is refused, not rounded to 2^53)."""
    try:
        if re.fullmatch(r"\s*[-+]?\d+\s*", text):
            value = int(text.strip())
        else:  # a float at 2^53 may be a rounded larger number: floats stay below it
            value = float(text)
            if not (math.isfinite(value) and abs(value) < MAX_WHOLE):
                raise ValueError
        if not (value == int(value) and minimum <= value <= MAX_WHOLE):
            raise ValueError
    except (ValueError, OverflowError):
        raise argparse.ArgumentTypeError(f"expected a whole number in {minimum}..2^53, got "
                                         f"{text!r}") from None
    return int(value)


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1, also written as 1e3."""
    return _whole(text, 1)


def whole_number(text: str) -> int:
    """An argparse type: a whole number >= 0, also written as 1e3."""
    return _whole(text, 0)




def parse_sweep(spec: str, *, names, default_count: int | None = None,
                max_count: int = MAX_SWEEP_VALUES, ranges_only: bool = False,
                flag: str = "--sweep"):
    """The one ``--sweep`` grammar: ``NAME=START:STOP:COUNT`` (COUNT equally spaced
    values, ends included; ``:COUNT`` may be left out where ``default_count`` is given)
    or ``NAME=V1,V2,...`` (distinct values; not where ``ranges_only``).

    Returns (name, values as an array, (start, stop, count)); the last is None for a
    list.

    >>> name, values, span = parse_sweep("c=0.01:0.1:10", names=("c",))
    >>> name, len(values), float(values[-1]), span
    ('c', 10, 0.1, (0.01, 0.1, 10))
    """
    counted = "[:COUNT]" if default_count is not None else ":COUNT"
    usage = (f"expected NAME=START:STOP{counted} (e.g. c=0.01:0.1:200)"
             + ("" if ranges_only else " or NAME=V1,V2,..."))
    name, sep, rhs = spec.partition("=")
    name = name.strip().lstrip("-")
    if not sep or not name or not rhs:
        raise ValueError(f"{flag} {spec!r}: {usage}")
    if name not in names:
        raise ValueError(f"{flag} {spec!r}: unknown parameter {name!r} "
                         f"(choose from {', '.join(names)})")

    def number(text, what):
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{flag} {spec!r}: {what} {text!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{flag} {spec!r}: {what} must be finite, got {text!r}")
        return value

    if ":" not in rhs:
        if ranges_only:
            raise ValueError(f"{flag} {spec!r}: {usage}")
        values = [number(v, "value") for v in rhs.split(",")]
        if len(values) > max_count:
            raise ValueError(f"{flag}: at most {max_count} values, got {len(values)}")
        if len(set(values)) != len(values):
            raise ValueError(f"{flag} {spec!r}: values must be distinct")
        return name, np.array(values), None
    fields = rhs.split(":")
    if len(fields) != 3 and not (len(fields) == 2 and default_count is not None):
        raise ValueError(f"{flag} {spec!r}: {usage}")
    start, stop = number(fields[0], "START"), number(fields[1], "STOP")
    if len(fields) == 2:
        count = default_count
    else:
        try:
            count = int(fields[2])
        except ValueError:
            raise ValueError(f"{flag} {spec!r}: COUNT must be an integer >= 1, "
                             f"got {fields[2]!r}") from None
    if not 1 <= count <= max_count:
        raise ValueError(f"{flag} {spec!r}: COUNT must be an integer in 1..{max_count}, "
                         f"got {count}")
    if count == 1 and start != stop:
        raise ValueError(f"{flag} {spec!r}: COUNT = 1 needs START == STOP")
    if count > 1 and start == stop:
        raise ValueError(f"{flag} {spec!r}: START and STOP are equal, got {start:g}")
    return name, np.linspace(start, stop, count), (start, stop, count)


__all__ = ["EXIT_USAGE", "MAX_SWEEP_VALUES", "Parser", "parse_sweep", "positive_int",
           "whole_number"]
