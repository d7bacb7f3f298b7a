"""The bus-time model against the datasheet's timing, the rate rule, and the docs table."""
import os

from accelcal_ros.driver import bus_timing
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_i2c_times_are_the_datasheet_clock_and_condition_times():
    """
    400 kHz: t1 = 2.5 us per SCL cycle (Table 12), 9 cycles per byte with the ACK.

    A 6-byte read is START (t4 = 0.6 us), address+W, register, repeated START (t7 + t4),
    address+R, 6 data bytes, STOP (t8) and bus free (t9 = 1.3 us).
    """
    t1, t4, t7, t8, t9 = 2.5e-6, 0.6e-6, 0.6e-6, 0.6e-6, 1.3e-6
    expected = 9 * 9 * t1 + t4 + (t7 + t4) + (t8 + t9)
    assert bus_timing.i2c_read_s(400e3, 6) == pytest.approx(expected, rel=1e-12)
    assert bus_timing.i2c_write_s(400e3, 1) == pytest.approx(3 * 9 * t1 + t4 + t8 + t9)
    # standard mode: 10 us per cycle; the "0.2-0.9 ms" per 6-byte FIFO read
    assert 0.8e-3 < bus_timing.i2c_read_s(100e3, 6) < 0.9e-3
    assert 0.2e-3 < bus_timing.i2c_read_s(400e3, 6) < 0.21e-3


def test_spi_times_are_eight_clocks_a_byte_plus_chip_select():
    """5 MHz: t_SCLK = 200 ns (Table 10); command + 6 bytes; FIFO pop needs 5 us in all."""
    t_sclk = 200e-9
    plain = 7 * 8 * t_sclk + (5e-9 + 5e-9 + 150e-9)
    assert bus_timing.spi_transfer_s(5e6, 6) == pytest.approx(plain)
    # popping a FIFO entry: CS stays high until 5 us minus the next command byte (1.6 us):
    # the datasheet's "at most 3.4 us" at 5 MHz
    assert bus_timing.spi_transfer_s(5e6, 6, pops_fifo=True) - 7 * 8 * t_sclk == \
        pytest.approx(3.4e-6)
    # at or below 1.6 MHz the command byte alone is long enough
    slow = bus_timing.spi_transfer_s(1.6e6, 6, pops_fifo=True)
    assert slow == pytest.approx(bus_timing.spi_transfer_s(1.6e6, 6))


@pytest.mark.parametrize('bus, speed, rate, ok', [
    ('i2c', 100e3, 3200.0, False), ('i2c', 100e3, 200.0, True), ('i2c', 100e3, 400.0, False),
    ('i2c', 400e3, 800.0, True), ('i2c', 400e3, 1600.0, False), ('spi', 2e6, 3200.0, True),
    ('spi', 1e6, 1600.0, False), ('spi', 5e6, 3200.0, True), ('spi', 400e3, 800.0, True),
])
def test_datasheet_rule(bus, speed, rate, ok):
    """Table 7: 1600/3200 Hz only on SPI >= 2 MHz; 800 Hz at >= 400 kHz, lower in proportion."""
    assert bus_timing.sustainable(bus, speed, rate) is ok


def test_refusal_names_the_limit_and_the_fastest_rate():
    """I2C at 100 kHz and 3200 Hz: one line with the rule, the read time and 200 Hz."""
    reason = bus_timing.check_rate('i2c', 100e3, 3200.0, True)
    assert '\n' not in reason
    assert 'only over SPI at >= 2 MHz' in reason and '831 us' in reason
    assert 'fastest rate that works here is 200 Hz' in reason
    assert bus_timing.check_rate('i2c', 400e3, 800.0, True) is None
    assert bus_timing.fastest_rate_hz('i2c', 400e3) == 800.0
    # a bus too slow for the reads even where the rule allows: the bus-time limit
    assert bus_timing.bus_load('i2c', 10e3, 6.25, False) < 0.5
    reason = bus_timing.check_rate('i2c', 20e3, 25.0, False)
    assert reason is None or 'fastest' in reason


@pytest.mark.parametrize('bus, speed, message', [
    ('i2c', 1e6, 'above the ADXL345 I2C maximum of 400 kHz'),
    ('spi', 8e6, 'above the ADXL345 SPI maximum of 5 MHz'),
    ('spi', 5e3, 'below 10 kHz'),
])
def test_bus_speed_out_of_range(bus, speed, message):
    """A clock beyond the chip's limits: one clear line."""
    assert message in bus_timing.check_speed(bus, speed)


def test_docs_table_is_the_model():
    """docs/driver_buses.md holds the table the model prints (bytes and us per transaction)."""
    with open(os.path.join(REPO, 'docs', 'driver_buses.md')) as handle:
        text = handle.read()
    assert bus_timing.timing_table() in text
