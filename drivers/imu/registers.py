"""Register map of the ICM-20948 and of its AK09916 magnetometer, and the scale factors.

Sources: TDK InvenSense ICM-20948 datasheet DS-000189 rev 1.3, cited as "DS <section>"
with the register named beside it (section 3: specifications; 7: register map; 8-11:
descriptions of user banks 0-3; 12-13: the AK09916 magnetometer's map and descriptions).
The bench's hardware-facts.md summarises the subset used here. Register addresses are per user bank:
the same address means different registers in different banks, so every constant below
names its bank.
"""

from __future__ import annotations

import math

# --- I2C addresses ------------------------------------------------------------------
# DS 6 (I2C interface): the 7-bit address is 110100X, X = logic level of pin AD0.
ICM20948_ADDRESS_AD0_LOW = 0x68
ICM20948_ADDRESS_AD0_HIGH = 0x69
# DS 12 / AK09916 datasheet: the magnetometer sits at the fixed address 0x0C on the
# ICM-20948's auxiliary bus (and on the main bus only in bypass mode).
AK09916_ADDRESS = 0x0C

# --- every bank -------------------------------------------------------------------
# DS 7 (register map): REG_BANK_SEL is at 0x7F in all four banks; USER_BANK is bits 5:4.
REG_BANK_SEL = 0x7F
BANK_SHIFT = 4
BANK_COUNT = 4

# --- user bank 0 (DS 8) -------------------------------------------------------------
WHO_AM_I = 0x00
WHO_AM_I_VALUE = 0xEA  # DS 8
USER_CTRL = 0x03
USER_CTRL_FIFO_EN = 0x40  # DS 8 bit 6: enable the FIFO
USER_CTRL_I2C_MST_EN = 0x20  # DS 8 bit 5: enable the auxiliary I2C master
USER_CTRL_I2C_MST_RST = 0x02  # DS 8 bit 1: reset the I2C master (self-clearing)
LP_CONFIG = 0x05
LP_CONFIG_I2C_MST_CYC = 0x40  # DS 8 bit 6: aux master duty-cycled at I2C_MST_ODR_CONFIG's rate
LP_CONFIG_RESET_VALUE = 0x40  # DS 7 register map
PWR_MGMT_1 = 0x06
PWR_MGMT_1_DEVICE_RESET = 0x80  # DS 8 bit 7, self-clearing
PWR_MGMT_1_SLEEP = 0x40  # DS 8 bit 6
PWR_MGMT_1_CLKSEL_AUTO = 0x01  # DS 8 bits 2:0 = 1: best available clock (PLL if ready)
PWR_MGMT_1_RESET_VALUE = 0x41  # DS 7 register map: asleep, CLKSEL = 1
PWR_MGMT_2 = 0x07
PWR_MGMT_2_ALL_ON = 0x00  # DS 8: zero = every accel and gyro axis enabled
PWR_MGMT_2_DISABLE_ACCEL = 0x38  # bits 5:3
PWR_MGMT_2_DISABLE_GYRO = 0x07  # bits 2:0
INT_PIN_CFG = 0x0F
INT_PIN_CFG_BYPASS_EN = 0x02  # DS 8 bit 1: aux bus bridged onto the host bus
INT_PIN_CFG_INT_ANYRD_2CLEAR = 0x10  # DS 8 bit 4: any read clears the INT_STATUS bits
INT_STATUS_1 = 0x1A  # DS 8: bit 0 RAW_DATA_0_RDY_INT, cleared by reading it
INT_STATUS_1_RAW_DATA_0_RDY = 0x01
INT_STATUS_2 = 0x1B  # DS 8: bits 4:0 FIFO_OVERFLOW_INT, cleared by reading it
INT_STATUS_2_FIFO_OVERFLOW = 0x1F
I2C_MST_STATUS = 0x17  # DS 8, read-to-clear
I2C_MST_STATUS_SLV4_DONE = 0x40
I2C_MST_STATUS_SLV4_NACK = 0x10
I2C_MST_STATUS_SLV0_NACK = 0x01
ACCEL_XOUT_H = 0x2D  # DS 8: accel X/Y/Z, big-endian int16, 0x2D-0x32
GYRO_XOUT_H = 0x33  # DS 8: gyro X/Y/Z, big-endian int16, 0x33-0x38
TEMP_OUT_H = 0x39  # DS 8: big-endian int16, 0x39-0x3A
EXT_SLV_SENS_DATA_00 = 0x3B  # DS 8: 24 bytes, 0x3B-0x52, filled by the I2C master
EXT_SLV_SENS_DATA_COUNT = 24
# The FIFO (DS 4.16, DS 8). Each write appends the enabled sources in register order
# (accel, gyro X/Y/Z, temperature, then each enabled slave's EXT_SLV_SENS_DATA bytes),
# one record per sample instant; the host pops bytes by reading FIFO_R_W.
FIFO_EN_1 = 0x66  # DS 8: bit 0 SLV_0_FIFO_EN (bits 3:0 for SLV0..SLV3)
FIFO_EN_1_SLV_0 = 0x01
FIFO_EN_2 = 0x67  # DS 8: bit 4 ACCEL, bits 3:1 GYRO_Z/Y/X, bit 0 TEMP
FIFO_EN_2_ACCEL = 0x10
FIFO_EN_2_GYRO_Z = 0x08
FIFO_EN_2_GYRO_Y = 0x04
FIFO_EN_2_GYRO_X = 0x02
FIFO_EN_2_TEMP = 0x01
FIFO_RST = 0x68  # DS 8: bits 4:0; assert and de-assert to empty the FIFO
FIFO_RST_ASSERT = 0x1F
FIFO_MODE = 0x69  # DS 8: bits 4:0; 0 stream (a full FIFO drops its oldest bytes), 1 snapshot (drops new ones)
FIFO_MODE_SNAPSHOT = 0x1F
FIFO_COUNTH = 0x70  # DS 8: bits 4:0 = count bits 12:8 (bytes in the FIFO); reading it latches FIFO_COUNTL
FIFO_COUNTL = 0x71
FIFO_R_W = 0x72  # DS 8: each read pops the oldest byte (the address does not advance)
# DS 4.16: a 512-byte FIFO. (Some report 4 KB on silicon; the emulator takes the datasheet.)
FIFO_SIZE_BYTES = 512

