"""
ADXL345 register map (Analog Devices ADXL345 datasheet, Rev. G, Table 19).

Only what the driver uses. Data registers 0x32..0x37 hold x, y, z as little-endian
two's-complement int16; in full-resolution mode (DATA_FORMAT.FULL_RES) the scale is
3.9 mg/LSB for every range. Reading all six bytes in one multi-byte transfer keeps the
three axes of one sample together (datasheet, "Register 0x32 to Register 0x37") and, with
the FIFO enabled, pops exactly one FIFO entry.
"""

DEVID = 0x00
DEVID_VALUE = 0xE5
BW_RATE = 0x2C
POWER_CTL = 0x2D
INT_ENABLE = 0x2E
INT_MAP = 0x2F
INT_SOURCE = 0x30
DATA_FORMAT = 0x31
DATAX0 = 0x32
FIFO_CTL = 0x38
FIFO_STATUS = 0x39

POWER_CTL_MEASURE = 0x08
DATA_FORMAT_FULL_RES = 0x08
DATA_FORMAT_SELF_TEST = 0x80
INT_SOURCE_OVERRUN = 0x01
INT_SOURCE_WATERMARK = 0x02
INT_SOURCE_DATA_READY = 0x80
FIFO_MODE_BYPASS = 0x00
FIFO_MODE_STREAM = 0x80
FIFO_ENTRIES_MASK = 0x3F
FIFO_DEPTH = 32

RATE_CODES = {
    3200.0: 0x0F, 1600.0: 0x0E, 800.0: 0x0D, 400.0: 0x0C, 200.0: 0x0B, 100.0: 0x0A,
    50.0: 0x09, 25.0: 0x08, 12.5: 0x07, 6.25: 0x06,
}
"""Output data rate (Hz) -> BW_RATE rate code (datasheet Table 7, normal power)."""
RANGE_CODES = {2: 0x00, 4: 0x01, 8: 0x02, 16: 0x03}
"""Measurement range (+-g) -> DATA_FORMAT range bits."""
VALID_ADDRESSES = (0x53, 0x1D)
"""I2C address with ALT ADDRESS low (0x53) or high (0x1D)."""
