"""springflat verilog: files, stable port names, and an interface description that matches the Verilog."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from golden_model.fixed import FormatSet

SPRINGFLAT = str(Path(sys.executable).parent / "springflat")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("verilog")
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "narrow", "--out", out], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out


def _verilog_ports(text: str, module: str) -> dict[str, tuple[str, int]]:
    body = text[text.index(f"module {module}("):]
    body = body[:body.index("endmodule")]
    ports = {}
    for direction, msb, name in re.findall(r"^\s*(input|output)\s+(?:wire\s+|reg\s+)?(?:\[(\d+):0\]\s+)?\\?([\w$]+)\s*;",
                                           body, re.M):
        ports[name] = (direction, int(msb) + 1 if msb else 1)
    return ports


def test_files_and_interface_match_the_verilog(exported):
    interface = json.loads((exported / "interface.json").read_text())
    assert interface["format_set"]["name"] == "narrow"
    assert FormatSet.from_dict(interface["format_set"]) == FormatSet.preset("narrow")
    for module, info in interface["components"].items():
        text = (exported / f"{module}.v").read_text()
        ports = _verilog_ports(text, module)
        assert ports == {p["name"]: (p["direction"], p["width"]) for p in info["ports"]}, module
        assert info["initiation_interval"] == 1 and info["latency"] > 0
    core = interface["components"]["springflat_core"]
    names = {p["name"] for p in core["ports"]}
    assert {"entries__payload", "entries__valid", "entries__ready", "results__payload", "results__valid",
            "results__ready", "errors__payload", "step_load__payload", "step", "measure", "half_spring",
            "damping"} <= names
    fields = {f["field"]: f for f in core["payload_layouts"]["entries__payload"]}
    width = {p["name"]: p["width"] for p in core["ports"]}["entries__payload"]
    assert sum(f["width"] for f in fields.values()) == width  # the fields tile the port
    assert fields["first"]["lsb"] == 0 and fields["node.position.x"]["format"] == "position s10.14"
    assert (exported / "rsqrt_seed.hex").read_text().count("\n") == FormatSet.preset("narrow").rsqrt_config().seed_table_size
    assert "| `entries__payload` | input |" in (exported / "interface.md").read_text()


def test_bad_formats_and_out(tmp_path):
    (tmp_path / "file").write_text("x")
    proc = subprocess.run([SPRINGFLAT, "verilog", "--out", tmp_path / "file"], capture_output=True, text=True)
    assert proc.returncode == 2 and "not a directory" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "nope", "--out", tmp_path / "v"], capture_output=True,
                          text=True)
    assert proc.returncode == 2 and "unknown FormatSet preset" in proc.stderr
