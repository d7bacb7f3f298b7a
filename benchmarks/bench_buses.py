"""
Benchmark the ADXL345 driver on the register-level simulated buses (no ROS graph).

For I2C at 100/400 kHz and SPI at 2/5 MHz, at each output data rate, polling and
interrupt reads (INT1 watermark, simulated line), the driver's own code drains the
simulated chip in real time with every transaction charged its wire time. Printed per
row: whether the start-up check accepts the rate, the achieved rate, samples the FIFO
dropped (the chip's count), bus busy %, the driver's CPU per sample (process time,
simulation included) and the stamp jitter (standard deviation of the stamp steps minus
the period, us). Run after ``source tools/env.sh``::

    python benchmarks/bench_buses.py [--seconds 1.5] [--rates 200 800 3200]

Anchors (no figures of theirs are claimed here): Adafruit's CircuitPython ADXL34x driver
reads one sample per ``acceleration`` call over I2C, without the FIFO, so its rate is the
host's call rate; the Linux kernel's adxl345 IIO driver (I2C and SPI) drains the FIFO on
the watermark interrupt in the kernel.
"""
import argparse
import time

from accelcal_ros.driver.params import DRIVER_PARAMS, make_source
from accelcal_ros.errors import InputError
import numpy as np

BUSES = (('i2c', 100e3), ('i2c', 400e3), ('spi', 2e6), ('spi', 5e6))


def measure(bus, speed, rate, reads, seconds):
    """Return a dict of figures for one configuration."""
    values = {s.name: s.default for s in DRIVER_PARAMS}
    values.update(backend='sim', rate_hz=float(rate), reads=reads, bus_speed_hz=speed,
                  allow_unsustainable_rate=True, fifo='always',
                  **{'sim.bus': bus, 'sim.poses_deg': [0.0, 0.0]})
    try:
        values['allow_unsustainable_rate'] = False
        make_source(values)
        accepted = 'yes'
    except InputError:
        accepted = 'no'
    values['allow_unsustainable_rate'] = True
    source = make_source(values)
    chip = source.sim_chip
    source.start()
    stamps = []
    cpu0, wall0, busy0 = time.process_time(), time.monotonic(), chip.busy_s
    generated0 = chip.generated
    end = time.time() + seconds
    while time.time() < end:
        time.sleep(max(0.0, source.next_poll_time() - time.time()))
        stamps.extend(source.poll().stamps)
    wall = time.monotonic() - wall0
    cpu = time.process_time() - cpu0
    steps = np.diff(stamps)
    jitter = float(np.std(steps[steps < 1.5 / rate] - 1.0 / rate)) * 1e6 if len(steps) else 0.0
    return {'bus': f'{bus.upper()} {speed / 1e3:g} kHz' if speed < 1e6
            else f'{bus.upper()} {speed / 1e6:g} MHz', 'rate': rate, 'reads': reads,
            'accepted': accepted, 'achieved': len(stamps) / wall,
            'dropped': chip.dropped, 'generated': chip.generated - generated0,
            'busy': 100 * (chip.busy_s - busy0) / wall,
            'cpu_us': 1e6 * cpu / max(len(stamps), 1), 'jitter_us': jitter}


def main():
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=1.5)
    parser.add_argument('--rates', type=float, nargs='*',
                        default=[100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0])
    args = parser.parse_args()
    header = (f'{"bus":<12} {"ODR Hz":>7} {"reads":<9} {"accepted":>8} {"achieved Hz":>11} '
              f'{"dropped":>7} {"bus %":>6} {"CPU us/sample":>13} {"jitter us":>9}')
    print(header)
    print('-' * len(header))
    for bus, speed in BUSES:
        for rate in args.rates:
            for reads in ('polling', 'interrupt'):
                r = measure(bus, speed, rate, reads, args.seconds)
                print(f'{r["bus"]:<12} {rate:>7g} {reads:<9} {r["accepted"]:>8} '
                      f'{r["achieved"]:>11.0f} {r["dropped"]:>7d} {r["busy"]:>6.1f} '
                      f'{r["cpu_us"]:>13.1f} {r["jitter_us"]:>9.1f}')


if __name__ == '__main__':
    main()
