// Runs the sweep sketch on a PC: Serial on fd 0 (a pty master), a simulated stepper
// axis driven by the sketch's STEP/DIR pins with a home switch at position <= 0, and a
// trace of the shutter pin. Opening the port (the host flushing the pty, seen in packet
// mode) re-executes the program, like an Uno's reset on DTR; the axis keeps its
// physical position across the reset. The program outlives a host that dies while
// another process keeps the pty's slave open (as the tests do), like a board on its own
// supply: its watchdog (WATCHDOG <ms>) then stops the axis and releases the shutter.
//
// Environment: MITSWEEP_FW_START_STEPS (axis position at start, steps, default 400),
// MITSWEEP_FW_TRACE (file to append "<micros> <pin> <value> <axis> <monotonic_us>" pin
// changes to; the last is CLOCK_MONOTONIC, the clock of Python's time.monotonic()).
#include "Arduino.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

HostSerial Serial;

static const uint8_t STEP_PIN = 2, DIR_PIN = 3, HOME_PIN = 5;
static long axis = 400;
static uint8_t pins[32];
static uint8_t modes[32];
static FILE *trace = NULL;
static struct timespec t0;
static char **self_argv;
static unsigned char rx[256];
static int rx_len = 0, rx_pos = 0;

unsigned long micros() {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  uint64_t us = (uint64_t)(t.tv_sec - t0.tv_sec) * 1000000ULL +
                (uint64_t)((t.tv_nsec - t0.tv_nsec) / 1000);
  return (unsigned long)(uint32_t)us;
}

void delayMicroseconds(unsigned int us) { (void)us; }

void pinMode(uint8_t pin, uint8_t mode) { modes[pin & 31] = mode; }

void digitalWrite(uint8_t pin, uint8_t value) {
  pin &= 31;
  if (pin == STEP_PIN && value == HIGH && pins[STEP_PIN] == LOW) {
    axis += pins[DIR_PIN] ? 1 : -1;
  }
  if (pins[pin] != value && trace && pin != STEP_PIN) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    fprintf(trace, "%lu %u %u %ld %lld\n", micros(), pin, value, axis,
            (long long)now.tv_sec * 1000000LL + now.tv_nsec / 1000);
    fflush(trace);
  }
  pins[pin] = value;
}

int digitalRead(uint8_t pin) {
  if ((pin & 31) == HOME_PIN) return axis <= 0 ? LOW : HIGH;
  return pins[pin & 31];
}

static void reset_board() {
  char buf[32];
  snprintf(buf, sizeof buf, "%ld", axis);
  setenv("MITSWEEP_FW_START_STEPS", buf, 1);
  if (trace) fclose(trace);
  execv("/proc/self/exe", self_argv);
  _exit(3);
}

static void fill() {
  if (rx_pos < rx_len) return;
  struct pollfd p = {0, POLLIN, 0};
  if (poll(&p, 1, 0) <= 0) return;
  unsigned char buf[257];
  ssize_t n = ::read(0, buf, sizeof buf);
  if (n <= 0) {
    if (n == 0 || (errno != EAGAIN && errno != EINTR)) exit(0);  // port closed
    return;
  }
  if (buf[0] != 0) {  // packet-mode control byte
    if (buf[0] & TIOCPKT_FLUSHREAD) reset_board();
    return;
  }
  memcpy(rx, buf + 1, (size_t)(n - 1));
  rx_len = (int)(n - 1);
  rx_pos = 0;
}

void HostSerial::begin(long baud) { (void)baud; }

int HostSerial::available() {
  fill();
  return rx_len - rx_pos;
}

int HostSerial::read() {
  fill();
  return rx_pos < rx_len ? rx[rx_pos++] : -1;
}

void HostSerial::print(const char *s) {
  size_t n = strlen(s);
  while (n > 0) {
    ssize_t w = ::write(1, s, n);
    if (w < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      exit(0);
    }
    s += w;
    n -= (size_t)w;
  }
}

void HostSerial::print(char c) {
  char s[2] = {c, 0};
  print(s);
}

int main(int argc, char **argv) {
  (void)argc;
  self_argv = argv;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  const char *start = getenv("MITSWEEP_FW_START_STEPS");
  if (start) axis = atol(start);
  const char *path = getenv("MITSWEEP_FW_TRACE");
  if (path) trace = fopen(path, "a");
  int one = 1;
  ioctl(0, TIOCPKT, &one);
  setup();
  for (;;) {
    loop();
    // yield the CPU briefly: the sketch's step schedule is absolute (nextStepUs), so
    // this adds jitter to when steps happen, not drift to the rate
    struct timespec nap = {0, 20000};
    nanosleep(&nap, NULL);
  }
}
