"""The UART-to-Wishbone bridge (hdl.uart_bridge) in Amaranth's simulator, against the frame format's Python
reference (golden_model.engine_spec.uart_protocol.ReferenceTarget): answers byte for byte and the bus accesses
access for access, with gaps on the byte stream in, back-pressure on the answer stream, and bus wait
states; and the serial line, bit by bit."""

import gc
import random
import warnings

import pytest
from amaranth.lib import crc
from amaranth.hdl import UnusedElaboratable
from amaranth.sim import Simulator

from golden_model.engine_spec import uart_protocol as protocol
from hdl.uart_bridge import FrameBridge, UartBridge, UartRx, UartTx, timeout_clocks, uart_divisor

ADDR_WIDTH = 12
TIMEOUT = 40
ERR_ADDRESSES = {0x013, 0x2A0}


# ------------------------------------------------------------------------------------------- the format
def test_crc8_is_the_catalogues_crc8_smbus():
    """The check value of the catalogue (0xF4 over b"123456789") and Amaranth's own CRC-8/SMBUS."""
    assert protocol.crc8(b"123456789") == 0xF4
    rng = random.Random(1)
    smbus = crc.catalog.CRC8_SMBUS(data_width=8)
    for n in (0, 1, 7, 300):
        data = bytes(rng.getrandbits(8) for _ in range(n))
        assert protocol.crc8(data) == smbus.compute(data)


def test_encode_and_decode():
    frame = protocol.encode_write(0x01020304, [0xDEADBEEF])
    assert frame[:6] == bytes([0x57, 1, 2, 3, 4, 1]) and frame[6:10] == bytes([0xDE, 0xAD, 0xBE, 0xEF])
    assert len(frame) == protocol.request_length(protocol.WRITE, 1) == 11
    assert protocol.crc8(frame) == 0  # the CRC-8 of a frame with its CRC is the residue, 0
    answer = protocol.answer_bytes(protocol.OK, 2, [1, 0xFFFFFFFF])
    assert protocol.decode_answer(answer) == protocol.Answer(protocol.OK, 2, (1, 0xFFFFFFFF))
    with pytest.raises(ValueError, match="checksum"):
        protocol.decode_answer(answer[:-1] + bytes([answer[-1] ^ 1]))
    with pytest.raises(ValueError, match="1 to 64 words"):
        protocol.encode_read(0, protocol.MAX_WORDS + 1)


def _test_parameters_are_checked_body():
    with pytest.raises(ValueError, match="divisor must be an int >= 4"):
        UartRx(3)
    with pytest.raises(ValueError, match="divisor"):
        UartTx(2.5)
    with pytest.raises(ValueError, match="addr_width must be at most 32"):
        FrameBridge(addr_width=33, timeout=10)
    with pytest.raises(ValueError, match="max_words must be at most 64"):
        FrameBridge(addr_width=8, timeout=10, max_words=65)
    with pytest.raises(ValueError, match="timeout"):
        FrameBridge(addr_width=8, timeout=0)
    assert uart_divisor(125e6, 1_000_000) == 125 and uart_divisor(125e6, 115200) == 1085
    with pytest.raises(ValueError, match="off"):
        uart_divisor(25e6, 3_000_000)  # 8.33 clocks per bit: 8 is 4 % fast
    assert timeout_clocks(125e6) == 6_250_000


# ------------------------------------------------------------------------------------------- frames
class BusModel:
    """A Wishbone target in Python: a word memory, ``err`` at ERR_ADDRESSES; logs every access."""

    def __init__(self, memory: dict):
        self.memory, self.log = dict(memory), []

    def read(self, address):
        self.log.append(("r", address))
        if address in ERR_ADDRESSES:
            raise RuntimeError("err")
        return self.memory.get(address, address * 0x01010101 & 0xFFFFFFFF)

    def write(self, address, value):
        self.log.append(("w", address, value))
        if address in ERR_ADDRESSES:
            raise RuntimeError("err")
        self.memory[address] = value