# --- user bank 2 (DS 10) ------------------------------------------------------------
GYRO_SMPLRT_DIV = 0x00  # DS 10: ODR = 1.125 kHz / (1 + div); DS prints "1.1 kHz"
GYRO_CONFIG_1 = 0x01  # DS 10: bits 5:3 DLPFCFG, bits 2:1 FS_SEL, bit 0 FCHOICE
ACCEL_SMPLRT_DIV_1 = 0x10  # DS 10: bits 3:0 = divider bits 11:8
ACCEL_SMPLRT_DIV_2 = 0x11  # DS 10: divider bits 7:0
ACCEL_SMPLRT_DIV_MAX = 0x0FFF  # 12 bits
ACCEL_CONFIG = 0x14  # DS 10: bits 5:3 DLPFCFG, bits 2:1 FS_SEL, bit 0 FCHOICE
CONFIG_FS_SHIFT = 1
CONFIG_DLPF_SHIFT = 3
CONFIG_FCHOICE_DLPF = 0x01  # FCHOICE = 1 routes the output through the DLPF
CONFIG_DLPF_MASK = 0x07

# Internal sample clock the dividers count down (DS 10, GYRO_SMPLRT_DIV and ACCEL_SMPLRT_DIV).
BASE_SAMPLE_RATE_HZ = 1125.0

