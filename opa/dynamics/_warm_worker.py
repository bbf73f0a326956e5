"""Fork-server preload of the sweep process pools (``opa.dynamics._sweep.local_executor``).

Importing this module loads the compiled integrator from numba's on-disk cache (1-2 s),
once, in the fork server; every worker forked from it then starts warm instead of
loading the kernel itself. Nothing else imports it. Only the serial kernel is touched:
starting numba's thread pool here would make forking from this process unsafe (the one
thread started here only sleeps and reads the parent pid).

It also ties the fork server's life to the process that started it. Left alone, the fork
server lives as long as any of its workers, and the workers, blocked on the pool's queue,
live forever once that process is killed. Here the fork server ends when its parent does,
and the workers, who ask for SIGKILL at their parent's death
(``opa.dynamics._sweep._init_worker``), end with it.
"""

from opa.dynamics._sweep import exit_with_parent
from opa._model import Oscillator
from opa._simulate import simulate_dmr

exit_with_parent()
simulate_dmr(Oscillator(), periods=1)