def scenarios(rng: random.Random) -> list[tuple[str, bytes]]:
    """(name, the bytes sent before the line idles)."""
    top = 1 << ADDR_WIDTH

    def words(n):
        return [rng.getrandbits(32) for _ in range(n)]

    good = [("write", protocol.encode_write(0x100, words(3))), ("read", protocol.encode_read(0x100, 3)),
            ("write-max", protocol.encode_write(0x200, words(protocol.MAX_WORDS))),
            ("read-max", protocol.encode_read(0x200, protocol.MAX_WORDS)),
            ("read-unwritten", protocol.encode_read(0x7F0, 2)),
            ("write-last-word", protocol.encode_write(top - 1, [0x12345678])),
            ("read-last-word", protocol.encode_read(top - 1, 1))]
    frame = protocol.encode_write(0x300, words(2))
    bad = [("bad-checksum-write", frame[:-1] + bytes([frame[-1] ^ 0x10])),
           ("bad-checksum-read", protocol.encode_read(0x300, 1)[:-1] + b"\x00"),
           ("payload-bit-flip", frame[:8] + bytes([frame[8] ^ 1]) + frame[9:]),
           ("length-zero", bytes([protocol.WRITE, 0, 0, 3, 0, 0]) + bytes([protocol.crc8(b"")])),
           ("length-overlong", _raw(protocol.WRITE, 0x300, protocol.MAX_WORDS + 1, words(protocol.MAX_WORDS + 1))),
           ("length-255-read", _raw(protocol.READ, 0x300, 255, [])),
           ("bad-command", bytes([0x41]) + protocol.encode_write(0x300, [7])),  # a good frame behind it: drained
           ("truncated-header", frame[:3]),
           ("truncated-data", frame[:9]),
           ("truncated-before-crc", frame[:-1]),
           ("past-the-end", protocol.encode_write(top - 1, [1, 2])),
           ("past-the-end-read", protocol.encode_read(top - 2, 3)),
           ("bus-err-write", protocol.encode_write(0x010, words(5))),  # 0x013 answers err: 3 words written
           ("bus-err-read", protocol.encode_read(0x29F, 4))]
    more = [(f"random-{k}", protocol.encode_write(a, words(n)) if rng.random() < 0.5 else protocol.encode_read(a, n))
            for k, (a, n) in enumerate((rng.randrange(0x400), rng.randint(1, 9)) for _ in range(6))]
    items = good + bad + more
    rng.shuffle(items)
    return good[:2] + items + [("read-after-all", protocol.encode_read(0x100, 3))]


def _raw(command, address, length, data):
    body = (bytes([command]) + address.to_bytes(4, "big") + bytes([length])
            + b"".join(w.to_bytes(4, "big") for w in data))
    return body + bytes([protocol.crc8(body)])


def run_frames(seed: int, gap: int, p_ready: float, wait: int):
    rng = random.Random(seed)
    items = scenarios(rng)
    initial = {a: rng.getrandbits(32) for a in range(0x100, 0x140)}
    reference = BusModel(initial)
    target = ReferenceTargetFor(reference)
    expected = [target.serve(burst) for _, burst in items]
    dut = FrameBridge(addr_width=ADDR_WIDTH, timeout=TIMEOUT)
    hardware = BusModel(initial)
    got: list[bytes] = []

    async def bus_target(ctx):
        bus = dut.bus
        while True:
            await ctx.tick()
            if not (ctx.get(bus.cyc) and ctx.get(bus.stb)):
                continue
            for _ in range(rng.randint(0, wait)):
                await ctx.tick()
            address, write = ctx.get(bus.adr), ctx.get(bus.we)
            assert ctx.get(bus.sel) == 0b1111
            try:
                if write:
                    hardware.write(address, ctx.get(bus.dat_w))
                else:
                    ctx.set(bus.dat_r, hardware.read(address))
                ctx.set(bus.ack, 1)
            except RuntimeError:
                ctx.set(bus.err, 1)
            await ctx.tick()
            ctx.set(bus.ack, 0)
            ctx.set(bus.err, 0)
            assert not ctx.get(bus.stb), "a new cycle right after an answer: the bridge idles a clock"

    async def host(ctx):
        rx, tx = dut.rx, dut.tx
        for (name, burst), want in zip(items, expected):
            for b in burst:
                for _ in range(rng.randint(0, gap)):
                    ctx.set(rx.valid, 0)
                    await ctx.tick()
                ctx.set(rx.valid, 1)
                ctx.set(rx.payload, b)
                assert ctx.get(rx.ready)
                await ctx.tick()
            ctx.set(rx.valid, 0)
            answer, held, clocks = [], None, 0
            while len(answer) < len(want):
                ready = rng.random() < p_ready
                ctx.set(tx.ready, ready)
                _, _, valid, payload = await ctx.tick().sample(tx.valid, tx.payload)
                if held is not None:
                    assert valid and payload == held, f"{name}: an offered byte was withdrawn or changed"
                if valid and ready:
                    answer.append(payload)
                held = payload if valid and not ready else None
                clocks += 1
                assert clocks < 20_000, f"{name}: no answer ({bytes(answer).hex()} so far, want {want.hex()})"
            ctx.set(tx.ready, 1)
            for _ in range(3 * TIMEOUT):  # nothing more is sent
                _, _, valid = await ctx.tick().sample(tx.valid)
                assert not valid, f"{name}: a byte after the answer"
            got.append(bytes(answer))

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bus_target, background=True)
    sim.add_testbench(host)
    sim.run()
    return items, expected, got, reference.log, hardware.log


