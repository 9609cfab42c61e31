// mitsweep-sweep: focal-sweep controller for an Arduino Uno (ATmega328P, 16 MHz).
//
// Drives a stepper (STEP/DIR/ENABLE into a stepper driver such as an A4988 or DRV8825,
// a normally-open home switch to GND at the negative end) and an optocoupler across the
// camera's remote-release lines (bulb mode: shutter open while the opto conducts).
// Speaks the line protocol documented in mitsweep/rig/arduino.py at 115200 baud, 8N1,
// lines ending in '\n'. Positions are steps, rates steps/s, accelerations steps/s^2,
// times micros() (32-bit, wraps every ~71.6 min; the host unwraps).
//
//   ID                                  -> OK ID mitsweep-sweep <fw> <protocol>
//   STATE                               -> OK STATE <t> <pos> <homed> <moving> <shutter>
//   CHK 0|1                             -> OK CHK <0|1>  (1: every line ends in *HH, XOR)
//   LIMITS <min> <max>                  -> OK LIMITS <min> <max>
//   HOME <rate>                         -> OK HOME; EV HOMED <t> 0
//   MOVE <target> <rate> <accel>        -> OK MOVE; EV DONE <t> <pos>
//   SWEEP <target> <rate> <accel> <open> <close>
//                                       -> OK SWEEP; EV START/OPEN/POS.../CLOSE/DONE
//   TABLE <n>                           -> OK TABLE <n>  (a step-rate table follows)
//   SEG <i> <steps> <duration_us>       -> OK SEG <i> <total_steps> <total_us>
//   TSWEEP <target> <accel> <open> <close>
//                                       -> OK TSWEEP; EV START/OPEN/POS.../CLOSE/DONE
//   SHUTTER <delay_us> <duration_us>    -> OK SHUTTER <t>; EV OPEN <t> <pos>; EV CLOSE ...
//   CLOSE                               -> OK CLOSE
//   STOP                                -> OK STOP <t> <pos> (shutter released first)
//   WATCHDOG <ms>                       -> OK WATCHDOG <ms>  (0 = off, the default)
//   PING                                -> OK PING <t>  (heartbeat; any line counts)
//   errors: ERR <SYNTAX|RANGE|LIMIT|BUSY|HOME|CHECKSUM> <text>
//   faults: EV FAULT <t> <pos> <HOME_SWITCH|LIMIT|WATCHDOG>  (shutter released, motor
//           stopped)
//
// Safety: the shutter is released and the motor stopped on STOP, on any fault, and when
// the home switch closes during any move other than homing. Targets outside the soft
// limits are refused; motion is refused until homed. Watchdog: with WATCHDOG <ms> set,
// a host silent for <ms> while the motor runs or a SHUTTER exposure is pending or open
// (a killed or crashed host cannot stop anything) is a WATCHDOG fault.
//
// Table sweep (TSWEEP): ramp at <accel> to the first segment's rate, cruise to <open>
// (shutter opens on that step), run the table -- segment k's steps evenly spread over
// its duration, timed from the open step in whole microseconds (Bresenham: no drift) --
// close the shutter on its last step (<close> = <open> +- the table's steps), cruise at
// the last segment's rate and ramp down to rest at <target>.

#include <Arduino.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define FW_NAME "mitsweep-sweep"
#define FW_VERSION "1.2"
#define PROTOCOL_VERSION 3

// Pins (change to match the wiring).
const uint8_t PIN_STEP = 2;
const uint8_t PIN_DIR = 3;
const uint8_t PIN_ENABLE = 4;   // active low
const uint8_t PIN_HOME = 5;     // switch to GND, internal pull-up: LOW = at home
const uint8_t PIN_SHUTTER = 6;  // opto LED (through its resistor): HIGH = shutter open
const uint8_t PIN_LED = 13;     // mirrors the shutter

const long MAX_STEP_RATE = 4000;          // steps/s the polling loop generates reliably
const uint32_t POS_PERIOD_US = 50000UL;   // EV POS period during a sweep
const long MAX_HOME_STEPS = 2000000L;     // give up homing after this many steps
const uint8_t LINE_MAX = 80;
const long MAX_WATCHDOG_MS = 600000L;     // longest watchdog timeout accepted
const uint8_t MAX_TABLE_SEGMENTS = 64;    // step-rate table: 6 bytes a segment (SRAM)
const long MAX_SEGMENT_STEPS = 65535L;

