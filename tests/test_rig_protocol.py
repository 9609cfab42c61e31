"""Protocol tests: the exact bytes each driver exchanges (pymeasure ``expected_protocol``
style). Every test fails on an unexpected write, an unused exchange or an unread reply."""

from __future__ import annotations

import pytest

from mitsweep.rig.arduino import ArduinoSweepController, BoardClock
from mitsweep.rig.errors import DeviceError, DeviceFault, ProtocolError, ReplyTimeout
from mitsweep.rig.testing import expected_protocol
from mitsweep.rig.transport import XorChecksum, ZaberChecksum
from mitsweep.rig.zaber import ZaberStage, parse_reply


def arduino(t):
    return ArduinoSweepController(t, steps_per_mm=400)


def zaber(t, **kw):
    return ZaberStage(t, steps_per_mm=1000, **kw)


# -- the helper itself -------------------------------------------------------------------
def test_expected_protocol_fails_on_unused_exchange():
    with pytest.raises(AssertionError, match="not used"):
        with expected_protocol(arduino, [(b"ID\n", b"OK ID mitsweep-sweep 1.2 3\n"),
                                         (b"STATE\n", b"OK STATE 1 0 0 0 0\n")]) as a:
            a.identify()


def test_expected_protocol_fails_on_unexpected_write():
    with pytest.raises(AssertionError, match="unexpected write"):
        with expected_protocol(arduino, [(b"ID\n", b"OK ID mitsweep-sweep 1.2 3\n")]) as a:
            a.state()


def test_expected_protocol_fails_on_unread_reply():
    with pytest.raises(AssertionError, match="never read"):
        with expected_protocol(arduino, [(b"CLOSE\n", b"OK CLOSE\nOK CLOSE\n")]) as a:
            a.close_shutter()


# -- Arduino sweep controller ------------------------------------------------------------
def test_arduino_ready_and_identify():
    with expected_protocol(arduino, [
            (None, b"READY mitsweep-sweep 1.2 3\n"),
            (b"ID\n", b"OK ID mitsweep-sweep 1.2 3\n")]) as a:
        assert a.wait_ready(0.1)
        assert a.identify() == "mitsweep-sweep 1.2 (protocol 3)"


@pytest.mark.parametrize("reply, error", [
    (b"OK ID other-board 1.0 1\n", "not 'mitsweep-sweep'"),
    # a board still running protocol-1 firmware (no watchdog) is refused
    (b"OK ID mitsweep-sweep 1.0 1\n", "protocol version 1, this driver speaks 2 or 3"),
    (b"OK ID mitsweep-sweep 1.3 4\n", "protocol version 4, this driver speaks 2 or 3"),
    (b"OK IDENT mitsweep-sweep 1.0 1\n", "unexpected reply"),
    (b"OK ID mitsweep-sweep 1.0\n", "unexpected reply"),
])
def test_arduino_identify_rejects_wrong_device(reply, error):
    with expected_protocol(arduino, [(b"ID\n", reply)]) as a:
        with pytest.raises(ProtocolError, match=error):
            a.identify()


def test_arduino_ready_mid_session_is_a_board_restart():
    """A READY line after the handshake means the board restarted (brown-out, another
    program opening the port): a DeviceFault saying so, not a bare protocol error."""
    with expected_protocol(arduino, [(b"STATE\n", b"READY mitsweep-sweep 1.2 3\n")]) as a:
        with pytest.raises(DeviceFault, match="restarted mid-session.*reply to 'STATE'"):
            a.state()


@pytest.mark.parametrize("reply, homed, moving, position", [
    (b"OK STATE 1000 0 0 0 0\n", False, False, None),
    (b"OK STATE 1000 800 1 1 0\n", True, True, 2.0),
    (b"OK STATE 1000 -4 1 0 1\n", True, False, -0.01),
])
def test_arduino_state(reply, homed, moving, position):
    with expected_protocol(arduino, [(b"STATE\n", reply)]) as a:
        s = a.state()
    assert (s.homed, s.moving, s.position) == (homed, moving, position)


def test_arduino_limits_home_move():
    with expected_protocol(arduino, [
            (b"LIMITS 0 10000\n", b"OK LIMITS 0 10000\n"),
            (b"HOME 2000\n", b"OK HOME\n"), (None, b"EV HOMED 5000 0\n"),
            (b"MOVE 4000 2000 4000\n", b"OK MOVE\n"), (None, b"EV DONE 900000 4000\n"),
    ]) as a:
        a.set_soft_limits(0.0, 25.0)
        a.home(velocity_mm_s=5.0, timeout_s=0.5)
        assert a.move_to(10.0, velocity_mm_s=5.0, acceleration_mm_s2=10.0, timeout_s=0.5) == 10.0
    assert [e.name for e in a.events] == ["HOMED", "DONE"]