# --- user bank 3 (DS 11): the auxiliary I2C master -------------------------------------
I2C_MST_ODR_CONFIG = 0x00  # DS 11: bits 3:0; duty-cycled master rate 1.1 kHz / 2^value
I2C_MST_CTRL = 0x01  # DS 11: bits 3:0 I2C_MST_CLK
I2C_MST_DELAY_CTRL = 0x02  # DS 11: written by Pimoroni's driver; no effect modelled
I2C_MST_CLK_RECOMMENDED = 0x07  # DS 11: 7 -> 345.6 kHz, recommended for a 400 kHz max bus
I2C_SLV0_ADDR = 0x03  # DS 11: bit 7 = read (1) / write (0), bits 6:0 address
I2C_SLV0_REG = 0x04
I2C_SLV0_CTRL = 0x05  # DS 11: bit 7 EN, bits 3:0 number of bytes to read
I2C_SLV0_DO = 0x06
I2C_SLV4_ADDR = 0x13  # DS 11: SLV4 does one transfer per enable
I2C_SLV4_REG = 0x14
I2C_SLV4_CTRL = 0x15  # bit 7 EN (clears itself when the single transfer completes)
I2C_SLV4_DO = 0x16
I2C_SLV4_DI = 0x17
I2C_SLV_READ = 0x80  # bit 7 of I2C_SLVx_ADDR
I2C_SLV_EN = 0x80  # bit 7 of I2C_SLVx_CTRL
I2C_SLV_LENG_MASK = 0x0F

# --- AK09916 (DS 12-13) -------------------------------------------------------------
AK_WIA1 = 0x00
AK_WIA1_VALUE = 0x48  # company ID (AK09916 datasheet; not listed in DS 12)
AK_WIA2 = 0x01
AK_WIA2_VALUE = 0x09  # DS 13
AK_ST1 = 0x10  # DS 13: bit 0 DRDY, bit 1 DOR
AK_ST1_DRDY = 0x01
AK_ST1_DOR = 0x02
AK_HXL = 0x11  # DS 13: X/Y/Z little-endian int16, 0x11-0x16
AK_TMPS = 0x17  # dummy byte between the data and ST2 (must be read through to ST2)
AK_ST2 = 0x18  # DS 13: bit 3 HOFL; reading ST2 releases the data registers
AK_ST2_HOFL = 0x08
AK_CNTL2 = 0x31  # DS 13: MODE[4:0]
AK_CNTL3 = 0x32  # DS 13: bit 0 SRST soft reset
AK_CNTL3_SRST = 0x01
AK_MODE_POWER_DOWN = 0x00
AK_MODE_SINGLE = 0x01
# DS 13: continuous measurement modes 1-4 and their rates (Hz).
AK_CONTINUOUS_MODES_HZ = {0x02: 10.0, 0x04: 20.0, 0x06: 50.0, 0x08: 100.0}
AK_MODE_CONTINUOUS_100HZ = 0x08
# SLV0 reads ST1 .. ST2 inclusive (9 bytes): reading through ST2 releases the next sample.
AK_BURST_START = AK_ST1
AK_BURST_LENGTH = AK_ST2 - AK_ST1 + 1

# --- scale factors ------------------------------------------------------------------
STANDARD_GRAVITY_M_S2 = 9.80665  # the "g" of the accelerometer's LSB/g (ISO 80000-3)
# DS 3 (gyroscope specifications) / DS 10: GYRO_FS_SEL -> (full scale dps, LSB per dps).
GYRO_FULL_SCALES: dict[int, tuple[int, float]] = {
    0: (250, 131.0),
    1: (500, 65.5),
    2: (1000, 32.8),
    3: (2000, 16.4),
}
# DS 3 (accelerometer specifications) / DS 10: ACCEL_FS_SEL -> (full scale g, LSB per g).
ACCEL_FULL_SCALES: dict[int, tuple[int, float]] = {
    0: (2, 16384.0),
    1: (4, 8192.0),
    2: (8, 4096.0),
    3: (16, 2048.0),
}
# DS 8: TEMP_degC = (TEMP_OUT - RoomTemp_Offset) / Temp_Sensitivity + 21,
# Temp_Sensitivity = 333.87 LSB/degC (DS 3, temperature sensor specification), RoomTemp_Offset = 0.
TEMP_SENSITIVITY_LSB_PER_DEGC = 333.87
TEMP_OFFSET_DEGC = 21.0
# DS 3, magnetometer specifications: 0.15 uT per LSB; DS 13 / AK09916: HOFL is set when
# |X| + |Y| + |Z| >= 4912 uT, and the data are then invalid.
MAG_UT_PER_LSB = 0.15
MAG_OVERFLOW_SUM_UT = 4912.0
MAG_COUNT_LIMIT = 32752  # AK09916 output range, +-32752 LSB (+-4912 uT)
# DS figure "orientation of axes of sensitivity and polarity of rotation": the AK09916 die's X axis matches the
# accel/gyro X axis, its Y and Z axes point the opposite way. The codec multiplies by
# these signs so every vector it returns is in the accel/gyro frame. (Not re-checked
# against the printed figure; several independent open drivers do the same.)
MAG_AXIS_SIGNS_IN_IMU_FRAME = (1, -1, -1)

