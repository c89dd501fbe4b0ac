"""The host transport (sim/uart_bus.py) and ``flatten --engine board`` against the bridge's Python reference
(``uart_protocol.ReferenceTarget``) with the engine's Python model (``ModelBus``) behind it; the CLI through
pyserial to a socket server that serves frames."""

import socket
import subprocess
import threading

import numpy as np
import pytest

from golden_model.fixed import FormatSet
from golden_model.engine_spec import uart_protocol as protocol
from golden_model.fixed.engine import flatten_fixed, prepare
from golden_model.engine_spec.image import UNGUARDED
from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity, build_image
from golden_model.engine_spec.register_map import MAGIC, RegisterMap
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from sim.board_run import board_capacity, board_engine, run_on_board
from sim.engine_driver import BusError, DriverError, EngineDriver, ModelBus
from sim.uart_bus import LinkError, UartBus, open_port
from support import SPRINGFLAT

DEFAULT = FormatSet.preset("default")


class ModelPort:
    """A byte stream whose other end is the bridge's reference with ``ModelBus`` behind it; ``mangle`` may
    change each answer (a corrupt link), ``mute`` answers nothing (a link that times out)."""

    def __init__(self, bus, addr_width: int, mangle=None, mute: bool = False):
        self.log: list = []
        self.bus = bus

        def read(a):
            self.log.append(("r", a))
            return bus.read(a)

        def write(a, v):
            self.log.append(("w", a, v))
            bus.write(a, v)

        self.target = protocol.ReferenceTarget(read, write, addr_width)
        self.mangle, self.mute, self.out, self.requests = mangle, mute, b"", []

    def write(self, data: bytes) -> None:
        self.requests.append(bytes(data))
        answer = self.target.serve(bytes(data))
        self.out += b"" if self.mute else (self.mangle(answer) if self.mangle else answer)

    def read(self, n: int) -> bytes:
        data, self.out = self.out[:n], self.out[n:]
        return data


def addr_width(rmap: RegisterMap) -> int:
    return (max(w.base + w.size for w in rmap.windows) - 1).bit_length()


CAPACITY = EngineCapacity(64, 512, 128)
MAP = RegisterMap.build(DEFAULT, CAPACITY)
MESH = dome_grid(6)
PARAMS = FlattenParams(dynamics="momentum", **UNGUARDED, barrier=True, max_iter=12)


def test_a_run_over_frames_is_the_golden_models():
    """run_on_board through UartBus frames (batched while loading) equals flatten_fixed bit for bit; the
    board's capacity is read from its CAP_* registers."""
    port = ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP))
    bus = UartBus(port)
    problem = prepare(MESH, initial_layout(MESH, "tutte"), PARAMS, DEFAULT)
    run = run_on_board(problem, bus)
    assert run.mismatches == [] and run.capacity == CAPACITY
    reference = flatten_fixed(MESH, initial_layout(MESH, "tutte"), PARAMS, DEFAULT)
    np.testing.assert_array_equal(run.readback.positions, reference.engine_state.raw_positions)
    assert (run.readback.result, run.readback.iterations) == (reference.status, reference.iterations)
    image = build_image(problem, CAPACITY)
    words = sum(a.size for a in (image.nodes, image.entries, image.triangles))
    writes = [r for r in port.requests if r[0] == protocol.WRITE]
    assert sum(r[5] for r in writes) >= words
    # batched: a run of addresses is one frame up to a window's stride hole (this map's node: 5 words of a stride of 8)
    assert len(writes) < words / 3
    node_words = MAP.window("nodes").words  # the read-back: a node's words in one frame
    reads_of_a_node = [r for r in port.requests if r[0] == protocol.READ and r[protocol.HEADER_BYTES - 1] == node_words]
    assert len(reads_of_a_node) == MESH.n_vertices


def _problem():
    return prepare(MESH, initial_layout(MESH, "tutte"), PARAMS, DEFAULT)


