"""The Arduino sketch: it compiles for an Uno, it agrees with the Python driver's
protocol constants, and (slow) the compiled firmware boots under simavr and greets the
driver.

Needs the Debian packages gcc-avr, avr-libc, arduino-core-avr, arduino-mk (compile) and
simavr (run). On a developer's machine the tests skip, with the reason, when they are
absent; under CI (``CI`` set) they run regardless and fail, because the test command
(``scripts/test.sh`` → ``bootstrap.sh --test``) installs them: a failed install must not
pass as a skip.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from rig_fixtures import bent_profile, sweep_of
from rig_fixtures import sphere  # noqa: F401 - fixture

from mitsweep.rig import arduino as driver
from mitsweep.rig.sim.pty import raise_priority
from mitsweep.rig.testing import expected_protocol

SKETCH_DIR = Path(__file__).resolve().parents[1] / "scripts" / "firmware" / "mitsweep_sweep"
SKETCH = SKETCH_DIR / "mitsweep_sweep.ino"
ARDUINO_MK = Path("/usr/share/arduino/Arduino.mk")
# ATmega328P: 32 KiB flash less the 0.5 KiB Optiboot bootloader; 2 KiB SRAM
UNO_FLASH_BYTES = 32256
UNO_SRAM_BYTES = 2048

IN_CI = bool(os.environ.get("CI"))

needs_toolchain = pytest.mark.skipif(
    not IN_CI and (shutil.which("avr-gcc") is None or not ARDUINO_MK.exists()),
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
                        "CLOSE", "STOP", "WATCHDOG", "PING", "TABLE", "SEG", "TSWEEP"}
    assert f"const uint8_t MAX_TABLE_SEGMENTS = {driver.MAX_TABLE_SEGMENTS};" in src
    assert f"const long MAX_SEGMENT_STEPS = {driver.MAX_SEGMENT_STEPS}L;" in src
    assert f"const long MAX_WATCHDOG_MS = {driver.MAX_WATCHDOG_MS}L;" in src
    assert 'fault("WATCHDOG")' in src


@pytest.mark.slow
@pytest.mark.skipif(not IN_CI and shutil.which("simavr") is None,
                    reason="simavr absent: apt-get install simavr")
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
    assert board.ready_line == f"READY {driver.FIRMWARE_NAME} 1.2 {driver.PROTOCOL_VERSION}"


# -- the sketch's own code on the host, against the Python driver ------------------------
# The host build's steps happen when the OS schedules the polling loop (it naps 20 µs
# per turn): a step, and so the shutter edge and its event, can be late by a scheduling
# delay, which on this shared 2-core machine reaches several ms (a real Uno's loop
# jitter is ~20 µs). The step *positions* of the edges are exact; times get this bound.
HOST_TIMING_TOLERANCE_S = 25e-3
# Events and the pin trace are stamped in the same loop turn: within 200 µs.
SAME_TURN_S = 200e-6


# host_firmware: the host build of the sketch, compiled once per session (tests/conftest.py)


class HostBoard:
    """The host-built sketch on the master side of a pty; ``port`` is the slave path."""

    def __init__(self, binary: Path, trace: Path, start_steps: int) -> None:
        import os
        import tty

        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.trace = trace
        env = dict(os.environ, MITSWEEP_FW_START_STEPS=str(start_steps),
                   MITSWEEP_FW_TRACE=str(trace))
        self.proc = subprocess.Popen([str(binary)], stdin=self.master, stdout=self.master,
                                     env=env)
        # the board is separate hardware: the host's load must not slow it (as for the
        # simulator's thread, mitsweep.rig.sim.pty); single-threaded, so its pid suffices
        raise_priority(self.proc.pid)
        # A board powered up before the host connects: its first READY is read here, so
        # that a test's opening of the port (pyserial flushes it: a reset, as an Uno's
        # DTR) is followed by exactly one READY. Without this, on a loaded machine the
        # program could print its first READY after that flush and then reset on it: a
        # second READY where the test reads its first command's reply (seen once in CI).
        self._first_line(b"READY ", timeout_s=10.0)

    def _first_line(self, prefix: bytes, timeout_s: float) -> None:
        import os
        import select
        import time

        data, deadline = b"", time.monotonic() + timeout_s
        while not (data.startswith(prefix) and b"\n" in data):
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.slave], [], [], left)[0]:
                self.close()
                raise AssertionError(f"the host firmware printed {data!r}, not {prefix!r}, "
                                     f"within {timeout_s} s")
            data += os.read(self.slave, 4096)

    def close(self) -> None:
        import os

        self.proc.kill()
        self.proc.wait(timeout=5)
        os.close(self.master)
        os.close(self.slave)

    def pin_changes(self, pin: int) -> list[tuple[int, int, int]]:
        """(micros, value, axis steps) for each change of ``pin`` (none before the
        program has opened its trace)."""
        return [(t, v, a) for t, p, v, a, _ in self._rows() if p == pin]

    def pin_times(self, pin: int) -> list[tuple[float, int]]:
        """(``time.monotonic()`` s, value) of each change of ``pin``."""
        return [(mono * 1e-6, v) for _, p, v, _, mono in self._rows() if p == pin]

    def _rows(self) -> list[tuple[int, ...]]:
        text = self.trace.read_text() if self.trace.exists() else ""
        return [tuple(int(v) for v in ln.split()) for ln in text.splitlines()]


def capture_on_host_board(host_firmware, tmp_path, setup, plan):
    """``plan`` run by run_capture on the host-built sketch over a real pty. Checks what
    every such capture must show: a complete record whose measured exposure is the
    planned one, and the shutter pin high once, exactly between the planned steps.
    Returns the record and the board's (open, close) times of the shutter pin, µs."""
    from mitsweep.rig import RigPorts, load_capture_record, run_capture

    board = HostBoard(host_firmware, tmp_path / "pins.txt", start_steps=400)
    out = tmp_path / "capture.json"
    try:
        run_capture(setup, RigPorts(arduino=board.port, checksums=True), out=out, plan=plan)
    finally:
        board.close()
    data = load_capture_record(out)
    assert data["complete"]
    assert data["measured"]["exposure"]["measured_exposure_s"] == pytest.approx(
        plan.planned_exposure_s, abs=HOST_TIMING_TOLERANCE_S)
    shutter = board.pin_changes(6)   # PIN_SHUTTER
    assert [v for _, v, _ in shutter] == [1, 0]
    (t_open, _, x_open), (t_close, _, x_close) = shutter
    assert (x_open, x_close) == (plan.open_steps, plan.close_steps)
    return data, (t_open, t_close)