enum Mode { IDLE, MOVING, SWEEPING, HOMING, TABLE_SWEEPING };
enum TablePhase { BEFORE_OPEN, IN_TABLE, AFTER_CLOSE };

static Mode mode = IDLE;
static long pos = 0;
static bool homed = false;
static bool limitsSet = false;
static long limLo = 0, limHi = 0;
static bool checksums = false;

// current move
static long moveStart = 0, moveTarget = 0, moveLength = 0, moveDone = 0;
static int8_t moveDir = 1;
static float moveRate = 0, moveAccel = 0;
static uint32_t nextStepUs = 0;
static uint32_t lastPosEventUs = 0;
static long openAt = 0, closeAt = 0;

// step-rate table (TABLE/SEG) and its execution (TSWEEP)
static uint16_t tabSteps[MAX_TABLE_SEGMENTS];
static uint32_t tabUs[MAX_TABLE_SEGMENTS];
static uint8_t tabLen = 0, tabLoaded = 0;   // announced, received
static long tabTotalSteps = 0;
static uint32_t tabTotalUs = 0;
static uint8_t tabPhase = BEFORE_OPEN;
static uint8_t seg = 0;                    // segment of the next table step
static uint16_t segDone = 0;               // its steps scheduled so far
static uint32_t segStartOff = 0, segOff = 0, segQ = 0, segR = 0, segAcc = 0;
static uint32_t tableOriginUs = 0;         // when the open step was due

// shutter
static bool shutterOpen = false;
static bool shutterTimed = false;      // SHUTTER command pending / running
static uint32_t shutterOpenUs = 0, shutterCloseUs = 0;
static bool shutterOpened = false;

// watchdog: 0 = off; lastRxUs = when the last whole line came from the host
static uint32_t watchdogUs = 0;
static uint32_t lastRxUs = 0;

static char line[LINE_MAX + 1];
static uint8_t lineLen = 0;
static bool lineOverflow = false;

// ---------------------------------------------------------------------------------------
// output

static uint8_t xorOf(const char *s) {
  uint8_t x = 0;
  while (*s) x ^= (uint8_t)*s++;
  return x;
}

static void sendLine(const char *text) {
  Serial.print(text);
  if (checksums) {
    char tail[4];
    uint8_t x = xorOf(text);
    const char *hex = "0123456789ABCDEF";
    tail[0] = '*';
    tail[1] = hex[x >> 4];
    tail[2] = hex[x & 0x0F];
    tail[3] = 0;
    Serial.print(tail);
  }
  Serial.print('\n');
}

static void sendEvent(const char *name, uint32_t t, long p, const char *detail) {
  char buf[64];
  if (detail && *detail) {
    snprintf(buf, sizeof buf, "EV %s %lu %ld %s", name, (unsigned long)t, p, detail);
  } else {
    snprintf(buf, sizeof buf, "EV %s %lu %ld", name, (unsigned long)t, p);
  }
  sendLine(buf);
}

static void sendErr(const char *code, const char *text) {
  char buf[64];
  snprintf(buf, sizeof buf, "ERR %s %s", code, text);
  sendLine(buf);
}

// ---------------------------------------------------------------------------------------
// shutter and motor

static void shutterWrite(bool open) {
  digitalWrite(PIN_SHUTTER, open ? HIGH : LOW);
  digitalWrite(PIN_LED, open ? HIGH : LOW);
  shutterOpen = open;
}

static void releaseShutter() {
  shutterWrite(false);
  shutterTimed = false;
}

static void stopMotor() {
  mode = IDLE;
}

static void fault(const char *code) {
  uint32_t t = micros();
  releaseShutter();   // shutter first
  stopMotor();
  sendEvent("FAULT", t, pos, code);
}

static void startMove(long target, long rate, long accel, Mode m) {
  moveStart = pos;
  moveTarget = target;
  moveDir = (target >= pos) ? 1 : -1;
  moveLength = labs(target - pos);
  moveDone = 0;
  moveRate = (float)rate;
  moveAccel = (float)accel;
  digitalWrite(PIN_DIR, moveDir > 0 ? HIGH : LOW);
  nextStepUs = micros();
  lastPosEventUs = nextStepUs;
  mode = m;
}

