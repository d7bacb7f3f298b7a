"""ITG-3205 gyro (GY-85) against its register-level simulator: identity, setup, scaling."""
import math

from accelcal_ros.driver import itg3205 as reg
from accelcal_ros.driver.itg3205 import dlpf_for_rate, Itg3205, sample_rate_divider
from accelcal_ros.driver.itg3205_sim import SimulatedItg3205Bus
from accelcal_ros.errors import DeviceError, InputError
import numpy as np
import pytest


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _gyro(rate=(0.5, -0.2, 1.0), **kwargs):
    clock = Clock()
    bus = SimulatedItg3205Bus(lambda t: rate, clock=clock, **kwargs)
    return Itg3205(bus), bus, clock


def test_wrong_who_am_i_is_refused_with_the_value_read():
    gyro, bus, _ = _gyro()
    bus.who_am_i = 0xE5   # an ADXL345 answering at that address
    with pytest.raises(DeviceError, match='WHO_AM_I read 0xE5.*not an ITG-3205'):
        gyro.configure(100.0)
    bus.who_am_i = 0x69   # AD0 high: fine
    gyro.configure(100.0)
    with pytest.raises(InputError, match='0x68 or 0x69'):
        Itg3205(bus, address=0x53)


def test_configuration_registers_and_rates():
    gyro, bus, _ = _gyro()
    gyro.configure(100.0)
    assert bus.registers[reg.DLPF_FS] == reg.FS_SEL_2000 | 3   # 42 Hz below 50 Hz
    assert bus.registers[reg.SMPLRT_DIV] == 9
    assert bus.registers[reg.PWR_MGM] == reg.CLK_PLL_X
    assert gyro.rate_hz == 100.0
    assert sample_rate_divider(1000.0) == 0 and dlpf_for_rate(1000.0) == 1
    with pytest.raises(InputError, match='not 1 kHz / an integer'):
        sample_rate_divider(300.0)
    with pytest.raises(InputError, match='3.9-1000 Hz'):
        sample_rate_divider(3200.0)


def test_rates_are_scaled_to_rad_s_with_the_datasheet_noise():
    truth = (0.5, -0.2, 1.0)
    gyro, bus, clock = _gyro(truth, noise_deg_s=0.0, bias_rad_s=(0.01, 0.0, -0.02))
    gyro.configure(100.0)
    clock.now = 0.5
    assert gyro.data_ready()
    rate = gyro.read_rate_rad_s()
    lsb = math.radians(1.0) / reg.LSB_PER_DEG_S
    np.testing.assert_allclose(rate, np.add(truth, (0.01, 0.0, -0.02)), atol=lsb)
    assert not gyro.data_ready()   # the data read cleared RAW_DATA_RDY
    assert gyro.read_temperature_c() == pytest.approx(30.0, abs=0.01)
    noisy, _, clock = _gyro((0.0, 0.0, 0.0), seed=4)
    noisy.configure(100.0)
    samples = []
    for k in range(400):
        clock.now = 0.01 * (k + 1)
        samples.append(noisy.read_rate_rad_s())
    # the datasheet's 0.38 deg/s is at 100 Hz bandwidth; 100 Hz sampling sets 42 Hz
    expected = 0.38 * math.sqrt(noisy.bandwidth_hz / 100.0)
    assert noisy.bandwidth_hz == 42.0
    assert np.degrees(np.std(samples, axis=0)) == pytest.approx([expected] * 3, rel=0.15)


def test_saturation_and_io_errors():
    gyro, bus, clock = _gyro((50.0, 0.0, 0.0), noise_deg_s=0.0)
    gyro.configure(100.0)
    clock.now = 0.1
    rate = gyro.read_rate_rad_s()
    assert rate[0] == pytest.approx(32767 * math.radians(1.0) / reg.LSB_PER_DEG_S)
    assert Itg3205.saturated(rate)
    bus.fail_next(1)
    with pytest.raises(OSError):
        gyro.read_rate_rad_s()
    bus.fail_next(1)
    with pytest.raises(DeviceError, match='cannot read WHO_AM_I'):
        gyro.configure(100.0)


