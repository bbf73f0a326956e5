"""How long `opa-mc bifurcation` and `opa-mc stochastic` take to refuse a silent scheduler.

A TCP endpoint that accepts connections and never says a word (a Dask scheduler speaks
first) is started here; each command is pointed at it with ``--scheduler`` and its exit
status, wall time (process start-up included) and last line are printed. Both must exit
2 within the connection timeout of ``opa.Execution`` (5 s) plus their start-up.

    python benchmarks/silent_scheduler.py
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time


@contextlib.contextmanager
def silent_endpoint():
    """The address of a TCP endpoint that accepts connections and never says a word,
    open for the block (every socket closed after it)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held = []

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)

    threading.Thread(target=serve, daemon=True).start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.close()
        for conn in held:
            conn.close()


def main() -> None:
    out = tempfile.mkdtemp()
    commands = {
        "bifurcation": ["bifurcation", "dmr", "--sweep", "c=0.03:0.06:3", "--transient",
                        "20", "--record", "10", "--out", os.path.join(out, "b.nc")],
        "stochastic": ["stochastic", "--sweep", "c=0.04:0.05:2", "--sigma", "0.03",
                       "--samples", "0", "--out", os.path.join(out, "s.nc")],
    }
    print(f"load average {os.getloadavg()[0]:.2f}")
    with silent_endpoint() as address:
        for name, argv in commands.items():
            start = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "opa.cli", *argv, "--scheduler",
                                   address], capture_output=True, text=True, timeout=120)
            last = (done.stderr.strip().splitlines() or [""])[-1]
            print(f"{name}: exit {done.returncode} after {time.perf_counter() - start:.1f} s: "
                  f"{last}")


if __name__ == "__main__":
    main()
