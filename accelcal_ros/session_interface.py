"""
The one calibration interface of every calibration node (pure part: rules, keys, texts).

Every calibration node (``calibration``, ``rig_calibration``, ``lidar_calibration``, and
any later one) offers the same session, wired by
:class:`accelcal_ros.rosutil.calibration_interface.CalibrationInterface`:

- ``<node>/start`` (std_srvs/Trigger) opens a session; refused while one runs.
- ``<node>/capture`` takes the current still position now; refused without a session
  (and with the node's reason when the position cannot be taken: moving, no data).
- ``<node>/cancel`` discards the session's captures; refused without a session.
- ``<node>/finish`` solves, writes ``output_file`` and ends the session; refused without
  a session, with nothing captured (the answer says how to capture) and when the solve
  fails (the session stays open: capture more and call finish again).
- ``<node>/status`` (diagnostic_msgs/DiagnosticStatus, reliable, transient local: a late
  joiner gets the latest) after every change and every ``status_period_s`` while a
  session runs, with the keys :data:`STATUS_KEYS` (same meaning on every node; empty
  when the node does not know the value yet) plus the node's own.
- ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) carries the same status every
  ``status_period_s``, session or not.

:class:`SessionState` holds the refusals, so the three nodes say the same words.
"""
from dataclasses import dataclass, field
from typing import Dict, Optional

from accelcal_ros.errors import CalibrationError
from accelcal_ros.paramspec import ParamSpec

SERVICES = ('start', 'capture', 'cancel', 'finish')
"""The Trigger services of every calibration node, under ``<node>/``."""

STATUS_KEYS = ('active', 'captures', 'captures_needed', 'coverage_percent',
               'predicted_error_deg', 'hint', 'last_event', 'output_file')
"""
Keys every calibration status carries, in this order.

``active`` (true/false), ``captures`` (positions or poses captured in this session, or
used by the last result when idle), ``captures_needed`` (the fewest finish accepts),
``coverage_percent`` (how much of what the calibration needs the captures cover, 0-100),
``predicted_error_deg`` (95 % bound of the result's angle error: predicted from the
captures while a session runs, from the solve after finish), ``hint`` (what to do next),
``last_event`` (the latest capture, refusal or result), ``output_file``.
"""

OK, WARN, ERROR = 0, 1, 2
"""Levels of diagnostic_msgs/DiagnosticStatus (the byte values)."""


def no_samples_reason(topic: str, skipped: int = 0) -> str:
    """
    Return the capture refusal of every calibration node with no usable IMU sample yet.

    ``topic`` is the resolved topic (a remapping shows), ``skipped`` the samples dropped
    since ``start`` for their header stamps. Without it a node said "moving": the user
    looked for vibration when nothing arrived.
    """
    why = (f'{skipped} skipped for their header stamps (0, or not increasing)' if skipped
           else 'is the driver running, is the topic remapped?')
    return f'no usable sample on {topic} since start: {why}'


def status_period_spec(node: str) -> ParamSpec:
    """Return the ``status_period_s`` parameter every calibration node declares."""
    return ParamSpec('status_period_s', 1.0, f'Period of {node}/status while a session '
                     'runs and of /diagnostics (the status is also published after every '
                     'change).', minimum=0.05, maximum=60.0, unit='s')


@dataclass
class SessionProgress:
    """
    What a calibration node reports (the values of :data:`STATUS_KEYS` it knows).

    ``coverage`` is a fraction (0-1) or None; ``predicted_error_deg`` None when not known
    yet; ``extra`` the node's own keys (strings). ``message`` and ``level`` (OK, WARN,
    ERROR) override the default one-line summary.
    """

    captures: int
    captures_needed: int
    coverage: Optional[float] = None
    predicted_error_deg: Optional[float] = None
    hint: str = ''
    extra: Dict[str, str] = field(default_factory=dict)
    message: str = ''
    level: int = OK


def status_values(progress: SessionProgress, active: bool, last_event: str,
                  output_file: str) -> Dict[str, str]:
    """Return the status key/values: :data:`STATUS_KEYS` first, then the node's extras."""
    values = {
        'active': 'true' if active else 'false',
        'captures': str(int(progress.captures)),
        'captures_needed': str(int(progress.captures_needed)),
        'coverage_percent': ('' if progress.coverage is None
                             else f'{100.0 * progress.coverage:.0f}'),
        'predicted_error_deg': ('' if progress.predicted_error_deg is None
                                else f'{progress.predicted_error_deg:.4f}'),
        'hint': progress.hint,
        'last_event': last_event,
        'output_file': output_file,
    }
    for key, value in progress.extra.items():
        values.setdefault(key, str(value))
    return values


def status_message(node: str, progress: SessionProgress, active: bool) -> str:
    """Return the status' one-line message (the node's own, or a summary of the counts)."""
    if progress.message:
        return progress.message
    if active:
        text = f'session running: {progress.captures} of {progress.captures_needed} captures'
        return f'{text}; {progress.hint}' if progress.hint else text
    return f'idle: call {node}/start'


class SessionState:
    """
    Whether a session runs, and the refusals every calibration node gives.

    ``node`` is the node's name (the services' prefix in the texts).
    """

    def __init__(self, node: str) -> None:
        self.node = node
        self.active = False

    def check_start(self, captures: int) -> None:
        """Refuse a second start while a session runs."""
        if self.active:
            raise CalibrationError(
                f'a calibration session is already running ({captures} captures); call '
                f'{self.node}/finish to solve it or {self.node}/cancel to discard it first')

    def check_active(self, what: str) -> None:
        """Refuse ``what`` (capture, cancel, finish) without a session."""
        if not self.active:
            raise CalibrationError(f'cannot {what}: no calibration session is running; '
                                   f'call {self.node}/start first')

    def check_finish(self, captures: int, how_to_capture: str) -> None:
        """Refuse finish without a session or with nothing captured (say how to capture)."""
        self.check_active('finish')
        if captures <= 0:
            raise CalibrationError(f'nothing captured yet: {how_to_capture}; then call '
                                   f'{self.node}/finish')

    def solve_failed(self, reason: str) -> str:
        """Return the refusal of a failed solve (the session stays open)."""
        return (f'{reason}; the session stays open: capture more and call '
                f'{self.node}/finish again (or {self.node}/cancel)')