def test_driver_gyro_rates_and_backends():
    from accelcal_ros.driver.gyro_source import gyro_rate_hz, make_gyro

    # 1 kHz whatever the accelerometer's rate: the newest sample is at most 1 ms old
    assert [gyro_rate_hz(r) for r in (100.0, 400.0, 800.0, 3200.0)] == [1000.0] * 4
    assert make_gyro({'gyro': 'none'}, None) is None
    with pytest.raises(InputError, match='needs the i2c or sim backend'):
        make_gyro({'gyro': 'itg3205', 'gyro_i2c_address': 0x68, 'backend': 'replay'}, None)


@pytest.mark.parametrize('accel_hz, poll_s, gain', [(800.0, 0.04, 3.0), (100.0, 0.01, 1.5)])
def test_each_accelerometer_sample_gets_the_rate_at_its_stamp(accel_hz, poll_s, gain):
    from accelcal_ros.driver.gyro_source import GyroReader

    amp, freq = 0.3, 0.7   # rad/s, Hz: a vehicle's rates

    def truth(t):
        phase = 2 * math.pi * freq * t
        return (amp * math.sin(phase), 0.0, amp * math.cos(phase))
    clock = Clock()
    bus = SimulatedItg3205Bus(truth, clock=clock, noise_deg_s=0.0)
    reader = GyroReader(Itg3205(bus), accel_hz, poll_period_s=poll_s, clock=clock)
    # the low-pass is below half the poll rate (what is not read would alias)
    assert reader.device.bandwidth_hz <= 0.5 / poll_s
    code = bus.registers[reg.DLPF_FS] & 0x07
    assert reader.device.delay_s == reg.DLPF_DELAY_S[code]
    interp, held = [], []
    per_poll = int(round(poll_s * accel_hz))
    for k in range(1, 200):
        clock.now = k * poll_s
        rate = reader.read_stamped()
        # the accelerometer samples of this poll (the batch), on their own grid
        stamps = (np.arange((k - 1) * per_poll, k * per_poll) + 1) / accel_hz
        if k < 3:
            continue
        want = np.array([truth(s) for s in stamps])
        interp.append(np.array(reader.rates_at(stamps.tolist())) - want)
        held.append(np.array([rate] * len(stamps)) - want)   # one read for the whole batch
    interp_rms = math.sqrt(np.mean(np.concatenate(interp) ** 2))
    held_rms = math.sqrt(np.mean(np.concatenate(held) ** 2))
    # linear interpolation between reads: curvature * poll^2 / 8, plus the sample grid of
    # the chip (1 kHz, or its divider) and one LSB of quantisation
    grid = 1.0 / reader.rate_hz
    bound = (amp * (2 * math.pi * freq) ** 2 * poll_s ** 2 / 8.0
             + amp * 2 * math.pi * freq * grid + math.radians(1.0 / reg.LSB_PER_DEG_S))
    assert interp_rms <= bound
    # one read for the whole batch, as it was stamped: the delay and the batch's span
    assert interp_rms < held_rms / gain


def test_stated_gyro_variance_is_the_simulated_noise_of_the_low_pass():
    from accelcal_ros.driver.gyro_source import GyroReader

    clock = Clock()
    bus = SimulatedItg3205Bus(lambda t: (0.0, 0.0, 0.0), clock=clock, seed=2)
    reader = GyroReader(Itg3205(bus), 800.0, poll_period_s=0.04, clock=clock)
    reads = []
    for k in range(1, 2000):
        clock.now = k * 0.04
        reads.append(reader.read_stamped())
    std = np.std(np.array(reads), axis=0)
    # 10 Hz low-pass: 0.38 deg/s * sqrt(10 / 100) (the datasheet's rms is at 100 Hz)
    assert np.allclose(std, math.sqrt(reader.variance), rtol=0.1)
    assert math.sqrt(reader.variance) == pytest.approx(math.radians(0.38) * math.sqrt(0.1))


def test_drive_simulation_polls_the_gyro_as_the_driver_does():
    from accelcal_ros.driver.bus_timing import fifo_poll_period_s
    from accelcal_ros.sensor.drive_sim import gy85_poll_s

    for rate in (25.0, 100.0, 400.0, 800.0, 3200.0):
        assert gy85_poll_s(rate) == fifo_poll_period_s(rate)
