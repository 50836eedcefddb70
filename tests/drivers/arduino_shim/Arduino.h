// Host stand-in for the few Arduino APIs the reference firmware uses, so the sketch can be
// compiled with g++ and fed the same command lines as the Python emulator (test_firmware.py).
#pragma once
#include <cstdio>
#include <cstring>

#define OUTPUT 1
inline void pinMode(int, int) {}
inline void analogWrite(int, long) {}
inline void analogWriteResolution(int) {}

struct HostSerial {
  int pending = -2;  // -2: nothing peeked yet
  void begin(long) {}
  int available() {
    if (pending == -2) pending = std::getchar();
    return pending == EOF ? 0 : 1;
  }
  int read() {
    available();
    int c = pending;
    pending = -2;
    return c;
  }
  void print(const char *s) { std::fputs(s, stdout); }
  void print(char c) { std::putchar(c); }
  void print(int v) { std::printf("%d", v); }
  void print(long v) { std::printf("%ld", v); }
  void print(double v, int digits) { std::printf("%.*f", digits, v); }
  void println() { std::putchar('\n'); std::fflush(stdout); }
  template <typename T> void println(T v) { print(v); println(); }
};
inline HostSerial Serial;

void setup();
void loop();
int main() {
  setup();
  while (Serial.available()) loop();
  return 0;
}