def ReferenceTargetFor(bus: BusModel):
    return protocol.ReferenceTarget(bus.read, bus.write, ADDR_WIDTH)


@pytest.mark.parametrize("seed, gap, p_ready, wait", [(1, 0, 1.0, 0), (2, 6, 0.3, 3), (3, 2, 0.7, 1)])
def test_frames_match_the_reference(seed, gap, p_ready, wait):
    """Every answer byte and every bus access equals the reference's, over good frames, every error
    answer, random frames; with stream gaps, answer back-pressure and bus wait states."""
    items, expected, got, reference_log, hardware_log = run_frames(seed, gap, p_ready, wait)
    for (name, _), want, answer in zip(items, expected, got):
        assert answer == want, f"{name}: answered {answer.hex()}, the reference {want.hex()}"
    assert hardware_log == reference_log
    statuses = {protocol.decode_answer(a).status for a in got}
    assert statuses == set(protocol.STATUS_NAMES)  # every status was exercised


def test_bad_frames_make_no_bus_access():
    """The frames answered with an error other than a bus error: the bus log has none of their accesses
    (checked independently of the reference: the log grows only with good frames)."""
    items, expected, got, _, hardware_log = run_frames(4, 1, 0.5, 1)
    accesses = 0
    for (name, burst), answer in zip(items, got):
        a = protocol.decode_answer(answer)
        if a.status in (protocol.OK, protocol.BUS_ERROR):
            accesses += a.count + (a.status == protocol.BUS_ERROR)
        else:
            assert name.startswith(("bad", "length", "truncated", "past", "payload")), name
    assert len(hardware_log) == accesses
    names = {name for name, _ in items}
    assert {"bad-checksum-write", "length-overlong", "truncated-data", "bad-command"} <= names


@pytest.mark.parametrize("timeout", [1, 2, 7, TIMEOUT])
def test_timeout_answers_come_timeout_clocks_after_the_last_byte(timeout):
    """A truncated frame (in its address field, and after its length) and a bad command: the first answer
    byte is offered ``timeout + 1`` clocks after the clock that took the last byte (the line idle for
    ``timeout`` clocks, then the clock that moves to the answer), with the status the format gives."""
    frames = {"truncated-address": (bytes([protocol.READ, 0, 0]), protocol.TIMEOUT),
              "truncated-after-length": (bytes([protocol.READ, 0, 0, 0, 0, 1]), protocol.TIMEOUT),
              "bad-command": (bytes([0x99]), protocol.BAD_COMMAND)}
    for name, (burst, status) in frames.items():
        dut = FrameBridge(addr_width=ADDR_WIDTH, timeout=timeout)
        seen = {}

        async def host(ctx):
            ctx.set(dut.tx.ready, 1)
            for b in burst:
                ctx.set(dut.rx.valid, 1)
                ctx.set(dut.rx.payload, b)
                await ctx.tick()  # the clock that takes the byte
            ctx.set(dut.rx.valid, 0)
            for clocks in range(1, timeout + 10):
                _, _, valid, payload = await ctx.tick().sample(dut.tx.valid, dut.tx.payload)
                if valid:  # offered during the clock before this edge: `clocks - 1` after the last byte's
                    seen.update(after=clocks - 1, status=payload)
                    return

        sim = Simulator(dut)
        sim.add_clock(1e-8)
        sim.add_testbench(host)
        sim.run()
        assert seen == {"after": timeout + 1, "status": status}, name


# ------------------------------------------------------------------------------------------- the line
def line_bits(byte: int, stop: int = 1) -> list[int]:
    return [0] + [(byte >> i) & 1 for i in range(8)] + [stop]


