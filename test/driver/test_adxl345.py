"""ADXL345 register logic against the register-map simulator behind the smbus2 interface."""
import errno

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver.adxl345 import Adxl345, FifoTimestamper, open_smbus
from accelcal_ros.driver.register_sim import SimulatedAdxl345Bus
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.driver.sources import I2cSource
from accelcal_ros.errors import DeviceError, InputError
from accelcal_ros.sensor.datasheet import FULL_RES_G_PER_LSB
from accelcal_ros.sensor.model import SensorModel
import numpy as np
import pytest


class FakeClock:
    """A clock the test advances by hand."""

    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        """Return the current fake time."""
        return self.t


def make_bus(clock, noise=0.0, devid=reg.DEVID_VALUE, poses=((0.0, 0.0),)):
    sensor = SimulatedAdxl345(SensorModel.identity(), rate_hz=100.0, poses_deg=poses,
                              noise_scale=noise)
    return SimulatedAdxl345Bus(sensor, clock=clock, devid=devid)


def test_device_id_and_configuration_registers():
    """DEVID is checked; rate code, full resolution, range and stream mode are written."""
    clock = FakeClock()
    bus = make_bus(clock)
    dev = Adxl345(bus, 0x53, bus_number=1)
    assert dev.check_device_id() == 0xE5
    dev.configure(800.0, 4, fifo=True)
    assert bus.registers[reg.BW_RATE] == 0x0D
    assert bus.registers[reg.DATA_FORMAT] == reg.DATA_FORMAT_FULL_RES | 0x01
    assert bus.registers[reg.FIFO_CTL] & 0xC0 == reg.FIFO_MODE_STREAM
    assert bus.registers[reg.POWER_CTL] == reg.POWER_CTL_MEASURE


def test_wrong_device_id_names_bus_address_and_value():
    """Another chip at the address: a DeviceError naming bus, address and the value read."""
    dev = Adxl345(make_bus(FakeClock(), devid=0x42), 0x53, bus_number=3)
    with pytest.raises(DeviceError, match=r'bus 3.*0x53.*0x42.*0xE5'):
        dev.check_device_id()


def test_no_device_answering_and_missing_bus():
    """Nothing at the address, or no /dev/i2c-N: clear DeviceErrors."""
    dev = Adxl345(make_bus(FakeClock()), 0x1D, bus_number=1)  # simulated chip is at 0x53
    with pytest.raises(DeviceError, match='no device answered'):
        dev.check_device_id()
    with pytest.raises(DeviceError, match=r'/dev/i2c-97 does not exist'):
        open_smbus(97)
    with pytest.raises(InputError, match='not an ADXL345 address'):
        Adxl345(make_bus(FakeClock()), 0x20)


def test_single_read_is_little_endian_full_resolution():
    """A level sensor reads +1 g on z (REP-145) at 3.9 mg/LSB, in one 6-byte block."""
    clock = FakeClock()
    bus = make_bus(clock)
    dev = Adxl345(bus)
    dev.configure(100.0, 16, fifo=False)
    clock.t += 0.05
    sample = dev.read_sample()
    assert sample == pytest.approx([0.0, 0.0, round(1.0 / FULL_RES_G_PER_LSB)
                                    * FULL_RES_G_PER_LSB], abs=1e-12)
    raw = bus.read_i2c_block_data(0x53, reg.DATAX0, 6)
    assert len(raw) == 6 and int.from_bytes(bytes(raw[4:6]), 'little', signed=True) == 256


def test_fifo_drains_every_sample_and_detects_overrun():
    """Stream mode: each poll drains all queued entries; a too-late poll reports overrun."""
    clock = FakeClock()
    bus = make_bus(clock, noise=1.0)
    dev = Adxl345(bus)
    dev.configure(800.0, 16, fifo=True)
    clock.t += 0.02  # 16 samples at 800 Hz
    samples, overrun = dev.read_fifo()
    assert len(samples) == 16 and not overrun
    clock.t += 0.1  # 80 samples > 32-entry FIFO
    samples, overrun = dev.read_fifo()
    assert len(samples) == 32 and overrun
    assert bus.generated == 96


def test_i2c_source_retries_with_backoff_and_never_invents_samples():
    """An I/O error mid-stream: no sample, an error counted, back-off, then recovery."""
    clock = FakeClock()
    bus = make_bus(clock, noise=1.0)
    source = I2cSource(Adxl345(bus, bus_number=1), 800.0, 16, use_fifo=True, clock=clock)
    source.start()
    clock.t += 0.01
    assert len(source.poll()) == 8
    bus.fail_next(3)
    empties = []
    for _ in range(3):
        clock.t = max(clock.t, source.next_poll_time())
        empties.append(len(source.poll()))
    assert empties == [0, 0, 0]
    assert source.stats.io_errors == 3 and 'errno %d' % errno.EIO in source.stats.last_error
    gaps = source._backoff
    assert gaps == pytest.approx(0.008)  # 2 ms doubling: 2, 4, 8 ms
    clock.t = source.next_poll_time()
    batch = source.poll()
    assert len(batch) > 0 and source.stats.consecutive_errors == 0
    assert source.stats.samples == 8 + len(batch)
    assert np.all(np.diff(batch.stamps) == pytest.approx(1 / 800.0))


def test_fifo_timestamps_even_and_monotonic():
    """Batches get evenly spaced stamps ending at the read time, never going back."""
    stamper = FifoTimestamper(100.0)
    first = stamper.stamps(5, 10.0)
    assert first == pytest.approx([9.96, 9.97, 9.98, 9.99, 10.0])
    second = stamper.stamps(3, 10.015)  # read early: stamps continue after the last one
    assert np.diff(second) == pytest.approx([0.01, 0.01])
    assert second[0] >= first[-1] + 0.005 - 1e-12 and abs(second[-1] - 10.015) < 0.02
    assert stamper.stamps(0, 11.0).size == 0


@pytest.mark.parametrize('rate_hz, clock_error', [(100.0, 0.01), (800.0, 0.01),
                                                  (800.0, -0.02), (3200.0, 0.0)])
def test_fifo_stamps_follow_a_sensor_clock_off_by_percent(rate_hz, clock_error):
    """
    A sensor clock 1 % fast (datasheet tolerance) for 10 simulated minutes.

    Sample k is taken at host time ``k / (rate (1 + error))``; the host drains the FIFO
    every 10 ms (5 ms at 3200 Hz) with 0-2 ms of random latency. Every stamp stays within
    a few ms of the true host time of its sample, and the measured output data rate is
    the true one.
    """
    rng = np.random.default_rng(3)
    true_rate = rate_hz * (1.0 + clock_error)
    stamper = FifoTimestamper(rate_hz)
    taken = 0
    worst_ms = 0.0
    interval_s = min(0.01, 16 / rate_hz)
    for poll in range(1, int(600 / interval_s) + 1):   # 600 s
        t_read = poll * interval_s + rng.uniform(0.0, 0.002)
        count = int(t_read * true_rate) + 1 - taken
        assert count <= 32   # the FIFO never overflows at these poll rates
        stamps = stamper.stamps(count, t_read)
        if count == 0:
            continue
        truth = (taken + np.arange(count)) / true_rate
        taken += count
        if t_read > 5.0:
            worst_ms = max(worst_ms, float(np.max(np.abs(stamps - truth))) * 1e3)
    assert worst_ms < 5.0
    assert abs(truth[-1] - stamps[-1]) < 0.005
    assert stamper.measured_rate_hz == pytest.approx(true_rate, rel=2e-4)
