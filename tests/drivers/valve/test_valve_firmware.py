"""The Arduino sketch and the Python emulator answer byte streams identically.

The sketch is compiled for the host with a minimal stand-in for Arduino.h (time frozen
at 0, so the watchdog is out of scope here) and fed random streams of valid, invalid
and corrupted frames and garbage. Skipped where no C++ compiler is installed.
"""

from __future__ import annotations

import random
import shutil
import subprocess
from pathlib import Path

import pytest

from drivers.plant import StaticPlant
from drivers.valve.emulator import ValveEmulator
from drivers.valve.protocol import (
    AllOff,
    Arm,
    Frame,
    GetStatus,
    Ping,
    SetAll,
    SetDuty,
    encode_frame,
    encode_message,
)

SKETCH = Path(__file__).resolve().parents[3] / "drivers/valve/firmware/valve_controller.ino"

ARDUINO_H = """#pragma once
#include <stdint.h>
#include <string.h>
#include <stddef.h>
#define LOW 0
#define OUTPUT 1
unsigned long millis();
void digitalWrite(uint8_t, uint8_t);
void analogWrite(uint8_t, int);
void pinMode(uint8_t, uint8_t);
struct HostSerial {
  void begin(unsigned long);
  int available();
  int read();
  size_t write(const uint8_t *, size_t);
};
extern HostSerial Serial;
"""

HARNESS = """#include "Arduino.h"
#include <stdio.h>
#include <vector>
HostSerial Serial;
static std::vector<uint8_t> input;
static size_t cursor = 0;
unsigned long millis() { return 0; }
void digitalWrite(uint8_t, uint8_t) {}
void analogWrite(uint8_t, int) {}
void pinMode(uint8_t, uint8_t) {}
void HostSerial::begin(unsigned long) {}
int HostSerial::available() { return cursor < input.size(); }
int HostSerial::read() { return input[cursor++]; }
size_t HostSerial::write(const uint8_t *b, size_t n) { return fwrite(b, 1, n, stdout); }
#include "sketch.cpp"
int main() {
  int c;
  while ((c = getchar()) != EOF) input.push_back((uint8_t)c);
  setup();
  loop();
  return 0;
}
"""


@pytest.fixture(scope="module")
def firmware(tmp_path_factory: pytest.TempPathFactory) -> Path:
    compiler = shutil.which("g++") or shutil.which("clang++")
    if compiler is None:
        pytest.skip("no C++ compiler to build the sketch for the host")
    work = tmp_path_factory.mktemp("firmware")
    (work / "Arduino.h").write_text(ARDUINO_H)
    (work / "sketch.cpp").write_text(SKETCH.read_text())
    (work / "harness.cpp").write_text(HARNESS)
    exe = work / "valve_firmware"
    subprocess.run(
        [compiler, "-std=c++11", "-Wall", "-Werror", "-O1", f"-I{work}", str(work / "harness.cpp"), "-o", str(exe)],
        check=True, capture_output=True, timeout=120,
    )
    return exe


def random_stream(rng: random.Random) -> bytes:
    messages = [Ping(), Arm(), AllOff(), GetStatus(), SetDuty(1, 300), SetAll((1, 2, 3)), SetDuty(0, 1000)]
    stream = bytearray()
    for _ in range(rng.randint(1, 12)):
        r = rng.random()
        if r < 0.6:  # a request; small SEQ range so duplicates happen
            stream += encode_message(rng.randrange(4), rng.choice(messages))
        elif r < 0.8:  # well-framed but possibly invalid: bad length, value, command
            command = rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 0x42, 0x80, 0x81])
            payload = bytes(rng.randrange(256) for _ in range(rng.randint(0, 7)))
            stream += encode_frame(Frame(rng.randrange(4), command, payload))
        else:  # garbage rich in false SOFs
            stream += bytes(rng.choice([0xA5, rng.randrange(256)]) for _ in range(rng.randint(1, 6)))
    if rng.random() < 0.3:
        stream[rng.randrange(len(stream))] ^= rng.randrange(1, 256)
    return bytes(stream)


def test_sketch_and_emulator_reply_identically(firmware: Path) -> None:
    rng = random.Random(20240601)
    for _ in range(200):
        stream = random_stream(rng)
        expected = ValveEmulator(StaticPlant(), clock=lambda: 0.0).receive(stream)
        got = subprocess.run([str(firmware)], input=stream, capture_output=True, timeout=10, check=True).stdout
        assert got == expected, f"stream {stream.hex(' ')}"
