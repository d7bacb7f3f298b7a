"""
The calibration interface of every calibration node, wired once (services, status, diagnostics).

A calibration node builds one :class:`CalibrationInterface` with a *backend*, an object
with these methods (called from the executor; the backend takes its own lock):

- ``begin() -> str``: open a session (fresh captures); returns the answer's text.
- ``capture() -> str``: capture now; raises :class:`~accelcal_ros.errors.AccelcalError`
  with the reason when it cannot.
- ``discard() -> int``: drop the session's captures; returns how many.
- ``solve() -> str``: solve and write the output; raises AccelcalError (or OSError)
  when it cannot (the session then stays open).
- ``progress(active: bool) ->``
  :class:`~accelcal_ros.session_interface.SessionProgress`.
- ``output_file() -> str``: the path finish writes (expanded).
- ``status_published(active: bool)`` (optional): called after each status is published
  (e.g. the calibration node's coverage markers go out with it).

The interface offers ``<node>/start``, ``capture``, ``cancel``, ``finish``
(std_srvs/Trigger), publishes ``<node>/status`` (diagnostic_msgs/DiagnosticStatus,
reliable, transient local) and ``/diagnostics``, and gives the refusals of
:class:`~accelcal_ros.session_interface.SessionState` (see
:mod:`accelcal_ros.session_interface` for the rules and the status keys). The node
reports its own events (automatic captures, warnings) with :meth:`event`.
"""
from accelcal_ros.errors import AccelcalError
from accelcal_ros.rosutil.diagnostics import (diagnostic_status, diagnostics_publisher,
                                              PeriodicTimer, publish_diagnostics)
from accelcal_ros.session_interface import SessionState, status_message, status_values
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger


class CalibrationInterface:
    """
    Services, status topic and diagnostics of one calibration node around its backend.

    ``title`` names the calibration in the status (``<node>: <title>``); ``how_to_capture``
    is the text a finish with nothing captured answers; ``status_period_s`` the period of
    the status (while a session runs) and of ``/diagnostics`` (:meth:`set_period`
    changes it at run time).
    """

    def __init__(self, node, backend, title, hardware_id, how_to_capture,
                 status_period_s=1.0):
        self.node = node
        self.backend = backend
        self.name = node.get_name()
        self.title = title
        self.hardware_id = hardware_id
        self.how_to_capture = how_to_capture
        self.state = SessionState(self.name)
        self.last_event = ''
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.status_pub = node.create_publisher(DiagnosticStatus, f'{self.name}/status', qos)
        self.diagnostics_pub = diagnostics_publisher(node)
        handlers = {'start': self._on_start, 'capture': self._on_capture,
                    'cancel': self._on_cancel, 'finish': self._on_finish}
        self.services = [node.create_service(Trigger, f'{self.name}/{what}', handler)
                         for what, handler in handlers.items()]
        self._timer = PeriodicTimer(node, status_period_s, self._on_timer)
        self.publish()

    @property
    def active(self):
        """Return True while a session runs."""
        return self.state.active

    def set_period(self, period_s):
        """(Re)start the status and diagnostics timer with ``period_s`` seconds."""
        self._timer.set_period(period_s)

    # -- events and status ----------------------------------------------------------------
    def event(self, text, level='info'):
        """Log ``text`` (info, warning or error), make it the last event, publish the status."""
        logger = self.node.get_logger()
        if level == 'error':   # one call site per severity (rclpy requires it)
            logger.error(text)
        elif level == 'warning':
            logger.warning(text)
        else:
            logger.info(text)
        self.last_event = text
        self.publish()

    def _status(self):
        progress = self.backend.progress(self.state.active)
        values = status_values(progress, self.state.active, self.last_event,
                               self.backend.output_file())
        message = status_message(self.name, progress, self.state.active)
        return diagnostic_status(f'{self.name}: {self.title}', self.hardware_id,
                                 progress.level, message, values)

    def publish(self):
        """Publish the current status on ``<node>/status``."""
        status = self._status()
        self.status_pub.publish(status)
        hook = getattr(self.backend, 'status_published', None)
        if hook is not None:
            hook(self.state.active)
        return status

    def _on_timer(self):
        status = self.publish() if self.state.active else self._status()
        publish_diagnostics(self.node, self.diagnostics_pub, [status])

    # -- services -------------------------------------------------------------------------
    def _answer(self, response, success, message):
        response.success, response.message = success, message
        self.event(message if success else f'refused: {message}',
                   'info' if success else 'warning')
        return response

    def _captures(self):
        return self.backend.progress(self.state.active).captures

    def _on_start(self, request, response):
        try:
            self.state.check_start(self._captures())
            message = self.backend.begin()
        except AccelcalError as exc:
            return self._answer(response, False, str(exc))
        self.state.active = True
        return self._answer(response, True, message)

    def _on_capture(self, request, response):
        try:
            self.state.check_active('capture')
            message = self.backend.capture()
        except AccelcalError as exc:
            return self._answer(response, False, str(exc))
        return self._answer(response, True, message)

    def _on_cancel(self, request, response):
        try:
            self.state.check_active('cancel')
            count = self.backend.discard()
        except AccelcalError as exc:
            return self._answer(response, False, str(exc))
        self.state.active = False
        return self._answer(response, True, f'calibration cancelled; {count} captures '
                            'discarded')

    def _on_finish(self, request, response):
        try:
            self.state.check_finish(self._captures(), self.how_to_capture)
        except AccelcalError as exc:
            return self._answer(response, False, str(exc))
        try:
            message = self.backend.solve()
        except (AccelcalError, OSError) as exc:
            return self._answer(response, False, self.state.solve_failed(str(exc)))
        self.state.active = False
        return self._answer(response, True, message)
