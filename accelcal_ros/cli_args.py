"""
Argument types of the ``accelcal`` command line: numbers checked where they are parsed.

Each function is an ``argparse`` ``type=``: it converts the text and raises
``argparse.ArgumentTypeError`` with the reason, so a bad value is a one-line usage error
(exit status 2) before any work starts. Every numeric option of every feature's
``cli.py`` uses one of them; none accepts NaN or infinity.

``finite_float``     any finite number (angles, offsets, times that may be negative)
``positive_float``   > 0 (durations, rates, windows, thresholds, sizes)
``nonnegative_float`` >= 0 (0 meaning "off")
``positive_int``     integer >= 1 (counts, trials, pixel sizes)
``nonnegative_int``  integer >= 0 (seeds, bus numbers, "0 = skip" counts)
``probability``      0 <= p <= 1
``float_in(lo, hi)`` / ``int_in(lo, hi)``  closed ranges (``None``: unbounded side)
``angle_deg(limit)`` finite angle with |value| <= limit degrees
"""
import argparse
import math
from typing import Callable, Optional

__all__ = ['angle_deg', 'finite_float', 'float_in', 'int_in', 'nonnegative_float',
           'nonnegative_int', 'positive_float', 'positive_int', 'probability']


def finite_float(text: str) -> float:
    """Return ``text`` as a finite number (no NaN, no infinity)."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text!r}: give a finite number')
    return value


def _int(text: str) -> int:
    try:
        return int(text, 0) if isinstance(text, str) and text.strip().lower().startswith(
            ('0x', '0o', '0b')) else int(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from None


def float_in(low: Optional[float] = None, high: Optional[float] = None, low_open: bool = False,
             high_open: bool = False) -> Callable[[str], float]:
    """Type of a finite number in [low, high] (open ends with ``low_open``/``high_open``)."""
    def check(text: str) -> float:
        value = finite_float(text)
        if low is not None and (value <= low if low_open else value < low):
            raise argparse.ArgumentTypeError(
                f'{text!r}: must be {">" if low_open else ">="} {low:g}')
        if high is not None and (value >= high if high_open else value > high):
            raise argparse.ArgumentTypeError(
                f'{text!r}: must be {"<" if high_open else "<="} {high:g}')
        return value
    check.__name__ = 'number'
    return check


def int_in(low: Optional[int] = None, high: Optional[int] = None) -> Callable[[str], int]:
    """Type of an integer in [low, high] (``None``: unbounded)."""
    def check(text: str) -> int:
        value = _int(text)
        if low is not None and value < low:
            raise argparse.ArgumentTypeError(f'{text!r}: must be at least {low}')
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f'{text!r}: must be at most {high}')
        return value
    check.__name__ = 'integer'
    return check


def positive_float(text: str) -> float:
    """Return ``text`` as a finite number > 0."""
    return float_in(0.0, low_open=True)(text)


def nonnegative_float(text: str) -> float:
    """Return ``text`` as a finite number >= 0."""
    return float_in(0.0)(text)


def probability(text: str) -> float:
    """Return ``text`` as a number in [0, 1]."""
    return float_in(0.0, 1.0)(text)


def positive_int(text: str) -> int:
    """Return ``text`` as an integer >= 1."""
    return int_in(1)(text)


def nonnegative_int(text: str) -> int:
    """Return ``text`` as an integer >= 0."""
    return int_in(0)(text)


def angle_deg(limit: float = 360.0) -> Callable[[str], float]:
    """Type of a finite angle in degrees with ``|value| <= limit``."""
    return float_in(-limit, limit)
