"""
One ADXL345 class on two transports, bus time in the register-level simulation, self-test.

A fake clock advanced by the simulation's own ``sleep`` makes the bus time exact: what
the driver achieves here is what its transactions cost on the wire.
"""
import time

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.driver import bus_timing
from accelcal_ros.driver.adxl345 import Adxl345
from accelcal_ros.driver.params import bus_speed_hz, DRIVER_PARAMS, make_source
from accelcal_ros.driver.register_sim import SimulatedAdxl345Bus, SimulatedAdxl345Spi
from accelcal_ros.driver.selftest import run_self_test, self_test_limits_lsb, self_test_scale
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.driver.sources import Adxl345Source
from accelcal_ros.driver.transport import (I2cTransport, linux_bus_speed_hz, setup_spi,
                                           SpiTransport)
from accelcal_ros.errors import DeviceError, InputError
from accelcal_ros.sensor.model import SensorModel
import numpy as np
import pytest


class FakeClock:
    """A clock advanced by the simulation's sleep (bus time) and by the test."""

    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        """Return the current fake time."""
        return self.t

    def sleep(self, seconds):
        """Advance the fake time."""
        self.t += seconds


def sensor(rate=800.0, noise=0.0):
    return SimulatedAdxl345(SensorModel.identity(), rate_hz=rate, poses_deg=[[0.0, 0.0]],
                            noise_scale=noise)


def device(bus, clock, speed=None, **kwargs):
    """Return an Adxl345 over the simulated ``bus`` (i2c or spi) with the fake clock."""
    if bus == 'spi':
        chip = SimulatedAdxl345Spi(sensor(), clock=clock, sleep=clock.sleep, max_lag_s=0.0,
                                   **kwargs)
        setup_spi(chip, speed or 5e6)
        return Adxl345(SpiTransport(chip, 0, 0)), chip
    chip = SimulatedAdxl345Bus(sensor(), clock=clock, sleep=clock.sleep, max_lag_s=0.0,
                               bus_speed_hz=speed, **kwargs)
    return Adxl345(I2cTransport(chip, 0x53, 1)), chip


@pytest.mark.parametrize('bus', ['i2c', 'spi'])
def test_same_registers_and_samples_on_both_buses(bus):
    """Configuration registers, DEVID, FIFO drain and +1 g on z: the same on I2C and SPI."""
    clock = FakeClock()
    dev, chip = device(bus, clock)
    assert dev.check_device_id() == 0xE5
    dev.configure(800.0, 4, fifo=True)
    assert chip.registers[reg.BW_RATE] == 0x0D
    assert chip.registers[reg.DATA_FORMAT] == reg.DATA_FORMAT_FULL_RES | 0x01
    assert chip.registers[reg.FIFO_CTL] & 0xC0 == reg.FIFO_MODE_STREAM
    clock.t += 0.02
    samples, overrun = dev.read_fifo()
    assert len(samples) == 16 and not overrun
    assert np.allclose(samples, [0.0, 0.0, 256 * 0.0039])


def test_spi_command_byte_read_and_multi_byte_bits():
    """Read sets 0x80, a multi-byte read also 0x40, a write neither; mode 3 is set."""
    sent = []

    class Recorder:
        def xfer2(self, values):
            sent.append(list(values))
            return [0] * len(values)

    transport = SpiTransport(Recorder(), 0, 1)
    transport.read_block(reg.DATAX0, 6)
    transport.read_register(reg.DEVID)
    transport.write_register(reg.POWER_CTL, 0x08)
    assert sent == [[0x80 | 0x40 | 0x32] + [0] * 6, [0x80, 0], [0x2D, 0x08]]
    chip = SimulatedAdxl345Spi(sensor())
    setup_spi(chip, 2e6)
    assert chip.mode == 3 and chip.max_speed_hz == 2_000_000