// Step interval (µs) for the next step: constant acceleration from rest, cruise at
// moveRate, constant deceleration to rest at the target (v = sqrt(2 a d)).
static float stepIntervalUs() {
  float dStart = (float)moveDone + 0.5f;
  float v = sqrtf(2.0f * moveAccel * dStart);
  if (mode != HOMING) {
    float dEnd = (float)(moveLength - moveDone) - 0.5f;
    if (dEnd < 0.5f) dEnd = 0.5f;
    float vEnd = sqrtf(2.0f * moveAccel * dEnd);
    if (vEnd < v) v = vEnd;
  }
  if (v > moveRate) v = moveRate;
  return 1e6f / v;
}

// Table: set up segment `seg` (skipping dwells, which only take their time).
static void tableSegmentStart() {
  while (seg < tabLen && tabSteps[seg] == 0) segStartOff += tabUs[seg++];
  segDone = 0;
  segOff = segStartOff;
  segAcc = 0;
  if (seg < tabLen) {
    segQ = tabUs[seg] / tabSteps[seg];
    segR = tabUs[seg] % tabSteps[seg];
  }
}

// Offset (µs from the open step) of the next table step: floor(j * D / n) for the
// j-th step of a segment of n steps over D µs.
static uint32_t tableNextOffset() {
  if (segDone >= tabSteps[seg]) {
    segStartOff += tabUs[seg++];
    tableSegmentStart();
  }
  segOff += segQ;
  segAcc += segR;
  if (segAcc >= tabSteps[seg]) {
    segOff++;
    segAcc -= tabSteps[seg];
  }
  segDone++;
  return segOff;
}

static void stepOnce(uint32_t now, uint32_t due) {
  digitalWrite(PIN_STEP, HIGH);
  delayMicroseconds(2);
  digitalWrite(PIN_STEP, LOW);
  pos += moveDir;
  moveDone++;
  if (mode == TABLE_SWEEPING) {
    if (tabPhase == BEFORE_OPEN && pos == openAt) {
      shutterWrite(true);
      sendEvent("OPEN", now, pos, "");
      tabPhase = IN_TABLE;
      tableOriginUs = due;   // the table is timed from when this step was due
      seg = 0;
      segStartOff = 0;
      tableSegmentStart();
    } else if (tabPhase == IN_TABLE && pos == closeAt) {
      shutterWrite(false);
      sendEvent("CLOSE", now, pos, "");
      tabPhase = AFTER_CLOSE;
      moveRate = (float)tabSteps[tabLen - 1] * 1e6f / (float)tabUs[tabLen - 1];
    }
  } else if (mode == SWEEPING) {
    if (pos == openAt) {
      shutterWrite(true);
      sendEvent("OPEN", now, pos, "");
    } else if (pos == closeAt) {
      shutterWrite(false);
      sendEvent("CLOSE", now, pos, "");
    }
  }
}

static void runMotion() {
  if (mode == IDLE) return;
  uint32_t now = micros();
  // the home switch closing while a move still has steps to go toward it: a lost
  // reference or a bad limit; stop (arriving exactly at 0 is fine)
  if (mode != HOMING && homed && moveDir < 0 && moveDone < moveLength && pos <= 0 &&
      digitalRead(PIN_HOME) == LOW) {
    fault("LIMIT");
    return;
  }
  if (mode == HOMING) {
    if (digitalRead(PIN_HOME) == LOW) {
      pos = 0;
      homed = true;
      mode = IDLE;
      sendEvent("HOMED", now, 0, "");
      return;
    }
    if (moveDone >= MAX_HOME_STEPS) {
      fault("HOME_SWITCH");
      return;
    }
  }
  if ((int32_t)(now - nextStepUs) < 0) return;
  if (mode != HOMING && moveDone >= moveLength) {
    mode = IDLE;
    sendEvent("DONE", now, pos, "");
    return;
  }
  uint32_t due = nextStepUs;
  stepOnce(now, due);
  if (mode == TABLE_SWEEPING && tabPhase == IN_TABLE) {
    nextStepUs = tableOriginUs + tableNextOffset();
  } else {
    nextStepUs += (uint32_t)(stepIntervalUs() + 0.5f);
  }
  if ((mode == SWEEPING || mode == TABLE_SWEEPING) &&
      (uint32_t)(now - lastPosEventUs) >= POS_PERIOD_US) {
    lastPosEventUs += POS_PERIOD_US;
    sendEvent("POS", now, pos, "");
  }
}

