"""`python -m controller_stub.warm`: a simulator that imports first and is told later what
to serve (hostpc's `--robot sim` starts it before its own imports, hostpc/robots/warm_stub.py).

Importing the simulator (numpy, OpenCV, pydantic, the server) is nearly all of a stub's
start-up (~0.4 s); a process that does it while its parent is still importing and checking
its options overlaps the two on a machine with two cores. Once imported it reads ONE line
from stdin, a JSON object:

    {"argv": ["serve", "--scenario", ...], "env": {"ZEROCAL_TOKEN": ...}, "stderr": PATH}

sets `env` (the token travels through the pipe, never the command line), appends its stderr
to PATH from then on, and runs `controller-stub ARGV` exactly as a fresh process would.
End of input before that line (the parent did not need a simulator, or died) ends it with
exit code 0 and no output.
"""

from __future__ import annotations

import gc
import json
import os
import sys


def _import_the_simulator() -> None:
    """The modules `controller-stub serve` imports (controller_stub/cli.py `_serve`)."""
    import controller_stub.cli  # noqa: F401
    import controller_stub.network.server  # noqa: F401
    import controller_stub.scenario.spec  # noqa: F401
    import controller_stub.sensors.registry  # noqa: F401


def main() -> int:
    gc.disable()  # imports make no garbage; their objects live as long as the process
    _import_the_simulator()
    gc.freeze()  # and no collection need visit them
    gc.enable()
    line = sys.stdin.readline()
    if not line.strip():
        return 0
    order = json.loads(line)
    os.environ.update({str(k): str(v) for k, v in order.get("env", {}).items()})
    if order.get("stderr"):
        sys.stderr.flush()
        log = os.open(order["stderr"], os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        os.dup2(log, 2)
        os.close(log)
    from controller_stub.cli import exit_without_collecting
    from controller_stub.cli import main as stub_main

    try:
        return stub_main([str(word) for word in order["argv"]])
    finally:
        exit_without_collecting()


if __name__ == "__main__":
    sys.exit(main())
