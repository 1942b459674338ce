// HydroJet valve controller firmware 1.0 (Arduino Uno / Nano, ATmega328P).
//
// Drives three solenoid valves (one per water jet) with PWM and speaks the framed
// protocol documented in drivers/valve/protocol.py; drivers/valve/emulator.py is the
// same state machine in Python and the two must stay byte-for-byte identical.
//
// Frame: SOF 0xA5 | LEN u8 (0..16) | SEQ u8 | CMD u8 | PAYLOAD | CRC16 (big-endian)
// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor) over
// LEN..PAYLOAD. Resync by length + CRC: on a bad LEN or CRC drop the SOF byte only.
// One ACK (0x80) or NAK (0x81) per valid frame, echoing SEQ. Watchdog: while armed, no
// valid frame for WATCHDOG_MS closes every valve, disarms and latches FAULT_WATCHDOG
// until ARM. The last frame and its reply are cached: an identical frame (a host retry)
// gets the cached reply and is not executed again; a watchdog trip clears the cache.
//
// Outputs: pins 9, 10, 11 drive the valves' MOSFET gates (analogWrite, ~490 Hz on 9/10
// and 11 on a Uno); a duty of 0 per mille writes the pin LOW (fully closed).
// tests/drivers/valve/test_valve_firmware.py builds this file for the host (with a stub
// Arduino.h) and checks it answers byte streams exactly as the Python emulator does.

#include <Arduino.h>

// ---- protocol constants (protocol.py) ------------------------------------------
static const uint8_t SOF = 0xA5;
static const uint8_t MAX_PAYLOAD = 16;
static const uint8_t HEADER_LEN = 4;  // SOF, LEN, SEQ, CMD
static const uint8_t CRC_LEN = 2;
static const uint8_t VALVE_COUNT = 3;
static const uint16_t DUTY_MAX_PERMILLE = 1000;
static const uint8_t FW_MAJOR = 1;
static const uint8_t FW_MINOR = 0;

static const uint8_t CMD_PING = 0x01;
static const uint8_t CMD_ARM = 0x02;
static const uint8_t CMD_SET_DUTY = 0x03;
static const uint8_t CMD_SET_ALL = 0x04;
static const uint8_t CMD_ALL_OFF = 0x05;
static const uint8_t CMD_STATUS = 0x06;
static const uint8_t CMD_ACK = 0x80;
static const uint8_t CMD_NAK = 0x81;

static const uint8_t NAK_BAD_LENGTH = 0x01;
static const uint8_t NAK_UNKNOWN_COMMAND = 0x02;
static const uint8_t NAK_BAD_VALUE = 0x03;
static const uint8_t NAK_NOT_ARMED = 0x04;
static const uint8_t NAK_WATCHDOG = 0x05;

static const uint8_t STATE_ARMED = 0x01;
static const uint8_t FAULT_WATCHDOG = 0x01;

// ---- configuration --------------------------------------------------------------
#ifndef WATCHDOG_MS
#define WATCHDOG_MS 500  // protocol.DEFAULT_WATCHDOG_MS; must be 1..65535
#endif
static const uint32_t BAUD = 115200;
static const uint8_t VALVE_PINS[VALVE_COUNT] = {9, 10, 11};

// ---- state ----------------------------------------------------------------------
static uint16_t duties[VALVE_COUNT] = {0, 0, 0};
static bool armed = false;
static uint8_t faults = 0;
static uint32_t lastValidMs = 0;
static uint16_t rxErrors = 0;

static uint8_t rxBuf[HEADER_LEN + MAX_PAYLOAD + CRC_LEN];
static uint8_t rxLen = 0;

static bool haveLastFrame = false;
static uint8_t lastFrame[HEADER_LEN + MAX_PAYLOAD + CRC_LEN];
static uint8_t lastFrameLen = 0;
static uint8_t lastReply[HEADER_LEN + MAX_PAYLOAD + CRC_LEN];
static uint8_t lastReplyLen = 0;