def test_sketch_runs_a_capture_with_the_python_driver(host_firmware, sphere, tmp_path):
    """The firmware's own parsing, ramps, shutter window and events, driven by
    run_capture over a real pty: the record is complete, the shutter pin was high once,
    exactly between the planned steps, for the planned time."""
    from mitsweep.rig import plan_capture

    data, (t_open, t_close) = capture_on_host_board(host_firmware, tmp_path, sphere,
                                                    plan_capture(sphere))
    assert data["homed"]
    # the board's events report the shutter edges it drove
    assert data["measured"]["exposure"]["measured_exposure_s"] == pytest.approx(
        (t_close - t_open) * 1e-6, abs=SAME_TURN_S)
    assert [e["name"] for e in data["events"]].count("POS") >= 10


def test_sketch_runs_a_motion_profile_with_the_python_driver(host_firmware, sphere, tmp_path):
    """The firmware's own table execution (TABLE/SEG/TSWEEP), driven by run_capture over
    a real pty with an optimised-like profile: the shutter pin was high once, exactly
    between the planned steps, for the table's time, and the board's positions follow
    the plan (one step, plus the peak rate over the host build's scheduling delay)."""
    from mitsweep.rig import plan_capture

    # 1.3x the mean velocity at the start, 0.7x at the end
    motion = bent_profile(sweep_of(sphere))
    plan = plan_capture(sphere, motion=motion, exposure_s=0.7)
    data, (t_open, t_close) = capture_on_host_board(host_firmware, tmp_path, sphere, plan)
    # the table is timed from the open step on the board's clock: its last step, which
    # closes the shutter, is due the table's duration later (late by scheduling only)
    assert (t_close - t_open) * 1e-6 == pytest.approx(plan.profile.duration_s,
                                                      abs=HOST_TIMING_TOLERANCE_S)
    cmp = data["measured"]["profile"]
    peak = max(k / d for k, d in zip(plan.profile.steps, plan.profile.durations_s))
    assert cmp["max_deviation_steps"] <= 1 + peak * HOST_TIMING_TOLERANCE_S
    assert len(cmp["time_s"]) >= 10