static void runShutter() {
  if (!shutterTimed) return;
  uint32_t now = micros();
  if (!shutterOpened && (int32_t)(now - shutterOpenUs) >= 0) {
    shutterWrite(true);
    shutterOpened = true;
    sendEvent("OPEN", now, pos, "");
  }
  if (shutterOpened && (int32_t)(now - shutterCloseUs) >= 0) {
    shutterWrite(false);
    shutterTimed = false;
    sendEvent("CLOSE", now, pos, "");
  }
}

static void runWatchdog() {
  if (watchdogUs == 0) return;
  if (mode == IDLE && !shutterTimed && !shutterOpen) return;  // nothing to guard
  if ((uint32_t)(micros() - lastRxUs) >= watchdogUs) fault("WATCHDOG");
}

// ---------------------------------------------------------------------------------------
// commands

static bool parseLongs(char *args, long *out, uint8_t n) {
  char *p = args;
  for (uint8_t i = 0; i < n; i++) {
    while (*p == ' ') p++;
    if (!*p) return false;
    char *end;
    out[i] = strtol(p, &end, 10);
    if (end == p || (*end != ' ' && *end != 0)) return false;
    p = end;
  }
  while (*p == ' ') p++;
  return *p == 0;
}

static bool checkMove(long target, long rate, long accel) {
  if (mode != IDLE) { sendErr("BUSY", "moving"); return false; }
  if (!homed) { sendErr("HOME", "not homed"); return false; }
  if (rate < 1 || rate > MAX_STEP_RATE || accel < 1) { sendErr("RANGE", "rate or accel"); return false; }
  if (!limitsSet || target < limLo || target > limHi) {
    sendErr("LIMIT", "target outside soft limits");
    return false;
  }
  return true;
}