def test_arduino_sweep_events_in_order():
    with expected_protocol(arduino, [
            (b"SWEEP 4800 400 4000 4780 4502\n", b"OK SWEEP\n"),
            (None, b"EV START 100 4820\nEV OPEN 200100 4780\nEV POS 250100 4760\n"
                   b"EV CLOSE 895100 4502\nEV DONE 995100 4800\n"),
    ]) as a:
        # direction -1 is fine too: the board only checks the window lies inside the move
        # 1 mm/s and 10 mm/s² at 400 steps/mm: 400 steps/s, 4000 steps/s² on the wire
        a.start_sweep(target=4800, velocity_mm_s=1.0, acceleration_mm_s2=10.0, open_at=4780,
                      close_at=4502)
        done = a.wait_event("DONE", timeout_s=0.5)
    assert done.position == 4800
    names = [e.name for e in a.events]
    assert names == ["START", "OPEN", "POS", "CLOSE", "DONE"]
    o, c = a.events[1], a.events[3]
    assert c.t_us - o.t_us == 695_000


def test_arduino_err_is_device_error():
    with expected_protocol(arduino, [(b"MOVE 99999 2000 4000\n",
                                      b"ERR LIMIT target outside soft limits\n")]) as a:
        with pytest.raises(DeviceError, match="LIMIT target outside soft limits"):
            a.move_to(249.9975, velocity_mm_s=5.0, acceleration_mm_s2=10.0, timeout_s=0.1)


def test_arduino_fault_event_raises_device_fault():
    with expected_protocol(arduino, [
            (b"SWEEP 800 400 4000 780 502\n", b"OK SWEEP\n"),
            (None, b"EV START 10 820\nEV FAULT 500 700 STALL\n")]) as a:
        a.start_sweep(target=800, velocity_mm_s=1.0, acceleration_mm_s2=10.0, open_at=780,
                      close_at=502)
        with pytest.raises(DeviceFault, match="STALL"):
            a.wait_event("DONE", timeout_s=0.2)


@pytest.mark.parametrize("line", [b"EV OPEN 12x 4\n", b"EV BOGUS 1 2\n", b"HELLO\n"])
def test_arduino_unknown_line_while_waiting_is_protocol_error(line):
    with expected_protocol(arduino, [(None, line)]) as a:
        with pytest.raises(ProtocolError):
            a.wait_event("DONE", timeout_s=0.1)


def test_arduino_no_event_is_timeout():
    with expected_protocol(arduino, []) as a:
        with pytest.raises(ReplyTimeout, match="EV DONE"):
            a.wait_event("DONE", timeout_s=0.05)


def test_arduino_checksum_mode_exact_bytes():
    # XOR checksums worked by hand: STOP = 53^54^4F^50 = 18; 'OK CHK 1' = 75
    with expected_protocol(arduino, [
            (b"CHK 1\n", b"OK CHK 1*75\n"),
            (b"STOP*18\n", b"OK STOP 123 45*0D\n"),
    ]) as a:
        a.enable_checksums()
        a.stop()
    assert a.stopped_at == 45


def test_arduino_bad_checksum_is_protocol_error():
    with expected_protocol(arduino, [(b"CHK 1\n", b"OK CHK 1*75\n"),
                                     (b"CLOSE*56\n", b"OK CLOSE*00\n")]) as a:
        a.enable_checksums()
        with pytest.raises(ProtocolError, match="bad checksum"):
            a.close_shutter()


def test_arduino_safe_stop_skips_stray_lines():
    # a late reply to an interrupted command and garbage must not block the stop
    with expected_protocol(arduino, [(b"STOP\n", b"\xff\xfe\nOK SWEEP\nOK STOP 77 1234\n")]) as a:
        assert a.safe_stop(timeout_s=0.2) == 1234


def test_board_clock_unwraps_micros():
    clock = BoardClock()
    raw = [2**32 - 300, 2**32 - 100, 50, 400]
    assert [clock.unwrap(r) for r in raw] == [2**32 - 300, 2**32 - 100, 2**32 + 50, 2**32 + 400]


# -- Zaber ASCII -------------------------------------------------------------------------
def test_zaber_identify_and_state_not_homed():
    with expected_protocol(zaber, [
            (b"/1 0 get deviceid\n", b"@01 0 OK IDLE WR 50081\r\n"),
            (b"/1 1 get pos\n", b"@01 1 OK IDLE WR 0\r\n"),
    ]) as z:
        assert z.identify() == "zaber device id 50081 at address 1"
        s = z.state()
    assert (s.homed, s.position, s.moving) == (False, None, False)


