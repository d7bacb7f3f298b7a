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
    assert np.degrees(np.std(samples, axis=0)) == pytest.approx([0.38] * 3, rel=0.15)


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

    assert [gyro_rate_hz(r) for r in (100.0, 400.0, 800.0, 3200.0)] == \
        [100.0, 1000.0 / 3, 500.0, 1000.0]
    assert make_gyro({'gyro': 'none'}, None) is None
    with pytest.raises(InputError, match='needs the i2c or sim backend'):
        make_gyro({'gyro': 'itg3205', 'gyro_i2c_address': 0x68, 'backend': 'replay'}, None)