def test_spi_without_multi_byte_bit_or_in_the_wrong_mode_fails_visibly():
    """The simulated chip repeats a register without MB, and garbles bytes outside mode 3."""
    clock = FakeClock()
    chip = SimulatedAdxl345Spi(sensor(), clock=clock)
    setup_spi(chip, 5e6)
    assert chip.xfer2([0x80 | 0x2C, 0, 0])[1:] == [0x0A, 0x0A]   # no MB: same register
    chip.mode = 0
    with pytest.raises(DeviceError, match='DEVID read 0xF2'):
        Adxl345(SpiTransport(chip, 0, 0)).check_device_id()


@pytest.mark.parametrize('devid', [0x00, 0xFF])
def test_absent_spi_device_is_one_clear_line(devid):
    """Nothing on the chip select reads all zeros or all ones: named as absent."""
    clock = FakeClock()
    chip = SimulatedAdxl345Spi(sensor(), clock=clock, devid=devid)
    setup_spi(chip, 5e6)
    with pytest.raises(DeviceError) as info:
        Adxl345(SpiTransport(chip, 0, 1)).check_device_id()
    text = str(info.value)
    assert f'SPI bus 0, chip select 1: DEVID read 0x{devid:02X}' in text
    assert 'no device answers' in text and '\n' not in text


def test_missing_spidev_node_is_one_clear_line():
    """/dev/spidevB.C absent: a DeviceError naming the path and what to check."""
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='spi', spi_bus=97, spi_device=3, rate_hz=100.0)
    with pytest.raises(DeviceError, match=r'/dev/spidev97\.3 does not exist'):
        make_source(values)


@pytest.mark.parametrize('bus, speed, rate', [('i2c', 400e3, 800.0), ('spi', 5e6, 3200.0),
                                              ('spi', 2e6, 3200.0), ('i2c', 100e3, 200.0)])
def test_sustainable_rates_lose_nothing_on_the_wire(bus, speed, rate):
    """
    Two simulated seconds polled on the driver's schedule: no overrun, every sample read.

    The bus time the chip recorded is the model's per-transaction time times the reads.
    """
    clock = FakeClock()
    dev, chip = device(bus, clock, speed)
    source = Adxl345Source(dev, rate, 16, use_fifo=True, clock=clock, bus_speed_hz=speed)
    source.start()
    t_end = clock.t + 2.0
    read = 0
    while clock.t < t_end:
        clock.t = max(clock.t, source.next_poll_time())
        read += len(source.poll())
    assert chip.dropped == 0 and source.stats.fifo_overruns == 0
    assert read >= chip.generated - 32 and read > 0.99 * 2.0 * rate
    sample_s = bus_timing.transaction_s(bus, speed, 6, pops_fifo=True)
    assert chip.busy_s >= read * sample_s
    assert chip.busy_s / 2.0 < bus_timing.MAX_BUS_LOAD


def test_unsustainable_rate_on_slow_i2c_overruns_and_the_loss_is_counted():
    """3200 Hz at 100 kHz: each read costs 831 us, the FIFO overflows; losses are counted."""
    clock = FakeClock()
    dev, chip = device('i2c', clock, 100e3)
    source = Adxl345Source(dev, 3200.0, 16, use_fifo=True, clock=clock,
                           bus_speed_hz=100e3)
    source.start()
    read = 0
    t_end = clock.t + 1.0
    while clock.t < t_end:
        clock.t = max(clock.t, source.next_poll_time())
        read += len(source.poll())
    assert chip.dropped > 1000 and source.stats.fifo_overruns > 10
    # the wire limits the achieved rate to about 1 / 831 us = 1200 Hz
    assert read < 1.0 / bus_timing.i2c_read_s(100e3, 6) * 1.01
    assert source.lost_samples == pytest.approx(chip.dropped, rel=0.2)
    # one overrun event that never ends (every drain finds the FIFO overflowing): the bus's
    assert source.overruns_bus == 1 and source.overruns_host == 0 and source.lost_host == 0