def test_zaber_limits_motion_move_and_poll():
    with expected_protocol(zaber, [
            (b"/1 1 set limit.min 0\n", b"@01 1 OK IDLE -- 0\r\n"),
            (b"/1 1 set limit.max 25000\n", b"@01 1 OK IDLE -- 0\r\n"),
            # 2 mm/s at 1000 µsteps/mm = 2000 µsteps/s -> 3277 speed units; 10 mm/s² -> 1638
            (b"/1 1 set maxspeed 3277\n", b"@01 1 OK IDLE -- 0\r\n"),
            (b"/1 1 set accel 1638\n", b"@01 1 OK IDLE -- 0\r\n"),
            (b"/1 1 move abs 3000\n", b"@01 1 OK BUSY -- 0\r\n"),
            (b"/1 1 get pos\n", b"@01 1 OK BUSY -- 1500\r\n"),
            (b"/1 1 get pos\n", b"!01 1 IDLE --\r\n@01 1 OK IDLE -- 3000\r\n"),
    ]) as z:
        z.set_soft_limits(0.0, 25.0)
        assert z.move_to(3.0, velocity_mm_s=2.0, acceleration_mm_s2=10.0, timeout_s=0.5) == 3.0
    assert [p for _, p, _ in z.samples] == [1500, 3000]
    # each poll is placed within its own round trip
    assert all(u >= 0 for _, _, u in z.samples)
    assert z.alerts == ["!01 1 IDLE --"]


def test_zaber_rejection_is_device_error():
    with expected_protocol(zaber, [(b"/1 1 move abs 999999\n",
                                    b"@01 1 RJ IDLE -- BADDATA\r\n")]) as z:
        with pytest.raises(DeviceError, match="BADDATA"):
            z.start_move(999.999)


def test_zaber_fault_flag_is_device_fault():
    with expected_protocol(zaber, [(b"/1 1 get pos\n", b"@01 1 OK IDLE FS 1234\r\n")]) as z:
        with pytest.raises(DeviceFault, match="FS"):
            z.state()


def test_zaber_reply_for_another_axis_is_protocol_error():
    with expected_protocol(zaber, [(b"/1 1 get pos\n", b"@02 1 OK IDLE -- 5\r\n")]) as z:
        with pytest.raises(ProtocolError, match="does not answer"):
            z.state()


def test_zaber_message_ids_and_checksums_exact_bytes():
    # '1 1 0 get pos' sums to 932 = 0xA4 (mod 256) -> checksum 0x5C
    with expected_protocol(lambda t: zaber(t, message_ids=True), [
            (b"/1 1 0 get pos:5C\n", b"@01 1 0 OK IDLE -- 10:0B\r\n"),
            (b"/1 1 1 stop:47\n", b"@01 1 1 OK IDLE -- 0:3B\r\n"),
    ]) as z:
        z.enable_checksums()
        assert z.state().position == 0.01
        z.command("stop")


def test_zaber_warnings_list():
    with expected_protocol(zaber, [(b"/1 1 warnings\n", b"@01 1 OK IDLE FS 02 FS WR\r\n")]) as z:
        assert z.warnings() == ["FS", "WR"]


@pytest.mark.parametrize("line", [
    "@01 1 OK IDLE -- 0", "@01 0 OK IDLE WR 50081", "@01 1 12 RJ IDLE -- BADCOMMAND",
    "@10 2 OK BUSY FS 3"])
def test_zaber_parse_reply_accepts(line):
    r = parse_reply(line)
    assert r.ok == (" OK " in line) and r.busy == (" BUSY " in line)


@pytest.mark.parametrize("line", ["@1 1 OK IDLE -- 0", "@01 1 OK WAIT -- 0", "#01 1 hello",
                                  "@01 1 OK IDLE -- ", "01 1 OK IDLE -- 0"])
def test_zaber_parse_reply_rejects(line):
    with pytest.raises(ProtocolError):
        parse_reply(line)


# -- checksums ---------------------------------------------------------------------------
@pytest.mark.parametrize("body", ["/1 1 move abs 10000", "@01 1 OK IDLE -- 0", "/1 0 get deviceid"])
def test_zaber_checksum_makes_message_sum_to_zero(body):
    # the defining property (Zaber manual): bytes after the type character, plus the
    # checksum, sum to 0 modulo 256
    wire = ZaberChecksum().append(body)
    value = int(wire[-2:], 16)
    assert (sum(body[1:].encode()) + value) % 256 == 0
    assert ZaberChecksum().strip(wire) == body


def test_zaber_checksum_known_value():
    # '1 1 move abs 10000' sums to 1216 = 0xC0 (mod 256); two's complement 0x40
    assert ZaberChecksum().append("/1 1 move abs 10000") == "/1 1 move abs 10000:40"


@pytest.mark.parametrize("text", ["OK STATE 1 2 3 4 5", "EV OPEN 4294967295 -12"])
def test_xor_checksum_round_trip_and_detects_single_byte_error(text):
    wire = XorChecksum().append(text)
    assert XorChecksum().strip(wire) == text
    corrupted = wire.replace(text[-1], chr(ord(text[-1]) ^ 0x01), 1)
    with pytest.raises(ProtocolError):
        XorChecksum().strip(corrupted)
