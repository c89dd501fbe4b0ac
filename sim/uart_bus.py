"""The host side of the UART link: :class:`UartBus`, the engine driver's bus over frames
(:mod:`golden_model.engine_spec.uart_protocol`) on any byte stream.

The stream is anything with ``write(data: bytes)`` and ``read(n) -> bytes`` that returns fewer than ``n``
bytes when its own timeout passes: pyserial's ``serial.Serial`` (a board's USB-UART, :func:`open_port`),
or a simulated UART (``sim/cocotb_benches/board.py``, the tests' socket server).

Every ``read``/``write`` is one frame and waits for its answer, so an error answer is raised by the call
that caused it: the driver's :class:`~sim.engine_driver.BusError` for every error status (the engine's
``err``, and the link's own: a bad checksum, length, command, address or a truncated frame), and
:class:`LinkError` when no whole answer comes back in time or the answer itself is corrupt. Inside
:meth:`UartBus.batched` consecutive writes are sent as one frame of up to
:data:`~golden_model.engine_spec.uart_protocol.MAX_WORDS` words (a run of addresses ends at a
window's stride hole: where a window's items leave a gap, each item is a frame of its words; the default
preset's node, 5 words at a stride of 8, is one): a write's error is then raised by the call that sends its
frame (a read, a write that does not continue the run of addresses, or the end of the block). :meth:`UartBus.read_words` reads a run of words in one
frame; the driver reads a node's words so.
"""

from __future__ import annotations

import contextlib
import os
import re
import stat

from golden_model.engine_spec import uart_protocol as protocol
from golden_model.files import file_kind

from .engine_driver import BusError, EngineError

__all__ = ["LinkError", "UartBus", "open_port"]


class LinkError(EngineError):
    """No whole answer, or a corrupt one, from the other end of the link (one line)."""


class UartBus:
    """``read(word_address)`` / ``write(word_address, value)`` over the frame format on ``port``."""

    def __init__(self, port, *, name: str = "the link"):
        self.port, self.name = port, name
        self._pending: list[int] = []
        self._pending_address = 0
        self._batching = 0
        self.frames = 0

    # ------------------------------------------------------------------ frames
    def _exchange(self, request: bytes, what: str) -> protocol.Answer:
        try:
            return self._exchange_on_port(request, what)
        except OSError as exc:  # (pyserial's SerialException too: a USB-UART pulled out, a socket closed)
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise LinkError(f"lost {self.name} during {what}: {reason}") from None

    def _exchange_on_port(self, request: bytes, what: str) -> protocol.Answer:
        reset = getattr(self.port, "reset_input_buffer", None)
        if reset is not None:  # nothing stale from an earlier, abandoned exchange
            reset()
        self.port.write(request)
        head = self._read_exactly(protocol.ANSWER_HEAD_BYTES, what)
        status, count = head
        asked = protocol.request_words(request)
        if status == protocol.OK and count != asked:  # (a body of another length would be waited for in vain)
            raise LinkError(f"corrupt answer from {self.name} to {what}: OK with {count} words for {asked}")
        body = protocol.answer_data_bytes(request, status)
        answer = head + self._read_exactly(body + 1, what, already=len(head))
        self.frames += 1
        try:
            return protocol.decode_answer(answer)
        except ValueError as exc:
            if request.startswith(answer):  # the request's own bytes came back: a loopback (loop://, a jumper)
                raise LinkError(f"{self.name} echoes what is sent ({what}): a loopback, not the board's bridge") \
                    from None
            raise LinkError(f"corrupt answer from {self.name} to {what}: {exc}") from None

    def _read_exactly(self, n: int, what: str, already: int = 0) -> bytes:
        """``n`` bytes of the answer to ``what``, of which ``already`` have come (for the message)."""
        data = self.port.read(n)
        if len(data) < n:
            got = f"{already + len(data)} of {already + n} bytes" if already or data else "nothing"
            raise LinkError(f"no answer from {self.name} to {what} ({got} before the timeout): is the board "
                            "programmed with springflat_ulx3s.bit, and the baud rate the bitstream's?")
        return bytes(data)

    @staticmethod
    def _raise(answer: protocol.Answer, kind: str, address: int, length: int) -> None:
        if answer.status == protocol.BUS_ERROR:
            raise BusError(f"bus error: {kind} at word address {address + answer.count:#x} answered err")
        raise BusError(f"the bridge refused a {kind} of {length} word(s) at word address {address:#x}: "
                       f"{answer.status_name}")

    def read_words(self, address: int, length: int) -> list[int]:
        """``length`` words from ``address`` up (one frame: at most ``MAX_WORDS``)."""
        self.flush()
        answer = self._exchange(protocol.encode_read(address, length), f"a read at {address:#x}")
        if answer.status != protocol.OK:
            self._raise(answer, "read", address, length)
        if len(answer.words) != length:
            raise LinkError(f"{self.name} answered {len(answer.words)} words to a read of {length}")
        return list(answer.words)

    def write_words(self, address: int, words: list[int]) -> None:
        """``words`` from ``address`` up (one frame: at most ``MAX_WORDS``)."""
        answer = self._exchange(protocol.encode_write(address, [w & 0xFFFF_FFFF for w in words]),
                                f"a write at {address:#x}")
        if answer.status != protocol.OK:
            self._raise(answer, "write", address, len(words))

    # ------------------------------------------------------------------ the driver's bus
    def read(self, address: int) -> int:
        return self.read_words(address, 1)[0]

    def write(self, address: int, value: int) -> None:
        if not self._batching:
            self.write_words(address, [value])
            return
        if self._pending and address != self._pending_address + len(self._pending):
            self.flush()
        if not self._pending:
            self._pending_address = address
        self._pending.append(value)
        if len(self._pending) == protocol.MAX_WORDS:
            self.flush()

    def flush(self) -> None:
        """Send the batched writes."""
        if self._pending:
            address, words = self._pending_address, self._pending
            self._pending = []
            self.write_words(address, words)

    @contextlib.contextmanager
    def batched(self):
        """Consecutive writes in one frame (see the module's docstring); flushed at the end of the block."""
        self._batching += 1
        try:
            yield self
        except BaseException:
            self._batching -= 1
            self._pending = []  # the block failed: what it had not sent is not sent
            raise
        self._batching -= 1
        if not self._batching:
            self.flush()


