// rgbcw_controller.ino — reference firmware for the `rgbcw-text/1` protocol
// (docs/protocols/rgbcw-text.md), driven by spectral-rig's `rgbcw-serial` driver.
//
// Hardware: any Arduino-compatible board with five PWM pins (Uno/Nano, RP2040 Pico,
// ESP32, SAMD21). Each pin drives a constant-current LED driver or a logic-level MOSFET
// for one LED channel of an RGBCW strip or bulb module (r, g, b, cool white, warm white).
// Drive the LEDs through a constant-current driver if you want stable spectra: PWM keeps
// the LED's spectrum fixed while its average power scales linearly with the duty cycle.
//
// Serial: 115200 baud 8N1, ASCII lines ending in '\n' ('\r' ignored).
//   ID?                     -> ID model=rig-rgbcw fw=1.0.0 serial=<id> channels=r,g,b,c,w pwm_bits=<n>
//   SET r=0.5 c=1 ...       -> OK        (channels not named go to 0; all or nothing)
//   OFF                     -> OK
//   GET?                    -> LEVELS r=0.5000 g=0.0000 b=0.0000 c=1.0000 w=0.0000
//   anything wrong          -> ERR <reason>
// The board prints READY once after reset. The Python twin of this sketch is
// drivers/lights/rgbcw_emulator.py; keep the two in step.

#include <Arduino.h>
#include <stdlib.h>
#include <string.h>

#define FIRMWARE "1.0.0"
#define MODEL "rig-rgbcw"
#ifndef SERIAL_ID
#define SERIAL_ID "RGBCW0001"  // give each board its own; it is recorded with every capture
#endif
#define MAX_LINE 120

#if defined(ARDUINO_ARCH_AVR)
  #define PWM_BITS 8
#else
  #define PWM_BITS 12  // RP2040, ESP32 (core >= 3), SAMD support analogWriteResolution
#endif
const long PWM_MAX = (1L << PWM_BITS) - 1;

const int N_CHANNELS = 5;
const char *NAMES[N_CHANNELS] = {"r", "g", "b", "c", "w"};
const int PINS[N_CHANNELS] = {3, 5, 6, 9, 10};  // PWM-capable pins on an Uno; change for your board
long duty[N_CHANNELS];                          // PWM counts now applied

char line[MAX_LINE + 1];
int lineLength = 0;
bool overflow = false;

void apply() {
  for (int i = 0; i < N_CHANNELS; i++) {
    analogWrite(PINS[i], duty[i]);
  }
}

int channelIndex(const char *name) {
  for (int i = 0; i < N_CHANNELS; i++) {
    if (strcmp(name, NAMES[i]) == 0) return i;
  }
  return -1;
}

// Parses "name=value name=value ..." into newDuty; on error prints ERR and returns false,
// leaving the outputs untouched.
bool parseSet(char *args, long *newDuty) {
  for (int i = 0; i < N_CHANNELS; i++) newDuty[i] = 0;
  for (char *word = strtok(args, " "); word != NULL; word = strtok(NULL, " ")) {
    char *eq = strchr(word, '=');
    if (eq == NULL) {
      Serial.print("ERR unknown channel ");
      Serial.println(word);
      return false;
    }
    *eq = '\0';
    const char *valueText = eq + 1;
    int index = channelIndex(word);
    if (index < 0) {
      Serial.print("ERR unknown channel ");
      Serial.println(word);
      return false;
    }
    char *end;
    double level = strtod(valueText, &end);
    if (end == valueText || *end != '\0') {
      Serial.print("ERR bad value ");
      Serial.println(valueText);
      return false;
    }
    if (level < 0.0 || level > 1.0) {
      Serial.print("ERR out of range ");
      Serial.print(word);
      Serial.print("=");
      Serial.println(valueText);
      return false;
    }
    newDuty[index] = (long)(level * PWM_MAX + 0.5);
  }
  return true;
}

void handleLine(char *text) {
  if (text[0] == '\0') return;
  char *args = strchr(text, ' ');
  if (args != NULL) *args++ = '\0';
  else args = text + strlen(text);

  if (strcmp(text, "ID?") == 0) {
    Serial.print("ID model=" MODEL " fw=" FIRMWARE " serial=" SERIAL_ID " channels=");
    for (int i = 0; i < N_CHANNELS; i++) {
      if (i) Serial.print(",");
      Serial.print(NAMES[i]);
    }
    Serial.print(" pwm_bits=");
    Serial.println(PWM_BITS);
  } else if (strcmp(text, "OFF") == 0) {
    for (int i = 0; i < N_CHANNELS; i++) duty[i] = 0;
    apply();
    Serial.println("OK");
  } else if (strcmp(text, "GET?") == 0) {
    Serial.print("LEVELS");
    for (int i = 0; i < N_CHANNELS; i++) {
      Serial.print(" ");
      Serial.print(NAMES[i]);
      Serial.print("=");
      Serial.print((double)duty[i] / PWM_MAX, 4);
    }
    Serial.println();
  } else if (strcmp(text, "SET") == 0) {
    long newDuty[N_CHANNELS];
    if (parseSet(args, newDuty)) {
      for (int i = 0; i < N_CHANNELS; i++) duty[i] = newDuty[i];
      apply();
      Serial.println("OK");
    }
  } else {
    Serial.print("ERR unknown command ");
    Serial.println(text);
  }
}

void setup() {
#if PWM_BITS != 8
  analogWriteResolution(PWM_BITS);
#endif
  for (int i = 0; i < N_CHANNELS; i++) {
    pinMode(PINS[i], OUTPUT);
    duty[i] = 0;
  }
  apply();  // LEDs off at power-up, whatever the host does
  Serial.begin(115200);
  Serial.println("READY");
}

void loop() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\r') continue;
    if (c == '\n') {
      line[lineLength] = '\0';
      if (overflow) Serial.println("ERR line too long");
      else handleLine(line);
      lineLength = 0;
      overflow = false;
    } else if (lineLength < MAX_LINE) {
      line[lineLength++] = c;
    } else {
      overflow = true;
    }
  }
}
