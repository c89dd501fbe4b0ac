"""The ``springflat`` console script.

A thin door in front of :func:`sim.cli.main`: importing the commands takes a second or two (numpy,
scipy, matplotlib), and a Ctrl-C in that time must end the program like one during a command, with
the one line ``springflat: interrupted`` and status 130, not a traceback from inside an import.
"""

from __future__ import annotations

import sys

EXIT_INTERRUPTED = 130


def main() -> int:
    try:
        from .cli import main as run_command

        return run_command()
    except KeyboardInterrupt:  # before the command's own handler is in place (it answers the same way)
        print("springflat: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
