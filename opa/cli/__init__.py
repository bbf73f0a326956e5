"""The ``opa-mc`` application: argparse only, flags declared once (``_flags``).

The only package allowed to import ``opa``, ``mc`` and ``compare`` together."""

from opa.cli._main import build_parser, main

__all__ = ["build_parser", "main"]