def test_a_run_cut_off_leaves_the_engine_idle_and_one_found_running_is_aborted_first():
    """The host owns the engine: an interrupted wait (the command's Ctrl-C, SIGTERM) aborts the run before the
    exception goes on, so the next run can load; one found running (a killed process, a lost link) is aborted
    first and said so. The run after each is the golden model's, bit for bit."""
    engine = ModelBus(MAP, DEFAULT, run_polls=1_000_000)
    bus = UartBus(ModelPort(engine, addr_width(MAP)))
    polls = []

    def interrupted_after_three():
        polls.append(1)
        if len(polls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_on_board(_problem(), bus, poll=interrupted_after_three)
    assert EngineDriver(bus, MAP).state() == "idle"
    reference = flatten_fixed(MESH, initial_layout(MESH, "tutte"), PARAMS, DEFAULT)
    engine.run_polls = 2
    run = run_on_board(_problem(), bus)
    assert not run.aborted_earlier_run and run.mismatches == []
    driver = EngineDriver(bus, MAP)  # a run left going, as by a process killed while it waited
    engine.run_polls = 1_000_000
    driver.start()
    assert driver.state() == "running"
    engine.run_polls = 2
    run = run_on_board(_problem(), bus)
    assert run.aborted_earlier_run and run.mismatches == []
    np.testing.assert_array_equal(run.readback.positions, reference.engine_state.raw_positions)


def test_a_run_whose_iterations_stop_moving_is_given_up_and_aborted():
    """A wall-clock watch on ITERATIONS (a hung engine, or a board that answers STATUS and nothing else): one
    line naming the time and the count, and the engine aborted, not left running."""
    engine = ModelBus(MAP, DEFAULT, run_polls=10**12)  # a model run never counts: ITERATIONS stays 0
    bus = UartBus(ModelPort(engine, addr_width(MAP)))
    with pytest.raises(DriverError, match=r"^the engine made no progress for 0\.2 s: ITERATIONS stays at 0$"):
        run_on_board(_problem(), bus, stall_seconds=0.2)
    assert EngineDriver(bus, MAP).state() == "idle"


def test_the_capacity_registers_do_not_move_with_the_capacity():
    """board_capacity reads CAP_* at the addresses of DEFAULT_CAPACITY's map: they must be the same for every
    capacity."""
    for capacity in (CAPACITY, DEFAULT_CAPACITY, EngineCapacity(16384, 131072, 32768)):
        rmap = RegisterMap.build(DEFAULT, capacity)
        assert [rmap.register(f"CAP_{w}").offset for w in ("VERTICES", "ENTRIES", "TRIANGLES")] == [
            RegisterMap.build(DEFAULT, DEFAULT_CAPACITY).register(f"CAP_{w}").offset
            for w in ("VERTICES", "ENTRIES", "TRIANGLES")]
    bus = UartBus(ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP)))
    assert board_capacity(bus, DEFAULT) == CAPACITY


class SameWord:
    """A bus whose every read answers ``word``: something that speaks the frames but is no engine."""

    def __init__(self, word: int):
        self.word = word

    def read(self, address: int) -> int:
        return self.word

    def write(self, address: int, value: int) -> None:
        pass


@pytest.mark.parametrize("word", [0, 0xFFFF_FFFF])
def test_a_bus_that_holds_no_engine_is_named_before_its_capacity_is_trusted(word):
    """The ID is checked before the CAP_* registers are read: their zeros (or ones) made a ValueError of
    EngineCapacity, or a register map past the 32-bit address space, each a traceback from the command."""
    with pytest.raises(DriverError, match=rf"^no springflat engine on this bus: ID reads 0x{word:08X}, expected "):
        board_capacity(SameWord(word), DEFAULT)
    engine = ModelBus(MAP, DEFAULT)
    cap_vertices = MAP.register("CAP_VERTICES").offset
    engine_with_no_vertices = SameWord(0)
    engine_with_no_vertices.read = lambda a: 0 if a == cap_vertices else engine.read(a)
    with pytest.raises(DriverError, match=r"^the engine reports a capacity it cannot have \(EngineCapacity: vertices "):
        board_capacity(engine_with_no_vertices, DEFAULT)
    engine_with_every_vertex = SameWord(0)  # a count no address map holds: refused as the map is built
    engine_with_every_vertex.read = lambda a: 0xFFFF_FFFF if a == cap_vertices else engine.read(a)
    with pytest.raises(DriverError, match=r"^the engine reports a capacity it cannot have \(register map: .* do not "
                                          r"fit a 32-bit byte address\)$"):
        board_capacity(engine_with_every_vertex, DEFAULT)


@pytest.mark.slow  # a CLI run
def test_flatten_engine_board_on_a_link_to_no_engine_is_one_line(tmp_path):
    server = FrameServer(DEFAULT_CAPACITY)
    server.target = protocol.ReferenceTarget(lambda a: 0, server.bus.write, addr_width(MAP))
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "board", "--port",
                           f"socket://127.0.0.1:{server.port}", "--out", "out.obj"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.splitlines()[-1] == ("springflat: error: no springflat engine on this bus: ID reads 0x00000000, "
                                            f"expected 0x{MAGIC:08X}")
    assert not (tmp_path / "out.obj").exists()


