"""The host link's frame format over a UART: constants, encoding, and the target's behaviour as a reference.

Why here: the frame format is pure data (byte codes, lengths, the checksum's parameters), like the
engine's register map beside it; ``hdl/uart_bridge.py`` (the bridge in RTL) and ``sim/uart_bus.py``
(the host transport) both import it, so a code or a length is written once. Nothing here needs
numpy or Amaranth: the checksum is computed bit by bit in Python (:func:`crc8`).

**Line.** 8 data bits, no parity, 1 stop bit, least significant bit first, at :data:`DEFAULT_BAUD`
unless the bitstream was built for another rate.

**Request** (host to bridge), multi-byte fields big-endian:

=====  ==========================================================================
bytes  field
=====  ==========================================================================
1      command: :data:`READ` (``'R'``, 0x52) or :data:`WRITE` (``'W'``, 0x57)
4      word address of the first word (byte address >> 2)
1      length ``n``: words to read or write, 1 .. :data:`MAX_WORDS`; word ``k`` at ``address + k``
4·n    write only: the ``n`` data words
1      CRC-8 of every byte before it (:data:`CRC8`: polynomial 0x07, initial 0, no reflection, no final XOR)
=====  ==========================================================================

**Answer** (bridge to host): ``status`` (1 byte), ``count`` (1 byte), then for a read answered
:data:`OK` the ``count`` = ``n`` words read (4 bytes each), then the CRC-8 of every answer byte before it.
``count`` is the number of words the bus completed: ``n`` for :data:`OK`, the index of the word whose
access answered ``err`` for :data:`BUS_ERROR` (the words before it were written or read), 0 otherwise.

**Statuses and when they are sent.** A frame with any error but :data:`BUS_ERROR` makes no bus
access: a write's data are held in the bridge until the checksum has been checked.

* :data:`OK`: after the last access.
* :data:`BAD_CHECKSUM`: the CRC byte does not match; sent after it.
* :data:`BAD_ADDRESS`: ``address + n`` is past the bus's address space; sent after the CRC byte.
* :data:`BUS_ERROR`: a word's access answered ``err``; sent after it, the remaining words not accessed.
* :data:`BAD_COMMAND`, :data:`BAD_LENGTH` (0 or over :data:`MAX_WORDS`): the bridge cannot know where
  such a frame ends, so it drops bytes until the line has been idle for the inter-byte timeout, then
  answers (the host's next frame then starts clean).
* :data:`TIMEOUT`: the line went idle for the inter-byte timeout (:data:`INTER_BYTE_TIMEOUT_S` on the
  board) in the middle of a frame (a truncated frame); sent at that moment.

One frame at a time: the host waits for each answer before it sends the next frame (bytes that arrive
while the bridge executes or answers are dropped).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from .image import BUS_WORD_BITS

__all__ = ["READ", "WRITE", "COMMANDS", "OK", "BAD_CHECKSUM", "BAD_LENGTH", "BAD_COMMAND", "TIMEOUT", "BUS_ERROR",
           "BAD_ADDRESS", "STATUS_NAMES", "MAX_WORDS", "ADDRESS_BYTES", "WORD_BYTES", "HEADER_BYTES",
           "ENGINE_CLOCK_HZ", "DEFAULT_BAUD", "INTER_BYTE_TIMEOUT_S", "CRC8", "crc8", "encode_read", "encode_write", "answer_bytes",
           "Answer", "decode_answer", "request_length", "ReferenceTarget"]

READ = 0x52  # 'R'
WRITE = 0x57  # 'W'
COMMANDS = {READ: "read", WRITE: "write"}

OK = 0x00
BAD_CHECKSUM = 0x01
BAD_LENGTH = 0x02
BAD_COMMAND = 0x03
TIMEOUT = 0x04
BUS_ERROR = 0x05
BAD_ADDRESS = 0x06
STATUS_NAMES = {OK: "ok", BAD_CHECKSUM: "bad checksum", BAD_LENGTH: "bad length", BAD_COMMAND: "bad command",
                TIMEOUT: "truncated frame (inter-byte timeout)", BUS_ERROR: "bus error", BAD_ADDRESS: "bad address"}

#: Words one frame reads or writes at most: the bridge's buffer depth (a write is buffered whole until its
#: checksum has been checked). 64 words make a write frame of 263 bytes, 97 % payload.
MAX_WORDS = 64
ADDRESS_BYTES = 4
WORD_BYTES = BUS_WORD_BITS // 8
#: command, address, length
HEADER_BYTES = 1 + ADDRESS_BYTES + 1

#: The engine clock the board top asks its PLL for unless told otherwise (Hz): a clock the guarded
#: engine's board build meets, not the 125 MHz the engine alone is closed towards (docs/board.md). The
#: bridge counts its bit periods and timeouts in these clocks.
ENGINE_CLOCK_HZ = 100e6
#: The line rate the board top is built for unless told otherwise (bits per second). 1 Mbaud is a whole
#: number of clocks per bit at the board's engine clocks (100 at 100 MHz, 125 at 125 MHz), and the board's
#: FT231X serves it exactly (3 MHz / 3).
DEFAULT_BAUD = 1_000_000
#: An idle line for this long inside a frame ends it as truncated (:data:`TIMEOUT`). Long against a
#: USB-serial adapter's gaps between packets (about 1 ms), short against a person.
INTER_BYTE_TIMEOUT_S = 0.05

#: CRC-8 parameters (the catalogue's CRC-8/SMBUS; check value 0xF4 over b"123456789").
CRC8 = {"width": 8, "polynomial": 0x07, "initial": 0x00, "reflect_input": False, "reflect_output": False,
        "xor_output": 0x00}


def crc8(data: bytes) -> int:
    """CRC-8 (:data:`CRC8`) of ``data``, most significant bit first."""
    crc = CRC8["initial"]
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC8["polynomial"]) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ CRC8["xor_output"]


def _check(address: int, length: int) -> None:
    if not 0 <= address < 1 << (8 * ADDRESS_BYTES):
        raise ValueError(f"word address {address:#x} does not fit {ADDRESS_BYTES} bytes")
    if not 1 <= length <= MAX_WORDS:
        raise ValueError(f"a frame carries 1 to {MAX_WORDS} words, not {length}")


def _with_crc(body: bytes) -> bytes:
    return body + bytes([crc8(body)])


def encode_read(address: int, length: int) -> bytes:
    """A read request of ``length`` words from ``address``."""
    _check(address, length)
    return _with_crc(bytes([READ]) + address.to_bytes(ADDRESS_BYTES, "big") + bytes([length]))


def encode_write(address: int, words: list[int]) -> bytes:
    """A write request of ``words`` (each 0 .. 2^32 − 1) from ``address``."""
    _check(address, len(words))
    if any(not 0 <= w < 1 << (8 * WORD_BYTES) for w in words):
        raise ValueError("a data word is outside 0 .. 2^32 - 1")
    return _with_crc(bytes([WRITE]) + address.to_bytes(ADDRESS_BYTES, "big") + bytes([len(words)])
                     + b"".join(w.to_bytes(WORD_BYTES, "big") for w in words))


def request_length(command: int, length: int) -> int:
    """Bytes in a request of ``length`` words."""
    return HEADER_BYTES + (WORD_BYTES * length if command == WRITE else 0) + 1


#: An answer's status and word count, before its data and checksum.
ANSWER_HEAD_BYTES = 2


def request_words(request: bytes) -> int:
    """The word count a request asks for (its length byte)."""
    return request[HEADER_BYTES - 1]


def answer_data_bytes(request: bytes, status: int) -> int:
    """The data bytes the answer to ``request`` carries after its head, whose status is ``status``: a read's
    words where it is :data:`OK`, else none."""
    return WORD_BYTES * request_words(request) if status == OK and request[0] == READ else 0


def answer_bytes(status: int, count: int, words: list[int] = ()) -> bytes:
    """The answer the bridge sends (``words``: a read's data, with :data:`OK` only)."""
    return _with_crc(bytes([status, count]) + b"".join(w.to_bytes(WORD_BYTES, "big") for w in words))


@dataclass(frozen=True)
class Answer:
    status: int
    count: int
    words: tuple[int, ...]

    @property
    def status_name(self) -> str:
        return STATUS_NAMES.get(self.status, f"unknown status 0x{self.status:02X}")


def decode_answer(data: bytes) -> Answer:
    """Decode one whole answer (raises ``ValueError`` on a bad checksum or a malformed answer)."""
    if len(data) < 3:
        raise ValueError(f"an answer has at least 3 bytes, got {len(data)}")
    if crc8(data[:-1]) != data[-1]:
        raise ValueError(f"the answer's checksum is 0x{data[-1]:02X}, expected 0x{crc8(data[:-1]):02X}")
    status, count, body = data[0], data[1], data[2:-1]
    if len(body) % WORD_BYTES:
        raise ValueError(f"an answer's data is whole words, got {len(body)} bytes")
    words = tuple(int.from_bytes(body[i:i + WORD_BYTES], "big") for i in range(0, len(body), WORD_BYTES))
    return Answer(status, count, words)


class ReferenceTarget:
    """What the bridge does with the bytes it receives, in Python: the reference its RTL is tested against.

    ``read(address)`` and ``write(address, value)`` are the bus (raising any exception for ``err``);
    ``addr_width`` is the bus's word-address width. :meth:`serve` takes the bytes that arrive before the
    line goes idle for the inter-byte timeout and returns the bridge's answer to them.
    """

    def __init__(self, read: Callable[[int], int], write: Callable[[int, int], None], addr_width: int):
        self.read, self.write, self.addr_width = read, write, addr_width

    def serve(self, burst: bytes) -> bytes:
        if not burst:
            return b""
        command = burst[0]
        if command not in COMMANDS:
            return answer_bytes(BAD_COMMAND, 0)
        if len(burst) < HEADER_BYTES:
            return answer_bytes(TIMEOUT, 0)
        length = burst[HEADER_BYTES - 1]
        if not 1 <= length <= MAX_WORDS:
            return answer_bytes(BAD_LENGTH, 0)
        size = request_length(command, length)
        if len(burst) < size:
            return answer_bytes(TIMEOUT, 0)
        frame = burst[:size]  # bytes after a whole frame arrive while the bridge works: dropped
        if crc8(frame[:-1]) != frame[-1]:
            return answer_bytes(BAD_CHECKSUM, 0)
        address = int.from_bytes(frame[1:1 + ADDRESS_BYTES], "big")
        if address + length > 1 << self.addr_width:
            return answer_bytes(BAD_ADDRESS, 0)
        data = [int.from_bytes(frame[HEADER_BYTES + WORD_BYTES * k:HEADER_BYTES + WORD_BYTES * (k + 1)], "big")
                for k in range(length)] if command == WRITE else []
        words = []
        for k in range(length):
            try:
                if command == WRITE:
                    self.write(address + k, data[k])
                else:
                    words.append(self.read(address + k))
            except Exception:
                return answer_bytes(BUS_ERROR, k)
        return answer_bytes(OK, length, words)