@pytest.mark.parametrize("divisor", [4, 7])
def test_uart_rx_bytes_framing_errors_and_glitches(divisor):
    rng = random.Random(divisor)
    sent = [rng.getrandbits(8) for _ in range(40)]
    dut = UartRx(divisor)
    got, framing = [], []

    async def drive(ctx):
        ctx.set(dut.rx, 1)
        await ctx.tick().repeat(5)
        for k, byte in enumerate(sent):
            if k == 10:  # a one-clock glitch: not a start bit
                ctx.set(dut.rx, 0)
                await ctx.tick()
                ctx.set(dut.rx, 1)
                await ctx.tick().repeat(2 * divisor)
            stop = 0 if k == 20 else 1  # a framing error: dropped
            for bit in line_bits(byte, stop):
                ctx.set(dut.rx, bit)
                await ctx.tick().repeat(divisor)
            ctx.set(dut.rx, 1)
            await ctx.tick().repeat(rng.randint(1, 2 * divisor) + (divisor if stop == 0 else 0))
        await ctx.tick().repeat(20 * divisor)

    async def take(ctx):
        ctx.set(dut.source.ready, 1)
        async for _, _, valid, payload, error in ctx.tick().sample(dut.source.valid, dut.source.payload,
                                                                   dut.framing_error):
            if valid:
                got.append(payload)
            if error:
                framing.append(len(got))

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(take, background=True)
    sim.add_testbench(drive)
    sim.run()
    assert got == sent[:20] + sent[21:]
    assert framing == [20]


@pytest.mark.parametrize("divisor", [4, 9])
def test_uart_tx_line(divisor):
    """Bytes with random gaps on the stream come out as 8N1 frames of exactly divisor clocks per bit."""
    rng = random.Random(divisor)
    sent = [rng.getrandbits(8) for _ in range(30)]
    dut = UartTx(divisor)
    line: list[int] = []

    async def feed(ctx):
        for byte in sent:
            for _ in range(rng.randint(0, 3) * divisor * 4 if rng.random() < 0.3 else 0):
                ctx.set(dut.sink.valid, 0)
                await ctx.tick()
            ctx.set(dut.sink.valid, 1)
            ctx.set(dut.sink.payload, byte)
            await ctx.tick().until(dut.sink.ready)
        ctx.set(dut.sink.valid, 0)
        await ctx.tick().repeat(12 * divisor)

    async def watch(ctx):
        async for _, _, tx in ctx.tick().sample(dut.tx):
            line.append(tx)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(watch, background=True)
    sim.add_testbench(feed)
    sim.run()
    assert decode_line(line, divisor) == sent


def decode_line(line: list[int], divisor: int) -> list[int]:
    """8N1 bytes from a line sampled every clock; every bit must hold for exactly ``divisor`` samples."""
    out, i = [], 0
    while i < len(line):
        if line[i] == 1:
            i += 1
            continue
        bits = [line[i + k * divisor:i + (k + 1) * divisor] for k in range(10)]
        assert all(len(set(b)) == 1 and len(b) == divisor for b in bits[:9]), f"a bit is not {divisor} clocks"
        assert bits[0][0] == 0 and bits[9] and all(bits[9]), "start or stop bit"
        out.append(sum(b[0] << k for k, b in enumerate(bits[1:9])))
        i += 10 * divisor
    return out


def test_the_whole_bridge_on_its_pins():
    """A write then a read-back over the serial pins (divisor 5), answered as the reference answers."""
    divisor, rng = 5, random.Random(9)
    dut = UartBridge(divisor=divisor, addr_width=ADDR_WIDTH, timeout=40 * divisor)
    memory = BusModel({})
    frames = [protocol.encode_write(0x40, [rng.getrandbits(32) for _ in range(4)]), protocol.encode_read(0x40, 4),
              protocol.encode_read(0x40, 1)[:-1] + b"\x00"]
    reference = ReferenceTargetFor(BusModel({}))
    expected = b"".join(reference.serve(f) for f in frames)
    line: list[int] = []

    async def bus_target(ctx):
        bus = dut.bus
        while True:
            await ctx.tick()
            if ctx.get(bus.cyc) and ctx.get(bus.stb):
                if ctx.get(bus.we):
                    memory.write(ctx.get(bus.adr), ctx.get(bus.dat_w))
                else:
                    ctx.set(bus.dat_r, memory.read(ctx.get(bus.adr)))
                ctx.set(bus.ack, 1)
                await ctx.tick()
                ctx.set(bus.ack, 0)

    async def watch(ctx):
        async for _, _, tx in ctx.tick().sample(dut.tx):
            line.append(tx)

    async def host(ctx):
        ctx.set(dut.rx, 1)
        await ctx.tick().repeat(10)
        for frame in frames:
            for byte in frame:
                for bit in line_bits(byte):
                    ctx.set(dut.rx, bit)
                    await ctx.tick().repeat(divisor)
            ctx.set(dut.rx, 1)
            await ctx.tick().repeat(250 * divisor)  # the longest answer: 19 bytes

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bus_target, background=True)
    sim.add_testbench(watch, background=True)
    sim.add_testbench(host)
    sim.run()
    assert bytes(decode_line(line, divisor)) == expected


def test_parameters_are_checked():
    """(The refused components were never elaborated: their warnings are collected here, not in a later test.)"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        _test_parameters_are_checked_body()
        gc.collect()
