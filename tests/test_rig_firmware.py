"""The Arduino sketch: it compiles for an Uno, it agrees with the Python driver's
protocol constants, and (slow) the compiled firmware boots under simavr and greets the
driver.

Needs the Debian packages gcc-avr, avr-libc, arduino-core-avr, arduino-mk (compile) and
simavr (run); the tests skip with the reason when they are absent.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from mitsweep.rig import arduino as driver
from mitsweep.rig.testing import expected_protocol

SKETCH_DIR = Path(__file__).resolve().parents[1] / "scripts" / "firmware" / "mitsweep_sweep"
SKETCH = SKETCH_DIR / "mitsweep_sweep.ino"
ARDUINO_MK = Path("/usr/share/arduino/Arduino.mk")
# ATmega328P: 32 KiB flash less the 0.5 KiB Optiboot bootloader; 2 KiB SRAM
UNO_FLASH_BYTES = 32256
UNO_SRAM_BYTES = 2048

needs_toolchain = pytest.mark.skipif(
    shutil.which("avr-gcc") is None or not ARDUINO_MK.exists(),
    reason="AVR toolchain absent: apt-get install gcc-avr avr-libc arduino-core-avr arduino-mk")


@pytest.fixture(scope="module")
def firmware(tmp_path_factory):
    """Build the sketch in a scratch copy (no build output in the repository)."""
    if shutil.which("avr-gcc") is None or not ARDUINO_MK.exists():
        pytest.skip("AVR toolchain absent: apt-get install gcc-avr avr-libc "
                    "arduino-core-avr arduino-mk")
    work = tmp_path_factory.mktemp("fw") / SKETCH_DIR.name
    shutil.copytree(SKETCH_DIR, work)
    proc = subprocess.run(["make", "-s"], cwd=work, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    # arduino-mk names the outputs after the directory (with a trailing '_')
    elves = sorted((work / "build-uno").glob("*.elf"))
    assert len(elves) == 1 and elves[0].with_suffix(".hex").exists()
    return elves[0]


def _section_sizes(elf: Path) -> tuple[int, int]:
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    size = {m.group(1): int(m.group(2)) for m in re.finditer(r"^\.(\w+)\s+(\d+)", out, re.M)}
    flash = size.get("text", 0) + size.get("data", 0)
    sram = size.get("data", 0) + size.get("bss", 0)
    return flash, sram


@needs_toolchain
def test_sketch_compiles_for_uno_and_fits(firmware):
    flash, sram = _section_sizes(firmware)
    assert 0 < flash <= UNO_FLASH_BYTES
    # leave at least 512 B of SRAM for the stack and the serial buffers
    assert 0 < sram <= UNO_SRAM_BYTES - 512


def test_sketch_speaks_the_drivers_protocol():
    src = SKETCH.read_text()
    assert f'#define FW_NAME "{driver.FIRMWARE_NAME}"' in src
    assert f"#define PROTOCOL_VERSION {driver.PROTOCOL_VERSION}" in src
    assert f"const long MAX_STEP_RATE = {driver.MAX_STEP_RATE};" in src
    assert f"const uint32_t POS_PERIOD_US = {driver.POS_EVENT_PERIOD_US}UL;" in src
    sent_codes = set(re.findall(r'sendErr\("([A-Z]+)"', src))
    assert sent_codes <= set(driver.ERROR_CODES)
    sent_events = set(re.findall(r'sendEvent\("([A-Z]+)"', src))
    assert sent_events == set(driver.EVENT_NAMES)
    commands = set(re.findall(r'!strcmp\(text, "([A-Z]+)"\)', src))
    assert commands == {"ID", "STATE", "CHK", "LIMITS", "HOME", "MOVE", "SWEEP", "SHUTTER",
                        "CLOSE", "STOP"}


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("simavr") is None, reason="simavr absent: apt-get install simavr")
def test_firmware_boots_under_simavr_and_greets_driver(firmware):
    # simavr's command line prints UART0 output (it offers no input); the firmware's
    # first line must be the READY line the driver waits for after a reset
    proc = subprocess.run(["timeout", "-s", "INT", "3", "simavr", "-m", "atmega328p",
                           "-f", "16000000", str(firmware)], capture_output=True, text=True)
    text = re.sub(r"\x1b\[[0-9;]*m", "", proc.stdout + proc.stderr)
    lines = [ln.rstrip(".") for ln in text.splitlines() if ln.startswith("READY")]
    assert lines, text[-2000:]
    with expected_protocol(lambda t: driver.ArduinoSweepController(t, steps_per_mm=400),
                           [(None, lines[0].encode() + b"\n")]) as board:
        assert board.wait_ready(0.1)
    assert board.ready_line == f"READY {driver.FIRMWARE_NAME} 1.0 {driver.PROTOCOL_VERSION}"