def test_a_host_stall_is_told_apart_from_a_slow_bus():
    """SPI at 5 MHz and 3200 Hz: a 50 ms stall of the host overruns; blamed on the host."""
    clock = FakeClock()
    dev, chip = device('spi', clock, 5e6)
    source = Adxl345Source(dev, 3200.0, 16, use_fifo=True, clock=clock, bus_speed_hz=5e6)
    source.start()
    stamps = []
    for k in range(200):
        clock.t = max(clock.t, source.next_poll_time()) + (0.05 if k == 100 else 0.0)
        stamps.extend(source.poll().stamps)
    assert np.all(np.diff(stamps) >= 0.5 / 3200.0)   # monotonic across the restart
    assert source.stats.fifo_overruns == 1 and source.overruns_host == 1
    assert source.overruns_bus == 0
    assert source.lost_host == pytest.approx(chip.dropped, abs=2)


def test_node_parameters_refuse_an_unsustainable_rate_or_run_it_when_asked():
    """make_source: I2C 100 kHz and 3200 Hz refused with the reason; allowed explicitly."""
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='sim', rate_hz=3200.0, bus_speed_hz=100e3)
    values['sim.bus'] = 'i2c'
    with pytest.raises(InputError, match='fastest rate that works here is 200 Hz'):
        make_source(values)
    values['allow_unsustainable_rate'] = True
    source = make_source(values)
    assert 'not sustainable' in source.rate_warning and source.bus == 'i2c'
    values.update(bus_speed_hz=1e6)
    with pytest.raises(InputError, match='above the ADXL345 I2C maximum'):
        make_source(values)


def test_linux_bus_speed_is_read_from_the_device_tree(tmp_path):
    """clock-frequency (big-endian u32) under of_node wins over the parameter on I2C."""
    node = tmp_path / 'bus' / 'i2c' / 'devices' / 'i2c-1' / 'of_node'
    node.mkdir(parents=True)
    (node / 'clock-frequency').write_bytes((400000).to_bytes(4, 'big'))
    assert linux_bus_speed_hz('i2c', 1, sysfs=str(tmp_path)) == 400000.0
    assert linux_bus_speed_hz('i2c', 2, sysfs=str(tmp_path)) is None
    assert linux_bus_speed_hz('spi', 0, 0, sysfs=str(tmp_path)) is None
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='i2c', i2c_bus=1, bus_speed_hz=100e3)
    assert bus_speed_hz(values, sysfs=str(tmp_path)) == ('i2c', 400e3)   # the kernel's clock
    values['i2c_bus'] = 2
    assert bus_speed_hz(values, sysfs=str(tmp_path)) == ('i2c', 100e3)   # the parameter
    values['bus_speed_hz'] = 0.0
    assert bus_speed_hz(values, sysfs=str(tmp_path)) == ('i2c', 100e3)   # the default
    spi = tmp_path / 'bus' / 'spi' / 'devices' / 'spi0.1' / 'of_node'
    spi.mkdir(parents=True)
    (spi / 'spi-max-frequency').write_bytes((2000000).to_bytes(4, 'big'))
    values.update(backend='spi', spi_bus=0, spi_device=1)
    assert bus_speed_hz(values, sysfs=str(tmp_path)) == ('spi', 2e6)   # capped by the tree


def test_self_test_limits_follow_the_supply_voltage():
    """Table 15 at 2.5 V, scaled by Table 14 (3.3 V: x1.77 on x/y, x1.47 on z)."""
    assert self_test_limits_lsb(2.5) == pytest.approx(np.array([[50, 540], [-540, -50],
                                                                [75, 875]]))
    assert self_test_limits_lsb(3.3)[0] == pytest.approx([88.5, 955.8])
    assert self_test_limits_lsb(3.3)[2] == pytest.approx([110.25, 1286.25])
    with pytest.raises(InputError, match='outside'):
        self_test_scale(5.0)


