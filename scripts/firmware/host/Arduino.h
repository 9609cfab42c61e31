// Host (Linux) stand-in for the parts of the Arduino core the sweep sketch uses, so the
// sketch's own code can run on a PC against the Python driver (see host_main.cpp).
// Not a general Arduino emulator: pins are recorded, time is CLOCK_MONOTONIC, Serial is
// file descriptor 0 (the master side of a pty).
#ifndef MITSWEEP_HOST_ARDUINO_H
#define MITSWEEP_HOST_ARDUINO_H

#include <algorithm>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define HIGH 1
#define LOW 0
#define INPUT 0
#define OUTPUT 1
#define INPUT_PULLUP 2

using std::max;
using std::min;

void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t value);
int digitalRead(uint8_t pin);
unsigned long micros();  // wraps at 2^32 like the AVR's
void delayMicroseconds(unsigned int us);

class HostSerial {
 public:
  void begin(long baud);
  int available();
  int read();
  void print(const char *s);
  void print(char c);
};
extern HostSerial Serial;

void setup();
void loop();

#endif
