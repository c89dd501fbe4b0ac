"""The ``springflat`` console script.

A thin door in front of :func:`sim.cli.main`. Importing the commands takes a second or two (numpy,
scipy, matplotlib), and a Ctrl-C in that time must end the program like one during a command, with
the one line ``springflat: interrupted`` and status 130 — not a traceback from inside an import,
nor the ImportError that a C extension's import cut short by the signal turns into. So SIGINT is
only recorded while the commands are imported, and answered once they are.
"""

from __future__ import annotations

import signal
import sys

from .exit_codes import EXIT_INTERRUPTED


def _interrupted() -> int:
    print("springflat: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def main() -> int:
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        from .cli import main as run_command
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        return _interrupted()
    try:
        return run_command()  # installs its own handler (sim.outputs.on_interrupt)
    except KeyboardInterrupt:  # in the instants before that handler, or after it is removed
        return _interrupted()