static void handleLine(char *text) {
  char buf[64];
  if (checksums) {
    char *star = strrchr(text, '*');
    if (!star || strlen(star) != 3) { sendErr("CHECKSUM", "missing"); return; }
    uint8_t want = (uint8_t)strtol(star + 1, NULL, 16);
    *star = 0;
    if (xorOf(text) != want) { sendErr("CHECKSUM", "mismatch"); return; }
  }
  char *args = strchr(text, ' ');
  if (args) *args++ = 0; else args = text + strlen(text);
  long v[5];

  if (!strcmp(text, "ID")) {
    if (!parseLongs(args, v, 0)) { sendErr("SYNTAX", "ID"); return; }
    snprintf(buf, sizeof buf, "OK ID %s %s %d", FW_NAME, FW_VERSION, PROTOCOL_VERSION);
    sendLine(buf);
  } else if (!strcmp(text, "STATE")) {
    if (!parseLongs(args, v, 0)) { sendErr("SYNTAX", "STATE"); return; }
    snprintf(buf, sizeof buf, "OK STATE %lu %ld %d %d %d", (unsigned long)micros(), pos,
             homed ? 1 : 0, mode != IDLE ? 1 : 0, shutterOpen ? 1 : 0);
    sendLine(buf);
  } else if (!strcmp(text, "CHK")) {
    if (!parseLongs(args, v, 1)) { sendErr("SYNTAX", "CHK"); return; }
    checksums = v[0] != 0;
    sendLine(checksums ? "OK CHK 1" : "OK CHK 0");
  } else if (!strcmp(text, "LIMITS")) {
    if (!parseLongs(args, v, 2)) { sendErr("SYNTAX", "LIMITS"); return; }
    if (v[0] >= v[1]) { sendErr("RANGE", "min must be < max"); return; }
    limLo = v[0]; limHi = v[1]; limitsSet = true;
    snprintf(buf, sizeof buf, "OK LIMITS %ld %ld", limLo, limHi);
    sendLine(buf);
  } else if (!strcmp(text, "HOME")) {
    if (!parseLongs(args, v, 1)) { sendErr("SYNTAX", "HOME"); return; }
    if (mode != IDLE) { sendErr("BUSY", "moving"); return; }
    if (v[0] < 1 || v[0] > MAX_STEP_RATE) { sendErr("RANGE", "rate"); return; }
    sendLine("OK HOME");
    startMove(pos - MAX_HOME_STEPS, v[0], 4L * v[0], HOMING);
  } else if (!strcmp(text, "MOVE")) {
    if (!parseLongs(args, v, 3)) { sendErr("SYNTAX", "MOVE"); return; }
    if (!checkMove(v[0], v[1], v[2])) return;
    sendLine("OK MOVE");
    startMove(v[0], v[1], v[2], MOVING);
  } else if (!strcmp(text, "SWEEP")) {
    if (!parseLongs(args, v, 5)) { sendErr("SYNTAX", "SWEEP"); return; }
    if (!checkMove(v[0], v[1], v[2])) return;
    long length = labs(v[0] - pos);
    long ramp = (long)ceil((double)v[1] * (double)v[1] / (2.0 * (double)v[2]));
    long dOpen = labs(v[3] - pos), dClose = labs(v[4] - pos);
    long lo = min(pos, v[0]), hi = max(pos, v[0]);
    bool inside = v[3] >= lo && v[3] <= hi && v[4] >= lo && v[4] <= hi;
    if (!inside || ramp > dOpen || dOpen >= dClose || dClose > length - ramp) {
      sendErr("RANGE", "open/close outside the constant-velocity part");
      return;
    }
    sendLine("OK SWEEP");
    openAt = v[3]; closeAt = v[4];
    startMove(v[0], v[1], v[2], SWEEPING);
    sendEvent("START", nextStepUs, pos, "");
  } else if (!strcmp(text, "TABLE")) {
    if (!parseLongs(args, v, 1)) { sendErr("SYNTAX", "TABLE"); return; }
    if (mode != IDLE) { sendErr("BUSY", "moving"); return; }
    if (v[0] < 1 || v[0] > MAX_TABLE_SEGMENTS) { sendErr("RANGE", "table size"); return; }
    tabLen = (uint8_t)v[0];
    tabLoaded = 0;
    tabTotalSteps = 0;
    tabTotalUs = 0;
    snprintf(buf, sizeof buf, "OK TABLE %d", (int)tabLen);
    sendLine(buf);
  } else if (!strcmp(text, "SEG")) {
    if (!parseLongs(args, v, 3)) { sendErr("SYNTAX", "SEG"); return; }
    if (mode != IDLE) { sendErr("BUSY", "moving"); return; }
    if (v[0] != (long)tabLoaded || tabLoaded >= tabLen) { sendErr("RANGE", "segment order"); return; }
    // steps * 1e6 / us <= MAX_STEP_RATE steps/s, in integers (1e6 / 4000 = 250 µs)
    if (v[1] < 0 || v[1] > MAX_SEGMENT_STEPS || v[2] < 1 ||
        (uint32_t)v[1] * (uint32_t)(1000000L / MAX_STEP_RATE) > (uint32_t)v[2]) {
      sendErr("RANGE", "segment steps or duration");
      return;
    }
    tabSteps[tabLoaded] = (uint16_t)v[1];
    tabUs[tabLoaded] = (uint32_t)v[2];
    tabLoaded++;
    tabTotalSteps += v[1];
    tabTotalUs += (uint32_t)v[2];
    snprintf(buf, sizeof buf, "OK SEG %ld %ld %lu", v[0], tabTotalSteps,
             (unsigned long)tabTotalUs);
    sendLine(buf);
  } else if (!strcmp(text, "TSWEEP")) {
    if (!parseLongs(args, v, 4)) { sendErr("SYNTAX", "TSWEEP"); return; }
    if (tabLen == 0 || tabLoaded != tabLen || tabSteps[0] == 0 || tabSteps[tabLen - 1] == 0) {
      sendErr("RANGE", "no complete table");
      return;
    }
    float rateIn = (float)tabSteps[0] * 1e6f / (float)tabUs[0];
    if (!checkMove(v[0], (long)ceil(rateIn), v[1])) return;
    float rateOut = (float)tabSteps[tabLen - 1] * 1e6f / (float)tabUs[tabLen - 1];
    long rampIn = (long)ceil((double)rateIn * rateIn / (2.0 * (double)v[1]) - 1e-6);
    long rampOut = (long)ceil((double)rateOut * rateOut / (2.0 * (double)v[1]) - 1e-6);
    int8_t dir = (v[0] >= pos) ? 1 : -1;
    long dOpen = dir * (v[2] - pos), dClose = dir * (v[3] - pos), length = labs(v[0] - pos);
    if (dOpen < rampIn || dClose - dOpen != tabTotalSteps || dClose > length - rampOut) {
      sendErr("RANGE", "open/close do not fit the table and its ramps");
      return;
    }
    sendLine("OK TSWEEP");
    openAt = v[2]; closeAt = v[3];
    tabPhase = BEFORE_OPEN;
    startMove(v[0], 1, v[1], TABLE_SWEEPING);
    moveRate = rateIn;
    sendEvent("START", nextStepUs, pos, "");
  } else if (!strcmp(text, "SHUTTER")) {
    if (!parseLongs(args, v, 2)) { sendErr("SYNTAX", "SHUTTER"); return; }
    if (v[0] < 0 || v[1] < 1) { sendErr("RANGE", "delay or duration"); return; }
    uint32_t now = micros();
    shutterOpenUs = now + (uint32_t)v[0];
    shutterCloseUs = shutterOpenUs + (uint32_t)v[1];
    shutterOpened = false;
    shutterTimed = true;
    snprintf(buf, sizeof buf, "OK SHUTTER %lu", (unsigned long)now);
    sendLine(buf);
  } else if (!strcmp(text, "CLOSE")) {
    releaseShutter();
    sendLine("OK CLOSE");
  } else if (!strcmp(text, "STOP")) {
    releaseShutter();   // shutter first
    stopMotor();
    snprintf(buf, sizeof buf, "OK STOP %lu %ld", (unsigned long)micros(), pos);
    sendLine(buf);
  } else if (!strcmp(text, "WATCHDOG")) {
    if (!parseLongs(args, v, 1)) { sendErr("SYNTAX", "WATCHDOG"); return; }
    if (v[0] < 0 || v[0] > MAX_WATCHDOG_MS) { sendErr("RANGE", "watchdog ms"); return; }
    watchdogUs = (uint32_t)v[0] * 1000UL;
    snprintf(buf, sizeof buf, "OK WATCHDOG %ld", v[0]);
    sendLine(buf);
  } else if (!strcmp(text, "PING")) {
    if (!parseLongs(args, v, 0)) { sendErr("SYNTAX", "PING"); return; }
    snprintf(buf, sizeof buf, "OK PING %lu", (unsigned long)micros());
    sendLine(buf);
  } else {
    sendErr("SYNTAX", "unknown command");
  }
}

static void readSerial() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\r') continue;
    if (c == '\n') {
      lastRxUs = micros();   // any line feeds the watchdog
      line[lineLen] = 0;
      if (lineOverflow) sendErr("SYNTAX", "line too long");
      else if (lineLen > 0) handleLine(line);
      lineLen = 0;
      lineOverflow = false;
      return;  // one command per loop: keep stepping responsive
    }
    if (lineLen < LINE_MAX) line[lineLen++] = c;
    else lineOverflow = true;
  }
}

void setup() {
  pinMode(PIN_STEP, OUTPUT);
  pinMode(PIN_DIR, OUTPUT);
  pinMode(PIN_ENABLE, OUTPUT);
  pinMode(PIN_SHUTTER, OUTPUT);
  pinMode(PIN_LED, OUTPUT);
  pinMode(PIN_HOME, INPUT_PULLUP);
  shutterWrite(false);
  digitalWrite(PIN_ENABLE, LOW);
  Serial.begin(115200);
  char buf[48];
  snprintf(buf, sizeof buf, "READY %s %s %d", FW_NAME, FW_VERSION, PROTOCOL_VERSION);
  sendLine(buf);
}

void loop() {
  runMotion();
  runShutter();
  readSerial();
  runWatchdog();
}