# -- the simulator and the firmware answer alike ------------------------------------------
# (command, expected reply, events that must follow before the next command). Replies are
# matched as regular expressions from their start (OK <CMD> / ERR <CODE>); events by
# name. ramp for rate 400 and accel 4000 is ceil(400² / (2·4000)) = 20 steps; for 200,
# 5 steps.
CONFORMANCE = [
    ("MOVE 100 400 4000", "ERR HOME", []),
    ("LIMITS 0 10000", "OK LIMITS 0 10000", []),
    ("HOME 4000", "OK HOME", ["HOMED"]),
    ("MOVE 20000 400 4000", "ERR LIMIT", []),
    ("MOVE 100 5000 4000", "ERR RANGE", []),
    ("MOVE 200 4000 40000", "OK MOVE", ["DONE"]),
    ("SWEEP 0 400 4000 190 10", "ERR RANGE", []),          # opens inside the ramp
    ("SWEEP 0 400 4000 170 30", "OK SWEEP", ["START", "OPEN", "CLOSE", "DONE"]),
    # a step-rate table: 40 steps in 0.1 s (400 steps/s), then 20 in 0.1 s (200 steps/s)
    ("TSWEEP 300 4000 100 160", "ERR RANGE", []),            # no table yet
    ("TABLE 0", "ERR RANGE", []),
    (f"TABLE {driver.MAX_TABLE_SEGMENTS + 1}", "ERR RANGE", []),
    ("TABLE 2", "OK TABLE 2$", []),
    ("SEG 1 40 100000", "ERR RANGE", []),                    # out of order
    ("SEG 0 40 100000", "OK SEG 0 40 100000$", []),
    ("SEG 1 500 100000", "ERR RANGE", []),                   # 5000 steps/s
    ("TSWEEP 300 4000 100 160", "ERR RANGE", []),            # the table is incomplete
    ("SEG 1 20 100000", "OK SEG 1 60 200000$", []),
    ("TSWEEP 300 4000 10 70", "ERR RANGE", []),              # opens inside the ramp
    ("TSWEEP 300 4000 100 170", "ERR RANGE", []),            # close is not open + 60
    ("TSWEEP 162 4000 100 160", "ERR RANGE", []),            # no room for the exit ramp
    ("TSWEEP 300 4000 100 160", "OK TSWEEP", ["START", "OPEN", "CLOSE", "DONE"]),
    ("STATE", r"OK STATE \d+ 300 1 0 0$", []),
    # a silent host in the middle of a table (shutter open): the board stops and
    # releases it 0.25 s after the command (open after the 0.1 s ramp, table 0.5 s)
    ("TABLE 1", "OK TABLE 1$", []),
    ("SEG 0 200 500000", "OK SEG 0 200 500000$", []),
    ("WATCHDOG 250", "OK WATCHDOG 250", []),
    ("TSWEEP 1000 4000 320 520", "OK TSWEEP", ["START", "OPEN", "FAULT"]),
    ("STATE", r"OK STATE \d+ \d+ 1 0 0$", []),             # at rest, shutter released
    ("WATCHDOG 0", "OK WATCHDOG 0", []),
    ("PING", "OK PING", []),
    ("WATCHDOG 600001", "ERR RANGE", []),
    # a silent host: 0.1 s after its last line the board stops the 10 s move
    ("WATCHDOG 100", "OK WATCHDOG 100", []),
    ("MOVE 4000 400 4000", "OK MOVE", ["FAULT"]),
    ("WATCHDOG 0", "OK WATCHDOG 0", []),
    ("BOGUS 1", "ERR SYNTAX", []),
    ("SHUTTER 1000 20000", "OK SHUTTER", ["OPEN", "CLOSE"]),
    ("STOP", "OK STOP", []),
]


