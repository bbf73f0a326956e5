"""Fork-server preload of the sweep process pools (``opa._bifurcation.local_executor``).

Importing this module loads the compiled integrator from numba's on-disk cache (1-2 s),
once, in the fork server; every worker forked from it then starts warm instead of
loading the kernel itself. Nothing else imports it. Only the serial kernel is touched:
starting numba's thread pool here would make forking from this process unsafe.
"""

from opa._model import Oscillator
from opa._simulate import simulate_dmr

simulate_dmr(Oscillator(), periods=1)
