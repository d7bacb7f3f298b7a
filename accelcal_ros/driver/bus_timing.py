"""
Time on the wire of ADXL345 transactions over I2C and SPI, and which rates a bus sustains.

Pure (no ROS, no I/O). Sources (Analog Devices ADXL345 datasheet, Rev. G):

- I2C (Table 12, fast mode up to 400 kHz; standard-mode figures from the I2C-bus
  specification NXP UM10204 Table 10 below 400 kHz): each byte is 8 data bits plus the
  acknowledge, 9 SCL periods. A START costs ``t_HD,STA``, a repeated START
  ``t_SU,STA + t_HD,STA``, a STOP ``t_SU,STO + t_BUF`` (the bus-free time before the
  next START). A register read is START, address+W, register, repeated START,
  address+R, ``n`` data bytes, STOP; a register write is START, address+W, register,
  value, STOP (Figure 41). Clock stretching is ignored (the ADXL345 does not stretch).
- SPI (Table 10, up to 5 MHz, CPOL = CPHA = 1): 8 SCLK periods per byte, the command
  byte (R/W bit 7 = 0x80, MB bit 6 = 0x40 for multi-byte) first; chip-select overhead
  ``t_DELAY + t_QUIET + t_CS,DIS`` = 5 + 5 + 150 ns. Reading a FIFO entry (the data
  registers) needs 5 us before the next FIFO or FIFO_STATUS read; the next command byte
  counts towards it, so above 1.6 MHz chip select stays high for the rest (FIFO section:
  "at most 3.4 us" at 5 MHz).
- The datasheet's rule (Table 7, notes): 3200 Hz and 1600 Hz only over SPI at >= 2 MHz;
  800 Hz only at >= 400 kHz, lower rates proportionally (200 Hz at >= 100 kHz).

:func:`check_rate` applies the rule and the computed FIFO read time with a margin: the
bus may be busy at most ``MAX_BUS_LOAD`` of the time.
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

from accelcal_ros.sensor.datasheet import OUTPUT_DATA_RATES_HZ

I2C_MAX_HZ = 400_000.0
"""ADXL345 I2C clock limit (datasheet Table 12, f_SCL)."""
SPI_MAX_HZ = 5_000_000.0
"""ADXL345 SPI clock limit (datasheet Table 10, f_SCLK)."""
BUS_MIN_HZ = 10_000.0
"""Slowest clock accepted (I2C standard mode starts at 10 kHz in practice)."""

I2C_CLOCKS_PER_BYTE = 9
SPI_CLOCKS_PER_BYTE = 8
# (t_HD,STA, t_SU,STA, t_SU,STO, t_BUF) in s: fast mode (ADXL345 Table 12), standard mode
# (UM10204 Table 10, 100 kHz)
I2C_FAST_CONDITIONS_S = (0.6e-6, 0.6e-6, 0.6e-6, 1.3e-6)
I2C_STANDARD_CONDITIONS_S = (4.0e-6, 4.7e-6, 4.0e-6, 4.7e-6)
SPI_CS_OVERHEAD_S = 5e-9 + 5e-9 + 150e-9
"""t_DELAY + t_QUIET + t_CS,DIS (datasheet Table 10)."""
FIFO_POP_DELAY_S = 5e-6
"""Time after a FIFO entry is read before the next FIFO or FIFO_STATUS read."""
SAMPLE_BYTES = 6
"""One sample: DATAX0..DATAZ1 in one multi-byte read (pops one FIFO entry)."""
STATUS_READS_PER_POLL = 2
"""A FIFO drain first reads INT_SOURCE (overrun) and FIFO_STATUS (entries)."""
MAX_BUS_LOAD = 0.5
"""Margin: the driver's reads may fill at most half of the bus time."""


def i2c_conditions_s(speed_hz: float) -> Dict[str, float]:
    """START, repeated START and STOP (+ bus free) times in s at ``speed_hz``."""
    hd_sta, su_sta, su_sto, buf = (I2C_FAST_CONDITIONS_S if speed_hz > 100_000.0
                                   else I2C_STANDARD_CONDITIONS_S)
    return {'start': hd_sta, 'repeated_start': su_sta + hd_sta, 'stop': su_sto + buf}


@dataclass(frozen=True)
class Transaction:
    """One bus transaction: bytes on the wire and its time (s)."""

    name: str
    wire_bytes: int
    seconds: float