def open_port(port: str, baud: int = protocol.DEFAULT_BAUD, timeout_s: float = 2.0):
    """A pyserial port: a device (``/dev/ttyUSB0``, ``COM3``) or a pyserial URL (``socket://host:port``).
    Raises :class:`LinkError` (one line) when it cannot be opened."""
    import urllib.parse

    import serial

    url = urllib.parse.urlsplit(port)
    if "://" in port and url.scheme in ("socket", "rfc2217"):  # (pyserial's own error is a TypeError's text)
        try:
            numbered = url.port is not None
        except ValueError:
            numbered = False
        if not numbered:
            raise LinkError(f"cannot open the serial port '{port}': a {url.scheme}:// URL needs a port number "
                            f"({url.scheme}://HOST:PORT)")
    if "://" in port and "file" in urllib.parse.parse_qs(url.query):  # spy://...?file=PATH truncates PATH
        raise LinkError(f"the serial port '{port}' names a log file (file=), which springflat would write "
                        "unchecked (it could replace any file, a mesh too): leave out file= (spy:// then logs "
                        "to standard error)")
    if "://" not in port:  # a device's path: a file of another kind is no port (pyserial's words name an ioctl)
        try:
            mode = os.stat(port).st_mode
        except OSError:
            mode = None  # (COM3, or a path that does not exist: pyserial says why)
        if mode is not None and not stat.S_ISCHR(mode):
            raise LinkError(f"cannot open the serial port '{port}': it is a {file_kind(mode)}, not a serial device "
                            "(such as /dev/ttyUSB0)")
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=timeout_s, write_timeout=timeout_s)
    except (serial.SerialException, ValueError, OSError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        # pyserial's words name the port again ('[Errno 2] could not open port P: [Errno 2] No such file ...: 'P'')
        reason = re.sub(rf"^(\[Errno \d+\] )?[Cc]ould not open port {re.escape(port)}: ", "", reason)
        reason = reason.removesuffix(f": '{port}'")
        raise LinkError(f"cannot open the serial port '{port}': {reason}") from None
