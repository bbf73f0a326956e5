"""``python -m opa.cli``: the ``opa-mc`` command."""

import sys

from opa.cli._main import main

sys.exit(main())