@pytest.fixture(params=["simulator", "firmware"])
def board_port(request, tmp_path):
    from mitsweep.rig.simulator import ArduinoModel, PtyDevice

    if request.param == "simulator":
        with PtyDevice(ArduinoModel(position=300)) as dev:
            yield dev.port, request.param
    else:
        binary = request.getfixturevalue("host_firmware")
        board = HostBoard(binary, tmp_path / "pins.txt", start_steps=300)
        try:
            yield board.port, request.param
        finally:
            board.close()


def test_simulator_and_firmware_answer_alike(board_port):
    from mitsweep.rig.arduino import ArduinoSweepController
    from mitsweep.rig.transport import LineTransport, open_port

    port, kind = board_port
    t = LineTransport(open_port(port), name=kind, timeout_s=1.0)
    try:
        board = ArduinoSweepController(t, steps_per_mm=400)
        assert board.wait_ready(3.0)
        for command, reply, events in CONFORMANCE:
            t.write_line(command)
            line = t.read_line()
            while line.startswith("EV POS"):
                line = t.read_line()
            assert re.match(reply, line), (command, line)
            seen = []
            while len(seen) < len(events):
                ev = board.take_event(t.read_line(timeout_s=3.0))
                assert ev is not None
                assert ev.name != "FAULT" or "FAULT" in events, (command, ev)
                if ev.name != "POS":
                    seen.append(ev)
            assert [e.name for e in seen] == events, command
            if command.startswith("SWEEP") and reply.startswith("OK"):
                opened, closed = seen[1], seen[2]
                assert (opened.position, closed.position, seen[-1].position) == (170, 30, 0)
                # 140 steps at 400 steps/s; the host build's steps may be late by a
                # scheduling delay (HOST_TIMING_TOLERANCE_S), the simulator's are exact
                tol = HOST_TIMING_TOLERANCE_S if kind == "firmware" else 2e-6
                assert (closed.t_us - opened.t_us) * 1e-6 == pytest.approx(0.35, abs=tol)
            if command.startswith("TSWEEP") and events[-1:] == ["DONE"]:
                opened, closed, done = seen[1], seen[2], seen[3]
                assert (opened.position, closed.position, done.position) == (100, 160, 300)
                tol = HOST_TIMING_TOLERANCE_S if kind == "firmware" else 2e-6
                assert (closed.t_us - opened.t_us) * 1e-6 == pytest.approx(0.2, abs=tol)
            if command.startswith("TSWEEP") and events[-1:] == ["FAULT"]:
                assert seen[-1].detail == "WATCHDOG"
                assert seen[1].position == 320 < seen[-1].position < 520   # inside the table
            if events == ["FAULT"]:
                assert seen[0].detail == "WATCHDOG"
                # stopped ~0.1 s into the move (~20 of its 4000 steps: the ramp), not at its end
                assert 0 < seen[0].position < 1000
            if command.startswith("SHUTTER"):
                tol = HOST_TIMING_TOLERANCE_S if kind == "firmware" else 2e-6
                assert (seen[1].t_us - seen[0].t_us) * 1e-6 == pytest.approx(0.02, abs=tol)
    finally:
        t.close()
