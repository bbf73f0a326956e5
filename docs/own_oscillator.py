"""Reruns the commands of docs/own-oscillator.md and writes what they print under each.

Every ``    $ opa-mc ...`` line of the page is run in this process from the repository's root
(``opa.cli._main.main``); the indented lines below it, up to the next blank line, are
replaced by its standard output (and, for a command that is refused, its one-line error
and the exit status); the output's own blank lines are written indented, so the block
ends at the first line that is not. ``tests/test_docs.py`` reruns them and fails when the page says
anything else; wall times ("in 0.41 s") are compared as numbers of the same form only.

    python docs/own_oscillator.py            # rewrite docs/own-oscillator.md
    python docs/own_oscillator.py --check    # exit 1 when the page is stale
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import sys

DOCS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(DOCS)
PAGE = os.path.join(DOCS, "own-oscillator.md")
PROMPT = "    $ opa-mc "
#: the wall times of a run, which no two runs share
_TIME = re.compile(r"\d+\.\d+ s\b")


def printed(command: str) -> list[str]:
    """What ``opa-mc command`` prints, run from the repository's root: its standard
    output, or its error line and exit status when it is refused."""
    from opa.cli._main import main

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(shlex.split(command))
            except SystemExit as stop:  # argparse
                status = stop.code
    finally:
        os.chdir(here)
    lines = out.getvalue().splitlines()
    if status != 0:
        lines += [line for line in err.getvalue().splitlines() if line.startswith("opa-mc")]
        lines.append(f"(exit status {status})")
    return lines


def render(text: str) -> str:
    """The page with each command's output rerun."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        i += 1
        if line.startswith(PROMPT):
            while (i < len(lines) and lines[i].startswith("    ")
                   and not lines[i].startswith(PROMPT)):
                i += 1  # the output printed before (its blank lines are indented too)
            out += [f"    {printed_line}" for printed_line in printed(line[len(PROMPT):])]
    return "\n".join(out) + "\n"


def same(page: str, fresh: str) -> bool:
    """Whether two renderings agree but for the wall times."""
    return _TIME.sub("T s", page) == _TIME.sub("T s", fresh)


def main(argv: list[str]) -> int:
    with open(PAGE, encoding="utf-8") as fh:
        page = fh.read()
    fresh = render(page)
    if "--check" in argv:
        if not same(page, fresh):
            print(f"{PAGE} is stale: run python docs/own_oscillator.py", file=sys.stderr)
            return 1
        return 0
    with open(PAGE, "w", encoding="utf-8") as fh:
        fh.write(fresh)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