@pytest.mark.parametrize('bus', ['i2c', 'spi'])
@pytest.mark.parametrize('broken', ['', 'z', 'xy'])
def test_self_test_passes_a_healthy_sensor_and_fails_a_broken_axis(bus, broken):
    """The measured change per axis is the simulated force; a missing one fails that axis."""
    clock = FakeClock()
    volts = 3.3
    scale = self_test_scale(volts) * [0.0 if a in broken else 1.0 for a in 'xyz']
    dev, chip = device(bus, clock, 400e3 if bus == 'i2c' else 5e6, self_test_scale=scale)
    chip.source = sensor(100.0, noise=1.0)
    dev.check_device_id()
    result = run_self_test(dev, volts, sleep=clock.sleep)
    expected = np.array([0.8, -0.8, 1.2]) * scale / 0.0039
    assert result.change_lsb == pytest.approx(expected, abs=3.0)
    assert result.axis_passed == [a not in broken for a in 'xyz']
    assert result.passed is (broken == '')
    assert ('FAILED' in result.summary()) is bool(broken)
    assert not chip.registers[reg.DATA_FORMAT] & reg.DATA_FORMAT_SELF_TEST


def run_real_time(reads, seconds=1.0, rate=800.0):
    """Drain the register-level SPI simulation in real time; return (source, stamps)."""
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='sim', rate_hz=rate, reads=reads,
                  **{'sim.bus': 'spi', 'sim.poses_deg': [0.0, 0.0]})
    source = make_source(values)
    source.start()
    end = time.time() + seconds
    stamps = []
    while time.time() < end:
        time.sleep(max(0.0, source.next_poll_time() - time.time()))
        stamps.extend(source.poll().stamps)
    return source, np.array(stamps)


def test_interrupt_reads_stamp_at_the_watermark_edge():
    """INT1 (watermark 16): drains on the simulated edge; stamps on the sample grid."""
    source, stamps = run_real_time('interrupt')
    chip = source.sim_chip
    assert chip.registers[reg.INT_ENABLE] == reg.INT_SOURCE_WATERMARK
    assert chip.registers[reg.FIFO_CTL] & 0x1F == 16
    if chip.dropped == 0:   # a loaded host may stall past the FIFO; then nothing to judge
        assert len(stamps) >= chip.generated - 32
        assert source.interrupt_timeouts == 0
        # the edge carries the watermark sample's time: steps within 1 % of the period
        assert np.max(np.abs(np.diff(stamps) * 800.0 - 1.0)) < 0.01


def test_interrupt_reads_after_an_overrun_are_stamped_at_the_read_not_the_old_edge():
    """
    A first drain long after start: stamped at the read, not from the stale edge.

    After a slow node start-up the FIFO overran and holds the newest 32 samples, so the
    watermark edge (20 ms after start) no longer dates them. Stamped from the edge, the
    batch ended at start + 40 ms, 0.2 s before it was read, and that batch anchored the
    rate measurement (a 4 % long period for the next 10 s).
    """
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='sim', rate_hz=800.0, reads='interrupt',
                  **{'sim.bus': 'spi', 'sim.poses_deg': [0.0, 0.0]})
    source = make_source(values)
    source.start()
    started = time.time()   # the chip measures from before this: its edge by started + 20 ms
    time.sleep(0.25)   # 200 samples: the 32-entry FIFO overruns
    batch = source.poll()   # read after started + 0.25 s, whatever the load
    after = time.time()
    assert source.stats.fifo_overruns >= 1 and len(batch.stamps) == 32
    assert started + 0.15 < batch.stamps[-1] <= after
    assert np.all(np.diff(batch.stamps) > 0)


def test_missing_gpio_chip_or_line_is_one_clear_line(monkeypatch):
    """A GPIO chip that is absent, or a line beyond its lines: DeviceError naming them."""
    from accelcal_ros.driver import gpio

    with pytest.raises(DeviceError, match=r'GPIO chip /dev/gpiochip97 does not exist'):
        gpio.GpiodInterrupt('gpiochip97', 4)

    class Chip:   # a 54-line chip (Raspberry Pi) standing in for /dev/gpiochip0
        def __init__(self, path):
            self.path = path

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def get_info(self):
            return type('Info', (), {'num_lines': 54})()

    import gpiod
    monkeypatch.setattr(gpiod, 'Chip', Chip)
    monkeypatch.setattr(gpio.os.path, 'exists', lambda path: True)
    with pytest.raises(DeviceError, match=r'GPIO line 99 does not exist on /dev/gpiochip0 '
                                          r'\(it has lines 0\.\.53'):
        gpio.GpiodInterrupt('gpiochip0', 99)