uint16_t crc16CcittFalse(const uint8_t *data, uint8_t len) {
  uint16_t crc = 0xFFFF;
  for (uint8_t i = 0; i < len; i++) {
    crc ^= (uint16_t)data[i] << 8;
    for (uint8_t b = 0; b < 8; b++) {
      crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
  }
  return crc;
}

void applyDuties(const uint16_t *newDuties) {
  for (uint8_t i = 0; i < VALVE_COUNT; i++) {
    duties[i] = newDuties[i];
    if (duties[i] == 0) {
      digitalWrite(VALVE_PINS[i], LOW);
    } else {
      analogWrite(VALVE_PINS[i], (uint8_t)(((uint32_t)duties[i] * 255UL + 500UL) / 1000UL));
    }
  }
}

void closeAll() {
  static const uint16_t zeros[VALVE_COUNT] = {0, 0, 0};
  applyDuties(zeros);
}

// Build a reply frame into lastReply and send it.
void sendReply(uint8_t seq, uint8_t cmd, const uint8_t *payload, uint8_t len) {
  lastReply[0] = SOF;
  lastReply[1] = len;
  lastReply[2] = seq;
  lastReply[3] = cmd;
  for (uint8_t i = 0; i < len; i++) lastReply[HEADER_LEN + i] = payload[i];
  uint16_t crc = crc16CcittFalse(&lastReply[1], 3 + len);
  lastReply[HEADER_LEN + len] = (uint8_t)(crc >> 8);
  lastReply[HEADER_LEN + len + 1] = (uint8_t)(crc & 0xFF);
  lastReplyLen = HEADER_LEN + len + CRC_LEN;
  Serial.write(lastReply, lastReplyLen);
}

void ack(uint8_t seq, uint8_t cmd, const uint8_t *data, uint8_t len) {
  uint8_t payload[MAX_PAYLOAD];
  payload[0] = cmd;
  for (uint8_t i = 0; i < len; i++) payload[1 + i] = data[i];
  sendReply(seq, CMD_ACK, payload, 1 + len);
}

void nak(uint8_t seq, uint8_t cmd, uint8_t code) {
  uint8_t payload[2] = {cmd, code};
  sendReply(seq, CMD_NAK, payload, 2);
}

// Same order of checks as the emulator: length, value, then armed/fault state.
void execute(uint8_t seq, uint8_t cmd, const uint8_t *p, uint8_t len) {
  switch (cmd) {
    case CMD_PING: {
      if (len != 0) return nak(seq, cmd, NAK_BAD_LENGTH);
      uint8_t data[2] = {(uint8_t)(armed ? STATE_ARMED : 0), faults};
      return ack(seq, cmd, data, 2);
    }
    case CMD_ARM:
      if (len != 0) return nak(seq, cmd, NAK_BAD_LENGTH);
      armed = true;
      faults &= (uint8_t)~FAULT_WATCHDOG;
      return ack(seq, cmd, 0, 0);
    case CMD_ALL_OFF:
      if (len != 0) return nak(seq, cmd, NAK_BAD_LENGTH);
      closeAll();
      return ack(seq, cmd, 0, 0);
    case CMD_STATUS: {
      if (len != 0) return nak(seq, cmd, NAK_BAD_LENGTH);
      uint8_t d[14];
      d[0] = armed ? STATE_ARMED : 0;
      d[1] = faults;
      for (uint8_t i = 0; i < VALVE_COUNT; i++) {
        d[2 + 2 * i] = (uint8_t)(duties[i] >> 8);
        d[3 + 2 * i] = (uint8_t)(duties[i] & 0xFF);
      }
      d[8] = FW_MAJOR;
      d[9] = FW_MINOR;
      d[10] = (uint8_t)((uint16_t)WATCHDOG_MS >> 8);
      d[11] = (uint8_t)((uint16_t)WATCHDOG_MS & 0xFF);
      d[12] = (uint8_t)(rxErrors >> 8);
      d[13] = (uint8_t)(rxErrors & 0xFF);
      return ack(seq, cmd, d, sizeof d);
    }
    case CMD_SET_DUTY: {
      if (len != 3) return nak(seq, cmd, NAK_BAD_LENGTH);
      uint8_t valve = p[0];
      uint16_t duty = ((uint16_t)p[1] << 8) | p[2];
      if (valve >= VALVE_COUNT || duty > DUTY_MAX_PERMILLE) return nak(seq, cmd, NAK_BAD_VALUE);
      if (faults & FAULT_WATCHDOG) return nak(seq, cmd, NAK_WATCHDOG);
      if (!armed) return nak(seq, cmd, NAK_NOT_ARMED);
      uint16_t next[VALVE_COUNT] = {duties[0], duties[1], duties[2]};
      next[valve] = duty;
      applyDuties(next);
      return ack(seq, cmd, 0, 0);
    }
    case CMD_SET_ALL: {
      if (len != 6) return nak(seq, cmd, NAK_BAD_LENGTH);
      uint16_t next[VALVE_COUNT];
      for (uint8_t i = 0; i < VALVE_COUNT; i++) {
        next[i] = ((uint16_t)p[2 * i] << 8) | p[2 * i + 1];
        if (next[i] > DUTY_MAX_PERMILLE) return nak(seq, cmd, NAK_BAD_VALUE);
      }
      if (faults & FAULT_WATCHDOG) return nak(seq, cmd, NAK_WATCHDOG);
      if (!armed) return nak(seq, cmd, NAK_NOT_ARMED);
      applyDuties(next);
      return ack(seq, cmd, 0, 0);
    }
    default:  // includes ACK/NAK sent to us: replies are not requests
      return nak(seq, cmd, NAK_UNKNOWN_COMMAND);
  }
}

void handleFrame(const uint8_t *frame, uint8_t total) {
  lastValidMs = millis();
  if (haveLastFrame && total == lastFrameLen && memcmp(frame, lastFrame, total) == 0) {
    Serial.write(lastReply, lastReplyLen);  // duplicate (host retry): answer, do not redo
    return;
  }
  memcpy(lastFrame, frame, total);
  lastFrameLen = total;
  haveLastFrame = true;
  execute(frame[2], frame[3], &frame[HEADER_LEN], frame[1]);
}

void countRxError() {
  if (rxErrors < 0xFFFF) rxErrors++;
}

// Drop the first byte of rxBuf (a false or corrupted SOF) and rescan the rest for SOF.
void skipSof() {
  uint8_t i = 1;
  while (i < rxLen && rxBuf[i] != SOF) i++;
  memmove(rxBuf, &rxBuf[i], rxLen - i);
  rxLen -= i;
}

void feedByte(uint8_t b) {
  if (rxLen == 0 && b != SOF) return;  // hunting for SOF
  rxBuf[rxLen++] = b;
  for (;;) {
    if (rxLen < 2) return;
    uint8_t len = rxBuf[1];
    if (len > MAX_PAYLOAD) {
      countRxError();
      skipSof();
      continue;
    }
    uint8_t total = HEADER_LEN + len + CRC_LEN;
    if (rxLen < total) return;
    uint16_t got = ((uint16_t)rxBuf[total - 2] << 8) | rxBuf[total - 1];
    if (crc16CcittFalse(&rxBuf[1], total - 1 - CRC_LEN) != got) {
      countRxError();
      skipSof();
      continue;
    }
    handleFrame(rxBuf, total);
    memmove(rxBuf, &rxBuf[total], rxLen - total);
    rxLen -= total;
    if (rxLen > 0 && rxBuf[0] != SOF) skipSof();
  }
}

void checkWatchdog() {
  // Unsigned subtraction is correct across the 49-day millis() wrap.
  if (armed && (uint32_t)(millis() - lastValidMs) >= (uint32_t)WATCHDOG_MS) {
    armed = false;
    faults |= FAULT_WATCHDOG;
    haveLastFrame = false;  // a retry after the trip is judged afresh (and refused)
    closeAll();
  }
}

void setup() {
  for (uint8_t i = 0; i < VALVE_COUNT; i++) {
    pinMode(VALVE_PINS[i], OUTPUT);
    digitalWrite(VALVE_PINS[i], LOW);
  }
  Serial.begin(BAUD);
  lastValidMs = millis();
}

void loop() {
  // Time passed before these bytes arrived: an overdue watchdog trips first.
  checkWatchdog();
  while (Serial.available() > 0) {
    feedByte((uint8_t)Serial.read());
  }
  checkWatchdog();
}
