"""A UART-to-Wishbone bridge: the host link of the board top (frame format: :mod:`golden_model.engine_spec.uart_protocol`).

Three blocks joined by ``lib.stream`` byte streams, and :class:`UartBridge` that composes them:

* :class:`UartRx`: the serial line to a stream of bytes;
* :class:`UartTx`: a stream of bytes to the serial line;
* :class:`FrameBridge`: the frames' parser and bus initiator: checks a frame (command, length, CRC-8,
  address range), buffers a write's data until its checksum has been checked, runs the Wishbone B4
  classic cycles (:mod:`hdl.wishbone`) and sends the answer.

The idea is LiteX's UARTBone (a command byte, a length and a word address, then the data; a timeout
that resets the parser between frames); this one adds the checksum, the status answer and the
error answers, and never touches the bus for a bad frame.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import crc, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from golden_model.engine_spec import uart_protocol as protocol

from . import wishbone
from .parameters import check_int

__all__ = ["UartRx", "UartTx", "FrameBridge", "UartBridge", "uart_divisor", "timeout_clocks"]


def uart_divisor(clock_hz: float, baud: float) -> int:
    """Clocks per bit for ``baud`` at ``clock_hz``, refused when the rate is off by more than 2 %
    (a receiver samples mid-bit; ten bits of a frame tolerate about 5 % between both ends)."""
    divisor = round(clock_hz / baud)
    if divisor < UartRx.MIN_DIVISOR:
        raise ValueError(f"{baud:g} baud at {clock_hz / 1e6:g} MHz is {clock_hz / baud:.2f} clocks per bit; "
                         f"the UART needs at least {UartRx.MIN_DIVISOR}")
    error = abs(clock_hz / divisor - baud) / baud
    if error > 0.02:
        raise ValueError(f"{baud:g} baud at {clock_hz / 1e6:g} MHz: {divisor} clocks per bit is "
                         f"{100 * error:.1f} % off (at most 2 %)")
    return divisor


def timeout_clocks(clock_hz: float, seconds: float = protocol.INTER_BYTE_TIMEOUT_S) -> int:
    """The inter-byte timeout in clocks."""
    return max(1, round(clock_hz * seconds))


class UartRx(wiring.Component):
    """The serial line (8N1, LSB first) to a stream of bytes.

    ``rx`` goes through a two-flip-flop synchroniser (the pin is asynchronous). A start bit's falling
    edge starts a bit timer; each bit is sampled in its middle (``divisor // 2`` clocks in, then every
    ``divisor``). A byte whose stop bit reads 1 is offered on ``source``; one whose stop bit reads 0
    (a framing error, or a break) is dropped, and the receiver waits for the line to go high again.

    **Latency**: a byte is offered 2 (synchroniser) + ``divisor // 2`` + 9 × ``divisor`` clocks after
    its start bit's falling edge, the middle of its stop bit. **Throughput**: one byte per 10 bit
    times, the line's rate. The receiver does not wait for ``source.ready``: a byte still offered when
    the next one completes is replaced by it and ``overrun`` pulses for a clock (the bridge is always
    ready).

    Parameters
    ----------
    divisor : int
        Clocks per bit, at least :data:`MIN_DIVISOR` (:func:`uart_divisor`).

    Members
    -------
    rx : ``In(1)``, the line (idle high).
    source : ``Out(stream.Signature(8))``
    overrun, framing_error : ``Out(1)``, one-clock pulses.
    """

    MIN_DIVISOR = 4

    def __init__(self, divisor: int):
        check_int("divisor", divisor, self.MIN_DIVISOR)
        self.divisor = divisor
        super().__init__({"rx": In(1, init=1), "source": Out(stream.Signature(8)), "overrun": Out(1),
                          "framing_error": Out(1)})

    def elaborate(self, platform):
        m = Module()
        line = Signal(init=1)
        m.submodules.sync_rx = FFSynchronizer(self.rx, line, init=1)
        timer = Signal(range(self.divisor))
        bits = Signal(range(10))
        shift = Signal(8)
        tick = timer == 0
        with m.If(~tick):
            m.d.sync += timer.eq(timer - 1)
        with m.If(self.source.ready):
            m.d.sync += self.source.valid.eq(0)
        m.d.sync += [self.overrun.eq(0), self.framing_error.eq(0)]
        with m.FSM():
            with m.State("IDLE"):
                with m.If(~line):
                    m.d.sync += [timer.eq(self.divisor // 2 - 1), bits.eq(0)]
                    m.next = "START"
            with m.State("START"):  # the start bit's middle: still low, or a glitch
                with m.If(tick):
                    with m.If(line):
                        m.next = "IDLE"
                    with m.Else():
                        m.d.sync += timer.eq(self.divisor - 1)
                        m.next = "DATA"
            with m.State("DATA"):
                with m.If(tick):
                    m.d.sync += [shift.eq(Cat(shift[1:], line)), bits.eq(bits + 1), timer.eq(self.divisor - 1)]
                    with m.If(bits == 7):
                        m.next = "STOP"
            with m.State("STOP"):
                with m.If(tick):
                    with m.If(line):
                        m.d.sync += [self.source.payload.eq(shift), self.source.valid.eq(1),
                                     self.overrun.eq(self.source.valid & ~self.source.ready)]
                        m.next = "IDLE"
                    with m.Else():
                        m.d.sync += self.framing_error.eq(1)
                        m.next = "BREAK"
            with m.State("BREAK"):  # wait for the line to return high before the next start bit
                with m.If(line):
                    m.next = "IDLE"
        return m


class UartTx(wiring.Component):
    """A stream of bytes to the serial line (8N1, LSB first).

    **Latency**: the start bit begins the clock after a byte is taken (``tx`` is a register).
    **Throughput**: one byte per 10 × ``divisor`` clocks; ``sink.ready`` is high while the line is idle
    (after the stop bit of the previous byte), so back-to-back bytes follow each other with no gap.

    Parameters
    ----------
    divisor : int
        Clocks per bit, at least :data:`UartRx.MIN_DIVISOR`.

    Members
    -------
    sink : ``In(stream.Signature(8))``
    tx : ``Out(1)``, the line (idle high).
    """

    def __init__(self, divisor: int):
        check_int("divisor", divisor, UartRx.MIN_DIVISOR)
        self.divisor = divisor
        super().__init__({"sink": In(stream.Signature(8)), "tx": Out(1, init=1)})

    def elaborate(self, platform):
        m = Module()
        timer = Signal(range(self.divisor))
        shift = Signal(10, init=0x3FF)  # start, 8 data bits, stop; shifted out LSB first
        left = Signal(range(11))  # bits still to send
        m.d.comb += [self.sink.ready.eq(left == 0), self.tx.eq(shift[0])]
        with m.If(self.sink.valid & self.sink.ready):
            m.d.sync += [shift.eq(Cat(Const(0, 1), self.sink.payload, Const(1, 1))), left.eq(10),
                         timer.eq(self.divisor - 1)]
        with m.Elif(left != 0):
            with m.If(timer == 0):
                m.d.sync += [shift.eq(Cat(shift[1:], Const(1, 1))), left.eq(left - 1), timer.eq(self.divisor - 1)]
            with m.Else():
                m.d.sync += timer.eq(timer - 1)
        return m


class FrameBridge(wiring.Component):
    """The frames' parser and Wishbone initiator (frame format: :mod:`golden_model.engine_spec.uart_protocol`).

    Takes a frame byte by byte from ``rx`` (always ready: bytes arriving while the bridge executes or
    answers are dropped), feeds every byte to a CRC-8 (:class:`amaranth.lib.crc.Processor`; the frame
    is good when the register holds the residue after its last byte), writes a write's data words into
    a ``max_words``-deep buffer (distributed RAM), and only after the checksum and the address range
    have been checked runs the bus cycles, one word at a time, the address incrementing; a read's
    words go into the same buffer. Then it sends the answer on ``tx``.

    **Latency**: the first bus cycle starts 3 clocks after the CRC byte is taken; each word takes the
    target's answer time plus 2 clocks (the cycle's outputs are flip-flops, loaded in an idle clock before
    each cycle, so the route to a distant target starts at a register); the answer's first byte is offered
    the clock after the last access (after the CRC byte, for an answer without access). A bad command or length
    is answered once the line has been idle for ``timeout`` clocks after the last byte of the frame (the
    bridge drains the line first), a truncated frame once it has been after its last byte: the answer's first
    byte is offered ``timeout + 1`` clocks after the clock that took the last byte. **Throughput**: one frame
    at a time; the line's byte rate bounds it.

    Parameters
    ----------
    addr_width : int
        The bus's word-address width (1 .. 32); a frame reaching past ``2**addr_width`` is answered
        ``BAD_ADDRESS``.
    timeout : int
        The inter-byte timeout in clocks (:func:`timeout_clocks`).
    max_words : int
        The buffer's depth, :data:`~golden_model.engine_spec.uart_protocol.MAX_WORDS` (a smaller bridge
        answers longer frames ``BAD_LENGTH``).

    Members
    -------
    rx : ``In(stream.Signature(8))``; tx : ``Out(stream.Signature(8))``
    bus : ``Out(wishbone.Signature(addr_width))``, the initiator.
    error : ``Out(1)``, high from an error answer until the next ``OK`` answer.
    busy : ``Out(1)``, high from a frame's first byte until its answer's last byte is taken.
    """

    def __init__(self, *, addr_width: int, timeout: int, max_words: int = protocol.MAX_WORDS):
        check_int("addr_width", addr_width)
        if addr_width > 8 * protocol.ADDRESS_BYTES:
            raise ValueError(f"addr_width must be at most {8 * protocol.ADDRESS_BYTES}, not {addr_width}")
        check_int("timeout", timeout)
        check_int("max_words", max_words)
        if max_words > protocol.MAX_WORDS:
            raise ValueError(f"max_words must be at most {protocol.MAX_WORDS} (the frame format's), not {max_words}")
        self.addr_width, self.timeout, self.max_words = addr_width, timeout, max_words
        super().__init__({"rx": In(stream.Signature(8)), "tx": Out(stream.Signature(8)),
                          "bus": Out(wishbone.Signature(addr_width=addr_width)), "error": Out(1), "busy": Out(1)})

    def elaborate(self, platform):
        m = Module()
        rx, tx, bus = self.rx, self.tx, self.bus
        params = crc.Algorithm(crc_width=protocol.CRC8["width"], polynomial=protocol.CRC8["polynomial"],
                               initial_crc=protocol.CRC8["initial"], reflect_input=protocol.CRC8["reflect_input"],
                               reflect_output=protocol.CRC8["reflect_output"],
                               xor_output=protocol.CRC8["xor_output"])(data_width=8)
        m.submodules.crc_rx = crc_rx = params.create()
        m.submodules.crc_tx = crc_tx = params.create()
        word_bits = 8 * protocol.WORD_BYTES
        m.submodules.buffer = buffer = Memory(shape=word_bits, depth=self.max_words, init=[],
                                              attrs={"ram_style": "distributed"})
        wr = buffer.write_port()
        rd = buffer.read_port(domain="comb")

        command = Signal(8)
        address = Signal(8 * protocol.ADDRESS_BYTES)
        length = Signal(8)
        word = Signal(word_bits)
        index = Signal(range(self.max_words + 1))  # words received, accessed or sent
        byte = Signal(range(max(protocol.ADDRESS_BYTES, protocol.WORD_BYTES)))  # byte within a field
        status = Signal(8)
        count = Signal(8)
        bus_address = Signal(self.addr_width)

        # the inter-byte timer: restarts at every byte; `idle` once `timeout` clocks passed without one
        # (`idle` is a flip-flop holding `timer == timeout`, set from the clock before's compare with
        # `timeout - 1`: the timer's wide compare stays off the FSM's next-state logic)
        timer = Signal(range(self.timeout + 1))
        idle = Signal(name="idle")
        m.d.comb += [rx.ready.eq(1), bus.sel.eq(~0)]
        took = rx.valid
        with m.If(took):
            m.d.sync += [timer.eq(0), idle.eq(0)]
        with m.Elif(~idle):
            m.d.sync += [timer.eq(timer + 1), idle.eq(timer == self.timeout - 1)]

        m.d.comb += [crc_rx.data.eq(rx.payload), crc_tx.data.eq(tx.payload),
                     crc_tx.valid.eq(tx.valid & tx.ready), wr.addr.eq(index), rd.addr.eq(index)]
        is_write = command == protocol.WRITE
        # whether `index` is the frame's last word, a flip-flop: `length - 1` and the compare with `index`
        # each in a register of their own, not a carry chain into the FSM's next state. Every state that
        # reads it (DATA, BUS, WORDS) comes at least two clocks after `length` or `index` last moved: DATA
        # takes four bytes per word, GAP precedes every BUS, LOAD every WORDS. WORDS runs only after an OK
        # answer, whose count is the length.
        length_less = Signal(8, name="length_less")
        last_word = Signal(name="last_word")
        m.d.sync += [length_less.eq(length - 1), last_word.eq(index == length_less)]
        # whether the frame reaches past the bus's last word: the 33-bit sum, then its compare, each in a
        # register of its own (not one carry chain of both in VERIFY); address
        # and length hold still from the length byte on, and SETTLE gives the two a clock when bytes
        # come back to back
        # the word being sent, from the buffer's read a clock before (LOAD), so that the buffer's read, the
        # byte select and the transmit CRC are not one clock's logic
        sent_word = Signal(word_bits, name="sent_word")
        m.d.sync += sent_word.eq(rd.data)
        end = Signal(8 * protocol.ADDRESS_BYTES + 1, name="frame_end")
        past_end = Signal(name="past_end")
        m.d.sync += [end.eq(address + length), past_end.eq(end > (1 << self.addr_width))]
        # the checksum's test, a flip-flop too (the CRC register's compare with the residue, into VERIFY's
        # logic, was a long path): the CRC register holds still from the CRC byte on, a clock before SETTLE
        crc_good = Signal(name="crc_good")
        m.d.sync += crc_good.eq(crc_rx.match_detected)

        def answer(code):
            m.d.sync += [status.eq(code), count.eq(0)]
            m.next = "STATUS"

        with m.FSM() as fsm:
            with m.State("COMMAND"):
                m.d.comb += [crc_rx.start.eq(1), crc_rx.valid.eq(took)]
                with m.If(took):
                    m.d.sync += [command.eq(rx.payload), byte.eq(0), index.eq(0)]
                    with m.If((rx.payload == protocol.READ) | (rx.payload == protocol.WRITE)):
                        m.next = "ADDRESS"
                    with m.Else():
                        m.d.sync += status.eq(protocol.BAD_COMMAND)
                        m.next = "DRAIN"
            with m.State("ADDRESS"):
                m.d.comb += crc_rx.valid.eq(took)
                with m.If(took):
                    m.d.sync += [address.eq(Cat(rx.payload, address[:-8])), byte.eq(byte + 1)]
                    with m.If(byte == protocol.ADDRESS_BYTES - 1):
                        m.next = "LENGTH"
                with m.Elif(idle):
                    answer(protocol.TIMEOUT)
            with m.State("LENGTH"):
                m.d.comb += crc_rx.valid.eq(took)
                with m.If(took):
                    m.d.sync += [length.eq(rx.payload), byte.eq(0)]
                    with m.If((rx.payload == 0) | (rx.payload > self.max_words)):
                        m.d.sync += status.eq(protocol.BAD_LENGTH)
                        m.next = "DRAIN"
                    with m.Elif(is_write):
                        m.next = "DATA"
                    with m.Else():
                        m.next = "CHECKSUM"
                with m.Elif(idle):
                    answer(protocol.TIMEOUT)
            with m.State("DATA"):  # big-endian words into the buffer
                m.d.comb += [crc_rx.valid.eq(took), wr.data.eq(Cat(rx.payload, word[:-8])),
                             wr.en.eq(took & (byte == protocol.WORD_BYTES - 1))]
                with m.If(took):
                    m.d.sync += [word.eq(Cat(rx.payload, word[:-8])), byte.eq(byte + 1)]
                    with m.If(byte == protocol.WORD_BYTES - 1):
                        m.d.sync += [index.eq(index + 1), byte.eq(0)]
                        with m.If(last_word):
                            m.next = "CHECKSUM"
                with m.Elif(idle):
                    answer(protocol.TIMEOUT)
            with m.State("CHECKSUM"):
                m.d.comb += crc_rx.valid.eq(took)
                with m.If(took):
                    m.next = "SETTLE"
                with m.Elif(idle):
                    answer(protocol.TIMEOUT)
            with m.State("SETTLE"):  # past_end's second register, crc_good's
                m.next = "VERIFY"
            with m.State("VERIFY"):  # the CRC register has taken the CRC byte
                with m.If(~crc_good):
                    answer(protocol.BAD_CHECKSUM)
                with m.Elif(past_end):
                    answer(protocol.BAD_ADDRESS)
                with m.Else():
                    m.d.sync += [index.eq(0), bus_address.eq(address[:self.addr_width])]
                    m.next = "GAP"
            with m.State("DRAIN"):  # a frame whose end cannot be known: drop bytes until the line idles
                with m.If(idle & ~took):
                    m.d.sync += count.eq(0)
                    m.next = "STATUS"
            with m.State("GAP"):  # stb low for a clock before each cycle; the cycle's outputs are registered here
                m.d.sync += [bus.cyc.eq(1), bus.stb.eq(1), bus.we.eq(is_write), bus.adr.eq(bus_address),
                             bus.dat_w.eq(rd.data)]
                m.next = "BUS"
            with m.State("BUS"):  # one classic cycle per word, its outputs from flip-flops
                m.d.comb += [wr.data.eq(bus.dat_r), wr.en.eq(bus.ack & ~is_write)]
                with m.If(bus.ack | bus.err):
                    m.d.sync += [bus.cyc.eq(0), bus.stb.eq(0)]
                with m.If(bus.err):
                    m.d.sync += [status.eq(protocol.BUS_ERROR), count.eq(index)]
                    m.next = "STATUS"
                with m.Elif(bus.ack):
                    m.d.sync += [index.eq(index + 1), bus_address.eq(bus_address + 1)]
                    with m.If(last_word):
                        m.d.sync += [status.eq(protocol.OK), count.eq(length), index.eq(0)]
                        m.next = "STATUS"
                    with m.Else():
                        m.next = "GAP"
            with m.State("STATUS"):
                m.d.comb += [tx.valid.eq(1), tx.payload.eq(status), crc_tx.start.eq(1)]
                with m.If(tx.ready):
                    m.next = "COUNT"
            with m.State("COUNT"):
                m.d.comb += [tx.valid.eq(1), tx.payload.eq(count)]
                with m.If(tx.ready):
                    m.d.sync += [index.eq(0), byte.eq(0)]
                    with m.If((status == protocol.OK) & ~is_write):
                        m.next = "LOAD"
                    with m.Else():
                        m.next = "CRC"
            with m.State("LOAD"):  # the word at `index` into `sent_word`
                m.next = "WORDS"
            with m.State("WORDS"):  # the read's words from the buffer, big-endian
                m.d.comb += [tx.valid.eq(1),
                             tx.payload.eq(sent_word.word_select(~byte, 8))]  # ~byte = 3 - byte: 2 bits
                with m.If(tx.ready):
                    m.d.sync += byte.eq(byte + 1)
                    with m.If(byte == protocol.WORD_BYTES - 1):
                        m.d.sync += [byte.eq(0), index.eq(index + 1)]
                        with m.If(last_word):
                            m.next = "CRC"
                        with m.Else():
                            m.next = "LOAD"
            with m.State("CRC"):
                m.d.comb += [tx.valid.eq(1), tx.payload.eq(crc_tx.crc)]
                with m.If(tx.ready):
                    m.d.sync += self.error.eq(status != protocol.OK)
                    m.next = "COMMAND"
        m.d.comb += self.busy.eq(~fsm.ongoing("COMMAND"))
        return m


class UartBridge(wiring.Component):
    """:class:`UartRx` → :class:`FrameBridge` → :class:`UartTx`: the serial pins to a Wishbone initiator.

    Latency and throughput: the blocks', and a register between the receiver and the frame bridge (a byte
    reaches the frame bridge a clock after the receiver offers it); the line's byte rate bounds everything.

    Parameters
    ----------
    divisor : int
        Clocks per bit (:func:`uart_divisor`).
    addr_width, timeout, max_words :
        :class:`FrameBridge`'s.

    Members
    -------
    rx : ``In(1)``; tx : ``Out(1)``, the line.
    bus : ``Out(wishbone.Signature(addr_width))``
    error : ``Out(1)``, :class:`FrameBridge`'s; rx_byte, tx_byte : ``Out(1)``, a pulse per byte received or sent
        (registered: a clock after the byte).
    """

    def __init__(self, *, divisor: int, addr_width: int, timeout: int, max_words: int = protocol.MAX_WORDS):
        self.receiver = UartRx(divisor)
        self.transmitter = UartTx(divisor)
        self.frames = FrameBridge(addr_width=addr_width, timeout=timeout, max_words=max_words)
        super().__init__({"rx": In(1, init=1), "tx": Out(1, init=1),
                          "bus": Out(wishbone.Signature(addr_width=addr_width)), "error": Out(1),
                          "rx_byte": Out(1), "tx_byte": Out(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.receiver = rx = self.receiver
        m.submodules.transmitter = tx = self.transmitter
        m.submodules.frames = frames = self.frames
        # the receiver's byte into a register beside the frame bridge (the frame bridge is always ready):
        # the receiver sits by the pin, and its valid flag into the frame bridge's next-state and status
        # logic from there is a long path
        byte_valid, byte = Signal(name="rx_byte_valid"), Signal(8, name="rx_byte_q", reset_less=True)
        m.d.sync += [byte_valid.eq(rx.source.valid), byte.eq(rx.source.payload)]
        m.d.comb += [rx.source.ready.eq(1), frames.rx.valid.eq(byte_valid), frames.rx.payload.eq(byte)]
        wiring.connect(m, frames.tx, tx.sink)
        wiring.connect(m, wiring.flipped(self.bus), frames.bus)
        m.d.comb += [rx.rx.eq(self.rx), self.tx.eq(tx.tx), self.error.eq(frames.error)]
        # registered: they go to the LEDs, across the device
        m.d.sync += [self.rx_byte.eq(rx.source.valid & rx.source.ready),
                     self.tx_byte.eq(tx.sink.valid & tx.sink.ready)]
        return m