def i2c_read_s(speed_hz: float, data_bytes: int) -> float:
    """Time (s) of an I2C register read of ``data_bytes`` bytes (address, register, data)."""
    cond = i2c_conditions_s(speed_hz)
    clocks = I2C_CLOCKS_PER_BYTE * (3 + data_bytes)
    return clocks / speed_hz + cond['start'] + cond['repeated_start'] + cond['stop']


def i2c_write_s(speed_hz: float, data_bytes: int = 1) -> float:
    """Time (s) of an I2C register write of ``data_bytes`` bytes."""
    cond = i2c_conditions_s(speed_hz)
    return I2C_CLOCKS_PER_BYTE * (2 + data_bytes) / speed_hz + cond['start'] + cond['stop']


def spi_transfer_s(speed_hz: float, data_bytes: int, pops_fifo: bool = False) -> float:
    """
    Time (s) of an SPI read or write of ``data_bytes`` after the command byte.

    ``pops_fifo``: the transfer read a FIFO entry; chip select then stays high until
    ``FIFO_POP_DELAY_S`` minus the next command byte has passed.
    """
    command_s = SPI_CLOCKS_PER_BYTE / speed_hz
    seconds = (1 + data_bytes) * command_s + SPI_CS_OVERHEAD_S
    if pops_fifo:
        seconds += max(FIFO_POP_DELAY_S - command_s - SPI_CS_OVERHEAD_S, 0.0)
    return seconds


def wire_bytes(bus: str, data_bytes: int, write: bool = False) -> int:
    """Bytes on the wire of one register transaction (I2C addresses counted)."""
    if bus == 'i2c':
        return (2 if write else 3) + data_bytes
    return 1 + data_bytes


def transaction_s(bus: str, speed_hz: float, data_bytes: int, write: bool = False,
                  pops_fifo: bool = False) -> float:
    """Time (s) of one register read or write on ``bus`` (``i2c`` or ``spi``)."""
    if bus == 'i2c':
        return i2c_write_s(speed_hz, data_bytes) if write else i2c_read_s(speed_hz, data_bytes)
    return spi_transfer_s(speed_hz, data_bytes, pops_fifo)


def transactions(bus: str, speed_hz: float) -> List[Transaction]:
    """Return the driver's transactions at ``speed_hz`` (register write, status, sample)."""
    return [
        Transaction('register write (1 byte)', wire_bytes(bus, 1, write=True),
                    transaction_s(bus, speed_hz, 1, write=True)),
        Transaction('register read (1 byte)', wire_bytes(bus, 1),
                    transaction_s(bus, speed_hz, 1)),
        Transaction('sample / FIFO entry (6 bytes)', wire_bytes(bus, SAMPLE_BYTES),
                    transaction_s(bus, speed_hz, SAMPLE_BYTES, pops_fifo=True)),
    ]


def fifo_poll_period_s(rate_hz: float) -> float:
    """
    How often the driver drains the FIFO at ``rate_hz`` (s).

    Every two samples but at most every 2.5 ms and at least every 20 ms: batches stay
    small (sensor-data subscribers keep 5 messages), far from the FIFO's 32 entries.
    """
    return min(max(2.0 / rate_hz, 0.0025), 0.02)


def bus_load(bus: str, speed_hz: float, rate_hz: float, use_fifo: bool = True) -> float:
    """Fraction of the bus time the driver's reads fill at ``rate_hz`` (1.0: saturated)."""
    sample_s = transaction_s(bus, speed_hz, SAMPLE_BYTES, pops_fifo=use_fifo)
    load = rate_hz * sample_s
    if use_fifo:
        load += STATUS_READS_PER_POLL * transaction_s(bus, speed_hz, 1) \
            / fifo_poll_period_s(rate_hz)
    return load


def datasheet_min_speed_hz(rate_hz: float) -> float:
    """Slowest bus clock the datasheet recommends for ``rate_hz`` (Table 7, notes)."""
    if rate_hz >= 1600.0:
        return 2_000_000.0
    return rate_hz * (400_000.0 / 800.0)


def datasheet_allows(bus: str, speed_hz: float, rate_hz: float) -> bool:
    """Apply the datasheet's rule: 1600/3200 Hz only on SPI >= 2 MHz, else >= 500 x rate."""
    if rate_hz >= 1600.0 and bus != 'spi':
        return False
    return speed_hz >= datasheet_min_speed_hz(rate_hz) * (1.0 - 1e-9)


