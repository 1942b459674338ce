"""Helpers of the IMU tests: a virtual clock and the driver's start-up transactions as a
script for the mock bus (`drivers.testing.ScriptedBus`).

(Named uniquely because tests/drivers/imu has no __init__.py: a tests/drivers/imu
package would shadow the real `drivers.imu` under pytest's default import mode.)
"""

from __future__ import annotations

from drivers.testing.scripted_bus import R, Step, W


class VirtualClock:
    """Time that moves only when something sleeps: `clock()` and `clock.sleep(dt)`."""

    def __init__(self, start_s: float = 100.0) -> None:
        self.now_s = start_s
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, duration_s: float) -> None:
        assert duration_s >= 0.0
        self.sleeps.append(duration_s)
        self.now_s += duration_s


def init_script(address: int = 0x68) -> list[Step]:
    """Every transaction of `Icm20948.initialize()` with the default settings (ranges
    +-4 g / +-500 dps, divider 10, DLPF 3), written out in plain numbers from the
    datasheet rather than from the driver's constants. SLV4 completes at the 2nd poll."""
    a = address
    return [
        W(a, 0x7F, 0x00),  # REG_BANK_SEL = bank 0
        R(a, 0x00, 0xEA),  # WHO_AM_I
        W(a, 0x06, 0x80),  # PWR_MGMT_1 DEVICE_RESET
        W(a, 0x7F, 0x00),  # bank unknown after reset: select bank 0 again
        R(a, 0x06, 0x41),  # reset done (bit 7 clear), asleep
        W(a, 0x06, 0x01),  # wake, CLKSEL auto
        W(a, 0x07, 0x00),  # PWR_MGMT_2: all axes on
        W(a, 0x0F, 0x00),  # INT_PIN_CFG: bypass off
        W(a, 0x05, 0x00),  # LP_CONFIG: aux master at the gyro rate, not duty-cycled
        W(a, 0x7F, 0x20),  # bank 2
        W(a, 0x00, 0x0A), R(a, 0x00, 0x0A),  # GYRO_SMPLRT_DIV = 10
        W(a, 0x01, 0x1B), R(a, 0x01, 0x1B),  # GYRO_CONFIG_1: DLPF 3, +-500 dps, FCHOICE
        W(a, 0x10, 0x00),  # ACCEL_SMPLRT_DIV_1
        W(a, 0x11, 0x0A), R(a, 0x11, 0x0A),  # ACCEL_SMPLRT_DIV_2 = 10
        W(a, 0x14, 0x1B), R(a, 0x14, 0x1B),  # ACCEL_CONFIG: DLPF 3, +-4 g, FCHOICE
        W(a, 0x7F, 0x00), W(a, 0x03, 0x20),  # USER_CTRL: I2C_MST_EN
        W(a, 0x7F, 0x30), W(a, 0x01, 0x07),  # I2C_MST_CTRL: 345.6 kHz
        # SLV4 write AK09916 CNTL3 = SRST
        W(a, 0x13, 0x0C), W(a, 0x14, 0x32), W(a, 0x16, 0x01), W(a, 0x15, 0x80),
        W(a, 0x7F, 0x00), R(a, 0x17, 0x00), R(a, 0x17, 0x40),
        # SLV4 read AK09916 WIA2
        W(a, 0x7F, 0x30), W(a, 0x13, 0x8C), W(a, 0x14, 0x01), W(a, 0x15, 0x80),
        W(a, 0x7F, 0x00), R(a, 0x17, 0x00), R(a, 0x17, 0x40),
        W(a, 0x7F, 0x30), R(a, 0x17, 0x09),  # I2C_SLV4_DI = WIA2
        # SLV4 write AK09916 CNTL2 = continuous 100 Hz
        W(a, 0x13, 0x0C), W(a, 0x14, 0x31), W(a, 0x16, 0x08), W(a, 0x15, 0x80),
        W(a, 0x7F, 0x00), R(a, 0x17, 0x00), R(a, 0x17, 0x40),
        # SLV0: read 9 bytes from ST1 at every sample
        W(a, 0x7F, 0x30), W(a, 0x03, 0x8C), W(a, 0x04, 0x10), W(a, 0x05, 0x89),
        W(a, 0x7F, 0x00),
    ]