def test_error_answers_and_timeouts_are_one_line():
    port = ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP))
    bus = UartBus(port)
    unmapped = next(a for a in range(1 << 12) if MAP.decode(a) is None)
    with pytest.raises(BusError, match=rf"^bus error: read at word address {unmapped:#x} answered err$"):
        bus.read(unmapped)
    with pytest.raises(BusError, match=r"^bus error: write at word address 0x0 answered err$"):
        bus.write(0, 1)  # ID is read-only
    with pytest.raises(BusError, match="refused a read of 2 word.* bad address$"):
        bus.read_words((1 << addr_width(MAP)) - 1, 2)
    with bus.batched():  # a write's error inside a batch is raised by the call that sends it
        bus.write(MAP.register("MAX_ITER").offset, 5)
        bus.write(0x7, 1)  # not consecutive: flushes MAX_ITER's; 0x7 is unmapped
        with pytest.raises(BusError, match="write at word address 0x7 answered err"):
            bus.read(0)
    assert bus.read(MAP.register("MAX_ITER").offset) == 5
    corrupt = UartBus(ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP), mangle=lambda a: a[:-1] + bytes([a[-1] ^ 1])))
    with pytest.raises(LinkError, match="^corrupt answer from the link to a read at 0x0: the answer's checksum"):
        corrupt.read(0)
    mute = UartBus(ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP), mute=True), name="the board on COM9")
    with pytest.raises(LinkError) as info:
        mute.read(0)
    assert str(info.value).startswith("no answer from the board on COM9 to a read at 0x0 (nothing before the timeout)")
    assert "\n" not in str(info.value)
    class Pulled(ModelPort):  # a USB-UART pulled out mid-run: pyserial raises SerialException, an OSError
        def read(self, n):
            raise OSError("device reports readiness to read but returned no data (device disconnected?)")

    pulled = UartBus(Pulled(ModelBus(MAP, DEFAULT), addr_width(MAP)), name="the board on /dev/ttyUSB0")
    with pytest.raises(LinkError, match=r"^lost the board on /dev/ttyUSB0 during a read at 0x0: device reports "
                                        r"readiness to read but returned no data \(device disconnected\?\)$"):
        pulled.read(0)
    headless = UartBus(ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP), mangle=lambda a: a[:2]))
    with pytest.raises(LinkError, match=r"^no answer from the link to a read at 0x0 \(2 of 7 bytes before the "):
        headless.read(0)  # the header came, the word and the checksum did not
    overlong = UartBus(ModelPort(ModelBus(MAP, DEFAULT), addr_width(MAP), mangle=lambda a: bytes([a[0], 255]) + a[2:]))
    with pytest.raises(LinkError, match=r"^corrupt answer from the link to a read at 0x0: OK with 255 words for 1$"):
        overlong.read(0)  # refused at its header, not after waiting for 1,021 bytes


@pytest.mark.parametrize("url", ["socket://localhost", "rfc2217://host:port", "socket://host:"])
def test_a_network_port_without_a_port_number_is_one_line(url):
    """pyserial answers a socket:// URL without a port with a TypeError's text ('<=' not supported ...)."""
    scheme = url.split(":")[0]
    with pytest.raises(LinkError, match=rf"^cannot open the serial port '{url}': a {scheme}:// URL needs a port number "
                                        rf"\({scheme}://HOST:PORT\)$"):
        open_port(url)


@pytest.mark.parametrize("port, baud, noted", [("socket://127.0.0.1:9", 9600, True), ("loop://", 9600, True),
                                               ("socket://127.0.0.1:9", None, False), ("/dev/ttyUSB7", 9600, False),
                                               ("rfc2217://127.0.0.1:9", 9600, False)])
def test_a_baud_on_a_link_without_a_line_rate_gets_a_note(capsys, port, baud, noted):
    """--baud on a socket:// or loop:// link (a network socket, pyserial's loopback) sets nothing: a note says
    so (rfc2217:// does set the far port's rate). Nothing is opened until the engine runs."""
    board_engine(FormatSet.preset("default"), port, baud)
    err = capsys.readouterr().err
    assert (err == f"springflat: note: --baud 9600 has no effect on a {port.split('://')[0]}:// link, which carries "
                   "bytes at no line rate; the board's UART runs at the rate its bitstream was built for\n") if noted \
        else err == ""


def test_an_impossible_baud_is_refused_without_the_note_on_a_link_that_ignores_it(capsys):
    """--baud 0 on loop:// printed the note that the rate has no effect, then refused it: the refusal alone."""
    from sim.run_options import UserError

    with pytest.raises(UserError, match=r"^--baud must be a positive number of bits per second, not 0$"):
        board_engine(FormatSet.preset("default"), "loop://", 0)
    assert capsys.readouterr().err == ""


def test_a_refused_connection_names_the_port_once():
    """The port named once, pyserial's own words about it ('Could not open port socket://...: ...') left out."""
    import socket

    with socket.socket() as s:  # a port nothing listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        url = f"socket://127.0.0.1:{s.getsockname()[1]}"
        with pytest.raises(LinkError) as refused:
            open_port(url)
    assert str(refused.value).startswith(f"cannot open the serial port '{url}': [Errno ")
    assert str(refused.value).count(url) == 1


