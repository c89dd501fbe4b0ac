"""The exit statuses of ``springflat`` (besides 0 and 1), in one place.

A module of its own with no imports but the standard library's ``signal``, so that the console script's
door (:mod:`sim.entry`) can use them before the commands are imported.
"""

import signal

EXIT_USAGE = 2
"""Bad arguments or input: one line ``springflat: error: ...``."""
EXIT_DIVERGED = 3
"""A run diverged (no pattern is written; the history and plot show the run)."""
EXIT_MESHES_FAILED = 4
"""A batch ran to its end and some of its meshes failed (the others' files are written); a batch refused
before its first run is :data:`EXIT_USAGE`."""
EXIT_HUNG_UP = 129
"""SIGHUP (the terminal closed, an SSH session dropped), as a shell reports it: 128 + 1."""
EXIT_INTERRUPTED = 130
"""Ctrl-C (SIGINT), as a shell reports it: 128 + 2."""
EXIT_TERMINATED = 143
"""SIGTERM (``kill``, a job's time limit), as a shell reports it: 128 + 15."""

#: The signals a command ends on cleanly (outputs not put in place, child processes killed), each with
#: its one line after ``springflat: `` and its status.
STOP_SIGNALS = {"SIGINT": ("interrupted", EXIT_INTERRUPTED), "SIGTERM": ("terminated", EXIT_TERMINATED),
                "SIGHUP": ("hung up", EXIT_HUNG_UP)}


def answered_signals() -> list[str]:
    """The :data:`STOP_SIGNALS` a command answers: those not ignored now. An ignored one stays ignored, as
    the shell or the user meant: ``nohup`` (SIGHUP), a script's background job (SIGINT)."""
    return [name for name in STOP_SIGNALS if signal.getsignal(getattr(signal, name)) is not signal.SIG_IGN]