DEG_TO_RAD = math.pi / 180.0

# DS 3.1 / 3.2: noise spectral densities (typical), and DS 10 tables of GYRO_DLPFCFG and
# ACCEL_DLPFCFG: the noise bandwidth (NBW, Hz) of each DLPFCFG with FCHOICE = 1, and of
# the filter bypassed (FCHOICE = 0). White noise per sample = density * sqrt(NBW).
GYRO_NOISE_DENSITY_DPS_PER_SQRT_HZ = 0.015
ACCEL_NOISE_DENSITY_UG_PER_SQRT_HZ = 230.0
GYRO_DLPF_NBW_HZ = (229.8, 187.6, 154.3, 73.3, 35.9, 17.8, 8.9, 376.5)
GYRO_BYPASS_NBW_HZ = 12316.0
ACCEL_DLPF_NBW_HZ = (265.0, 265.0, 136.0, 68.8, 34.4, 17.0, 8.3, 499.0)
ACCEL_BYPASS_NBW_HZ = 1248.0


def noise_bandwidth_hz(config: int, table: tuple[float, ...], bypass_hz: float) -> float:
    """Noise bandwidth (Hz) of a GYRO_CONFIG_1 / ACCEL_CONFIG value: its DLPFCFG row if
    FCHOICE routes through the filter, else the bypass bandwidth."""
    if not config & CONFIG_FCHOICE_DLPF:
        return bypass_hz
    return table[(config >> CONFIG_DLPF_SHIFT) & CONFIG_DLPF_MASK]


def bank_select_value(bank: int) -> int:
    """Value to write to REG_BANK_SEL for user bank 0..3 (DS 8: USER_BANK is bits 5:4)."""
    if not 0 <= bank < BANK_COUNT:
        raise ValueError(f"user bank must be 0..3, got {bank}")
    return bank << BANK_SHIFT


# --- the burst ----------------------------------------------------------------------
# One read from ACCEL_XOUT_H covers accel (6), gyro (6), temperature (2) and then the
# AK09916 bytes SLV0 copied into EXT_SLV_SENS_DATA_00 onwards (9): 23 bytes, contiguous.
MOTION_BYTES = EXT_SLV_SENS_DATA_00 - ACCEL_XOUT_H  # 14
BURST_START = ACCEL_XOUT_H
BURST_LENGTH = MOTION_BYTES + AK_BURST_LENGTH  # 23
# The FIFO record with accel, gyro, temperature and SLV0 enabled has the burst's layout.
FIFO_EN_2_MOTION = FIFO_EN_2_ACCEL | FIFO_EN_2_GYRO_Z | FIFO_EN_2_GYRO_Y | FIFO_EN_2_GYRO_X | FIFO_EN_2_TEMP
FIFO_RECORD_LENGTH = BURST_LENGTH
FIFO_RECORDS = FIFO_SIZE_BYTES // FIFO_RECORD_LENGTH  # 22 whole records
# smbus2.SMBus.read_i2c_block_data / write_i2c_block_data refuse more than 32 bytes
# (I2C_SMBUS_BLOCK_MAX in linux/i2c.h); longer transfers need i2c_rdwr.
SMBUS_BLOCK_MAX = 32
