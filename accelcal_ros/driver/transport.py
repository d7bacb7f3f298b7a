"""
The one difference between the ADXL345 on I2C and on SPI: how a register is read or written.

Pure (no ROS). :class:`Adxl345 <accelcal_ros.driver.adxl345.Adxl345>` holds the register
map, the FIFO logic, the error handling and the stamps; a transport only moves bytes:

- :class:`I2cTransport`: an smbus2-like bus (``read_byte_data``, ``write_byte_data``,
  ``read_i2c_block_data``) and the 7-bit address (0x53 or 0x1D).
- :class:`SpiTransport`: a spidev-like device (``xfer2``); 4-wire, mode 3 (CPOL = CPHA =
  1), MSB first, the command byte first: bit 7 (0x80) set to read, bit 6 (0x40, MB) set
  for a multi-byte transfer, bits 5:0 the register (datasheet, "SPI", Figures 37-39).

Where Linux says the bus clock (the device tree's ``clock-frequency`` of an I2C adapter,
``spi-max-frequency`` of an SPI device, under ``/sys/.../of_node``), :func:`linux_bus_speed_hz`
reads it.
"""
import os
from typing import Any, List, Optional

from accelcal_ros.driver import adxl345_registers as reg
from accelcal_ros.errors import DeviceError

SPI_READ = 0x80
"""Command byte bit 7: read."""
SPI_MULTI_BYTE = 0x40
"""Command byte bit 6 (MB): the register address increments over a multi-byte transfer."""
SPI_MODE = 0b11
"""CPOL = 1, CPHA = 1 (datasheet, "SPI")."""


class Transport:
    """Register access of one ADXL345; subclasses say which bus."""

    kind = ''
    """``i2c`` or ``spi``."""

    def read_register(self, register: int) -> int:
        """Read one register (raises OSError on a bus error)."""
        return self.read_block(register, 1)[0]

    def read_block(self, register: int, length: int) -> List[int]:
        """Read ``length`` consecutive registers in one transaction."""
        raise NotImplementedError

    def write_register(self, register: int, value: int) -> None:
        """Write one register."""
        raise NotImplementedError

    def where(self) -> str:
        """Return where the device is, for messages (``I2C bus 1, address 0x53``)."""
        raise NotImplementedError

    def absent_hint(self) -> str:
        """Return what to check when no device answers."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the bus."""


class I2cTransport(Transport):
    """The ADXL345 at ``address`` on an smbus2-like ``bus``."""

    kind = 'i2c'

    def __init__(self, bus: Any, address: int = 0x53, bus_number: Optional[int] = None) -> None:
        self.bus = bus
        self.address = address
        self.bus_number = bus_number

    def read_register(self, register: int) -> int:
        """Read one register (SMBus read byte data)."""
        return int(self.bus.read_byte_data(self.address, register))

    def read_block(self, register: int, length: int) -> List[int]:
        """Read ``length`` registers from ``register`` (repeated-start block read)."""
        return list(self.bus.read_i2c_block_data(self.address, register, length))

    def write_register(self, register: int, value: int) -> None:
        """Write one register (SMBus write byte data)."""
        self.bus.write_byte_data(self.address, register, value)

    def where(self) -> str:
        """``I2C bus N, address 0xAA``."""
        bus = '?' if self.bus_number is None else self.bus_number
        return f'I2C bus {bus}, address 0x{self.address:02X}'

    def absent_hint(self) -> str:
        """Wiring and address hint."""
        return 'check wiring, power and the address (0x53 or 0x1D)'

    def close(self) -> None:
        """Close the smbus2 handle."""
        close = getattr(self.bus, 'close', None)
        if close is not None:
            close()