def test_a_file_that_is_no_device_is_no_port(tmp_path):
    """A regular file (the mesh, say) or a directory named as the port is no serial device: refused before
    pyserial opens it (read-write)."""
    mesh = tmp_path / "m.obj"
    mesh.write_text("v 0 0 0\n")
    for path, kind in ((mesh, "regular file"), (tmp_path, "directory")):
        with pytest.raises(LinkError, match=rf"^cannot open the serial port '{path}': it is a {kind}, not a serial "
                                            r"device \(such as /dev/ttyUSB0\)$"):
            open_port(str(path))
    assert mesh.read_text() == "v 0 0 0\n"


@pytest.mark.slow  # two CLI runs
def test_a_missing_port_is_one_line(tmp_path):
    with pytest.raises(LinkError, match=f"^cannot open the serial port '{tmp_path}/ttyUSB9': ") as missing:
        open_port(str(tmp_path / "ttyUSB9"))
    assert str(missing.value).count("ttyUSB9") == 1  # (once: pyserial's own words about the port left out)
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "board", "--port", str(tmp_path / "ttyUSB9"),
                           "--out", "out.obj"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    last = proc.stderr.splitlines()[-1]
    assert last.startswith(f"springflat: error: cannot open the serial port '{tmp_path}/ttyUSB9'")
    assert len([l for l in proc.stderr.splitlines() if l.startswith("springflat: error")]) == 1
    assert not (tmp_path / "out.obj").exists()
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "board"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and proc.stderr.strip() == ("springflat: error: --engine board needs --port DEVICE "
                                                            "(the board's serial port, e.g. /dev/ttyUSB0)")


class FrameServer:
    """A TCP server (pyserial's ``socket://`` URL) that answers frames as the bridge would, ModelBus behind."""

    def __init__(self, capacity: EngineCapacity):
        rmap = RegisterMap.build(DEFAULT, capacity)
        self.bus = ModelBus(rmap, DEFAULT)
        self.target = protocol.ReferenceTarget(self.bus.read, self.bus.write, addr_width(rmap))
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.frames = 0
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _recv(self, conn, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = conn.recv(n - len(data))
            if not chunk:
                raise EOFError
            data += chunk
        return data

    def _serve(self):
        with self.server:  # one connection: the listening socket closes once it is accepted
            conn, _ = self.server.accept()
        with conn:
            try:
                while True:
                    head = self._recv(conn, protocol.HEADER_BYTES)
                    rest = self._recv(conn, protocol.request_length(head[0], head[-1]) - len(head))
                    conn.sendall(self.target.serve(head + rest))
                    self.frames += 1
            except (EOFError, ConnectionError):
                pass


@pytest.mark.slow  # two CLI runs
def test_flatten_engine_board_writes_the_fixed_engines_layout(tmp_path):
    """flatten surf1 --engine board through pyserial (socket://) to the reference bridge and the engine model:
    the layout file is byte for byte the one --engine fixed writes."""
    server = FrameServer(DEFAULT_CAPACITY)
    outs = {}
    for engine, extra in (("board", ["--port", f"socket://127.0.0.1:{server.port}"]), ("fixed", [])):
        proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", engine, *extra, "--out", f"{engine}.obj"],
                              capture_output=True, text=True, cwd=tmp_path, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        outs[engine] = proc.stdout
    assert (tmp_path / "board.obj").read_bytes() == (tmp_path / "fixed.obj").read_bytes()
    assert "engine cycles on the board on socket://" in outs["board"]
    assert outs["board"].split(":")[1] == outs["fixed"].split(":")[1]  # status and iterations
    assert server.frames > 10


def test_a_port_url_that_names_a_log_file_is_refused_and_the_file_left_alone(tmp_path):
    """pyserial's spy:// truncates its file= at once, with none of the checks an output gets (it could be the
    mesh being flattened): refused; another URL still opens."""
    mesh = tmp_path / "ear.obj"
    mesh.write_text("v 0 0 0\n")
    with pytest.raises(LinkError, match=r"names a log file \(file=\), which springflat would write unchecked"):
        open_port(f"spy://loop://?file={mesh}")
    assert mesh.read_text() == "v 0 0 0\n"
    port = open_port("loop://")
    port.close()


@pytest.mark.slow  # a CLI run
def test_a_loopback_port_is_said_to_echo_not_to_answer_corruptly(tmp_path):
    """loop:// (or a jumper on the wires) sends the request back: said as an echo, not as a corrupt answer."""
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "board", "--port", "loop://", "--out", "o.obj"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and not (tmp_path / "o.obj").exists()
    assert proc.stderr.splitlines()[-2:] == [
        "springflat: board: loading the mesh over loop:// and running the flattening ...",
        "springflat: error: the board on loop:// echoes what is sent (a read at 0x0): a loopback, not the board's "
        "bridge"]
