"""
The one rule for reported uncertainties (shared floor): never smaller than a known error.

A reported standard deviation, covariance or predicted error comes from a model of the
noise; a check inside the program (a hold-out, two half fits, a search limit reached)
may already know of a larger error. :func:`floor_at_known_error` raises the reported
value to that error and returns why, so that the output says so (a warning, a report
key). Where it is applied is listed in ``docs/formats.md`` ("Uncertainties").
"""
from dataclasses import dataclass
import math
from typing import Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class KnownError:
    """An error (same unit as the reported value) that a check knows of, and the check."""

    value: float
    why: str


def floor_at_known_error(reported: float, known: Sequence[Optional[KnownError]],
                         unit: str = '', name: str = 'uncertainty'
                         ) -> Tuple[float, Optional[str]]:
    """
    Return ``(max(reported, largest known error), note)``; ``note`` None when unchanged.

    ``known`` entries that are None or not finite-positive are ignored; a non-finite
    ``reported`` (already "unknown") stays as it is. The note names the quantity, both
    values and the check that knew the error.
    """
    candidates = [k for k in known if k is not None and math.isfinite(k.value) and k.value > 0]
    if not candidates or not math.isfinite(reported):
        return reported, None
    worst = max(candidates, key=lambda k: k.value)
    if worst.value <= reported:
        return reported, None
    return worst.value, (f'{name} raised from {reported:.3g}{unit} to {worst.value:.3g}{unit}: '
                         f'{worst.why}')


def floor_each_at_known_error(reported: ArrayLike,
                              known: Sequence[Optional[KnownError]], unit: str = '',
                              name: str = 'uncertainty'
                              ) -> Tuple[np.ndarray, Optional[str]]:
    """Apply :func:`floor_at_known_error` to each value of ``reported``; one note for all."""
    values = np.asarray(reported, dtype=float).reshape(-1).copy()
    notes = []
    for k, value in enumerate(values.tolist()):
        values[k], note = floor_at_known_error(value, known, unit, name)
        if note is not None:
            notes.append(note)
    if not notes:
        return values, None
    return values, notes[0] if len(notes) == 1 else (
        f'{name} raised to at least {np.max(values):.3g}{unit} ({len(notes)} values): '
        + notes[0].split(': ', 1)[1])


__all__ = ['floor_at_known_error', 'floor_each_at_known_error', 'KnownError']