def sustainable(bus: str, speed_hz: float, rate_hz: float, use_fifo: bool = True) -> bool:
    """Whether ``rate_hz`` passes the datasheet rule and the bus-time margin."""
    return (datasheet_allows(bus, speed_hz, rate_hz)
            and bus_load(bus, speed_hz, rate_hz, use_fifo) <= MAX_BUS_LOAD)


def fastest_rate_hz(bus: str, speed_hz: float,
                    rates: Sequence[float] = OUTPUT_DATA_RATES_HZ) -> Optional[float]:
    """Return the highest output data rate sustainable on ``bus`` at ``speed_hz`` (or None)."""
    ok = [r for r in rates if sustainable(bus, speed_hz, r, use_fifo=r > 100.0)]
    return max(ok) if ok else None


def speed_text(speed_hz: float) -> str:
    """``100 kHz``, ``5 MHz``."""
    if speed_hz >= 1e6:
        return f'{speed_hz / 1e6:g} MHz'
    return f'{speed_hz / 1e3:g} kHz'


def check_speed(bus: str, speed_hz: float) -> Optional[str]:
    """Reason why ``speed_hz`` is outside the ADXL345's range on ``bus``, or None."""
    limit = I2C_MAX_HZ if bus == 'i2c' else SPI_MAX_HZ
    if speed_hz > limit:
        return (f'bus_speed_hz {speed_hz:g} is above the ADXL345 {bus.upper()} maximum of '
                f'{speed_text(limit)} (datasheet Table {12 if bus == "i2c" else 10})')
    if speed_hz < BUS_MIN_HZ:
        return f'bus_speed_hz {speed_hz:g} is below {speed_text(BUS_MIN_HZ)}'
    return None


def check_rate(bus: str, speed_hz: float, rate_hz: float, use_fifo: bool) -> Optional[str]:
    """
    Why ``rate_hz`` is not sustainable on ``bus`` at ``speed_hz`` (one line), or None.

    The line names the limit (datasheet rule or bus time) and the fastest rate that works.
    """
    where = f'{bus.upper()} at {speed_text(speed_hz)}'
    fastest = fastest_rate_hz(bus, speed_hz)
    best = ('no output data rate works here' if fastest is None
            else f'the fastest rate that works here is {fastest:g} Hz')
    if not datasheet_allows(bus, speed_hz, rate_hz):
        if rate_hz >= 1600.0:
            rule = f'the ADXL345 datasheet recommends {rate_hz:g} Hz only over SPI at >= 2 MHz'
        else:
            rule = (f'the ADXL345 datasheet recommends {rate_hz:g} Hz only at >= '
                    f'{speed_text(datasheet_min_speed_hz(rate_hz))}')
        sample_us = transaction_s(bus, speed_hz, SAMPLE_BYTES, pops_fifo=use_fifo) * 1e6
        load = bus_load(bus, speed_hz, rate_hz, use_fifo)
        return (f'rate_hz {rate_hz:g} is not sustainable on {where}: {rule} (one sample read '
                f'takes {sample_us:.0f} us here, {100 * load:.0f} % of the bus at '
                f'{rate_hz:g} Hz); {best}')
    load = bus_load(bus, speed_hz, rate_hz, use_fifo)
    if load > MAX_BUS_LOAD:
        return (f'rate_hz {rate_hz:g} is not sustainable on {where}: the reads would fill '
                f'{100 * load:.0f} % of the bus (limit {100 * MAX_BUS_LOAD:.0f} %); {best}')
    return None


def timing_table(speeds: Sequence[tuple] = (('i2c', 100_000.0), ('i2c', 400_000.0),
                                            ('spi', 2_000_000.0), ('spi', 5_000_000.0))
                 ) -> str:
    """Markdown table: bytes and us per transaction, and the fastest rate, per bus speed."""
    lines = ['| bus | speed | transaction | bytes on the wire | us |', '|---|---|---|---|---|']
    for bus, speed in speeds:
        for t in transactions(bus, speed):
            lines.append(f'| {bus.upper()} | {speed_text(speed)} | {t.name} | {t.wire_bytes} '
                         f'| {t.seconds * 1e6:.1f} |')
    lines += ['', '| bus | speed | fastest sustainable rate (Hz) | bus load at that rate |',
              '|---|---|---|---|']
    for bus, speed in speeds:
        fastest = fastest_rate_hz(bus, speed)
        load = bus_load(bus, speed, fastest, fastest > 100.0) if fastest else float('nan')
        lines.append(f'| {bus.upper()} | {speed_text(speed)} | {fastest:g} | '
                     f'{100 * load:.0f} % |')
    return '\n'.join(lines)
