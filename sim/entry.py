"""The ``springflat`` console script.

A thin door in front of :func:`sim.cli.main`. Importing the commands takes a second or two (numpy,
scipy, matplotlib), and a Ctrl-C in that time must end the program like one during a command, with
the one line ``springflat: interrupted`` and status 130 — not a traceback from inside an import,
nor the ImportError that a C extension's import cut short by the signal turns into. So SIGINT (and
SIGTERM and SIGHUP, answered alike with ``springflat: terminated`` and 143 and ``springflat: hung up``
and 129) is only recorded while the commands are imported, and answered once they are; from then on,
also in the instants before the command installs its own handler and after it puts it back, as the
command answers it; one that is ignored when it starts (``nohup``'s SIGHUP) stays ignored. Once the program
has its status (the command's, a usage error's, an interrupt's), all three are ignored while Python shuts down.
"""

from __future__ import annotations

import io
import os
import signal
import sys

from .exit_codes import STOP_SIGNALS, answered_signals


def _stopped(name: str) -> int:
    line, status = STOP_SIGNALS[name]
    try:
        print(f"springflat: {line}", file=sys.stderr)
    except OSError:  # after SIGHUP the terminal may be gone (EIO)
        pass
    return status


class ClosedStandardOutput(io.StringIO):
    """What stands for a standard output closed at the start (``>&-``): the lines printed there are dropped
    (:func:`sim.cli.main` refuses any command's ``--json``, which asks for nothing else)."""

    closed_at_start = True


def main() -> int:
    try:
        return _run()
    finally:  # done, its outputs in place or not, its status said: the status stands
        for name in STOP_SIGNALS:
            # ignored, not answered: Python's shutdown puts a Python handler back to the default action (and a
            # signal in that time, tens of milliseconds, killed the finished program with no line), but leaves
            # an ignored signal ignored
            signal.signal(getattr(signal, name), signal.SIG_IGN)


def _run() -> int:
    # The command draws into files only: matplotlib's file backend, whatever MPLBACKEND names (a name matplotlib
    # does not know fails its import, the run with it); its worker processes inherit it.
    os.environ["MPLBACKEND"] = "Agg"
    if sys.stderr is None:  # started with its standard error closed (2>&-): what it says there is dropped,
        sys.stderr = io.StringIO()  # not sent to print()'s default, the standard output (a --json line)
    if sys.stdout is None:  # closed (>&-): what it prints there is dropped; its files are still written, and
        sys.stdout = ClosedStandardOutput()  # --json, which asks for the standard output alone, is refused
    if isinstance(sys.stdout, io.TextIOWrapper):  # a file name its encoding lacks (a Windows code page, a C
        sys.stdout.reconfigure(errors="backslashreplace")  # locale) comes out escaped, as on stderr, not a traceback
    received: list[str] = []

    def record(signum, frame) -> None:
        received.append(signal.Signals(signum).name)

    previous = {name: signal.signal(getattr(signal, name), record) for name in answered_signals()}
    answer = None
    try:
        from .cli import main as run_command
        from .outputs import on_interrupt as answer, received_signal
    finally:
        # from here on a signal is answered as in a command (KeyboardInterrupt, the signal noted), also
        # before the command installs that handler itself and after it is put back: with the default
        # action a kill in those instants ended the program with no line
        for name, before in previous.items():
            signal.signal(getattr(signal, name), answer or before)
    if received:
        return _stopped(received[0])
    try:
        status = run_command()
    except KeyboardInterrupt:  # in the instants before the command's handler, or after it is removed
        return _stopped(received_signal().name)
    return status