class SpiTransport(Transport):
    """The ADXL345 on a spidev-like ``device`` (``xfer2``), 4-wire SPI mode 3."""

    kind = 'spi'

    def __init__(self, device: Any, bus_number: Optional[int] = None,
                 chip_select: Optional[int] = None) -> None:
        self.device = device
        self.bus_number = bus_number
        self.chip_select = chip_select

    def read_block(self, register: int, length: int) -> List[int]:
        """One transfer: command byte (read, MB if ``length`` > 1), then ``length`` bytes."""
        command = SPI_READ | (SPI_MULTI_BYTE if length > 1 else 0) | (register & 0x3F)
        reply = self.device.xfer2([command] + [0] * length)
        return list(reply[1:])

    def write_register(self, register: int, value: int) -> None:
        """One transfer: command byte (write), value."""
        self.device.xfer2([register & 0x3F, value & 0xFF])

    def where(self) -> str:
        """``SPI bus B, chip select C``."""
        bus = '?' if self.bus_number is None else self.bus_number
        cs = '?' if self.chip_select is None else self.chip_select
        return f'SPI bus {bus}, chip select {cs}'

    def absent_hint(self) -> str:
        """Wiring hint (an absent SPI device reads all zeros or all ones)."""
        return ('no device answers: check wiring (SDO to MISO, SDI to MOSI, SCLK, CS to '
                'this chip select), power, and that nothing else drives MISO')

    def close(self) -> None:
        """Close the spidev handle."""
        close = getattr(self.device, 'close', None)
        if close is not None:
            close()


def setup_spi(device: Any, speed_hz: float) -> None:
    """Mode 3 (CPOL = CPHA = 1), 8-bit words, MSB first, ``speed_hz`` on a spidev-like device."""
    device.mode = SPI_MODE
    device.bits_per_word = 8
    device.max_speed_hz = int(speed_hz)


def open_spidev(bus_number: int, chip_select: int, speed_hz: float) -> Any:
    """Open ``/dev/spidev<bus>.<cs>`` with spidev in mode 3 at ``speed_hz``; DeviceError if not."""
    path = f'/dev/spidev{bus_number}.{chip_select}'
    if not os.path.exists(path):
        raise DeviceError(f'SPI bus {bus_number}, chip select {chip_select}: {path} does not '
                          'exist (is SPI enabled, e.g. dtparam=spi=on on a Raspberry Pi, and '
                          'are spi_bus and spi_device right? see `ls /dev/spidev*`)')
    try:
        import spidev
    except ImportError as exc:
        raise DeviceError('the spi backend needs spidev (pip: spidev, apt: '
                          'python3-spidev)') from exc
    device = spidev.SpiDev()
    try:
        device.open(bus_number, chip_select)
        setup_spi(device, speed_hz)
    except OSError as exc:
        device.close()
        raise DeviceError(f'SPI bus {bus_number}, chip select {chip_select}: cannot open '
                          f'{path}: {exc.strerror or exc} (permissions? add the user to the '
                          'spi group)') from exc
    return device


def linux_bus_speed_hz(bus: str, bus_number: int, chip_select: int = 0,
                       sysfs: str = '/sys') -> Optional[float]:
    """
    Return the bus clock Linux's device tree gives (Hz), or None where it says nothing.

    I2C: ``<sysfs>/bus/i2c/devices/i2c-N/of_node/clock-frequency``; SPI:
    ``<sysfs>/bus/spi/devices/spiB.C/of_node/spi-max-frequency`` (both big-endian u32).
    """
    if bus == 'i2c':
        path = os.path.join(sysfs, 'bus', 'i2c', 'devices', f'i2c-{bus_number}', 'of_node',
                            'clock-frequency')
    else:
        path = os.path.join(sysfs, 'bus', 'spi', 'devices', f'spi{bus_number}.{chip_select}',
                            'of_node', 'spi-max-frequency')
    try:
        with open(path, 'rb') as handle:
            raw = handle.read(4)
    except OSError:
        return None
    if len(raw) != 4:
        return None
    value = int.from_bytes(raw, 'big')
    return float(value) if value > 0 else None


def devid_absent(value: int) -> bool:
    """Return whether DEVID 0x00 or 0xFF: nothing drives the data line (not another chip)."""
    return value in (0x00, 0xFF) and value != reg.DEVID_VALUE
