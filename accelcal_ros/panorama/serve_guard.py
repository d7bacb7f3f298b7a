"""
Who may talk to ``accelcal serve`` and the stitcher's page, and what the answers carry.

The guard of every request (:func:`request_problem`: 403 for another site's page, for a
DNS-rebinding ``Host``), the headers of every answer (:data:`SECURITY_HEADERS`), the
token, the listening address's errors, and a quiet log: a malformed request, a client
gone mid-handshake or the process out of file handles is one line, never aiohttp's or
asyncio's traceback per connection (:func:`quiet_bad_requests`, :class:`QuietLoopErrors`).
"""
import ipaddress
import os
import secrets
import socket
import sys
import time
from typing import Any, Dict, Optional
from urllib.parse import quote, urlsplit

from accelcal_ros.errors import InputError

SECURITY_HEADERS = {
    'X-Content-Type-Options': 'nosniff',
    'X-Frame-Options': 'DENY',
    'Referrer-Policy': 'no-referrer',
    'Cache-Control': 'no-store',
    'Content-Security-Policy': ("default-src 'none'; script-src 'unsafe-inline'; "
                                "style-src 'unsafe-inline'; img-src 'self' blob: data:; "
                                "connect-src 'self' ws: wss:; frame-ancestors 'none'; "
                                "base-uri 'none'; form-action 'none'"),
    'Server': 'accelcal',
}
"""Headers of every answer: no sniffing, no framing by another site (frame-ancestors,
X-Frame-Options), no referrer (the token travels in the URL), nothing cached, the page's
own script and sockets only; ``Server`` names no versions (aiohttp's said them)."""
LOOP_ERROR_EVERY_S = 10.0
"""A repeated event-loop error (``accept`` out of file handles) is printed at most this
often, as one line with the count since."""


def is_loopback(host: str) -> bool:
    """Return True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _hostname(netloc: str) -> str:
    """Return the host of ``host[:port]`` (brackets of an IPv6 address dropped)."""
    try:
        return (urlsplit(f'//{netloc}').hostname or '').lower()
    except ValueError:
        return ''


def request_problem(headers: Any, host: str, token_required: bool) -> Optional[str]:
    """
    Return why a request must be refused (403) before its token is looked at, or None.

    ``headers``: the request's headers; ``host``: its ``Host``. The site the browser
    shows is ``X-Forwarded-Host`` when a proxy set it (a browser cannot set that header
    on a WebSocket, nor on a cross-site request without a CORS preflight, which this
    server never grants), else ``Host``. ``Origin``, which a browser sends on every
    WebSocket and cross-site request, must name that site: another page's script gets
    nothing (cross-site WebSocket hijacking). Without a token (``token_required`` False,
    a loopback server) ``Host`` must also be a loopback name unless a proxy forwarded the
    request: a DNS-rebinding page reaches 127.0.0.1 under its own host name.
    """
    forwarded = headers.get('X-Forwarded-Host', '').split(',')[0].strip()
    site = (forwarded or host).lower()
    if not token_required and not forwarded and not is_loopback(_hostname(host)):
        return (f'403: Host {host!r} is not a loopback name; this server answers only '
                'http://127.0.0.1 or http://localhost (a guard against DNS rebinding)\n')
    origin = headers.get('Origin')
    if origin is not None:
        try:
            netloc = urlsplit(origin).netloc.lower()
        except ValueError:
            netloc = ''
        if netloc != site:
            return (f'403: a request from the page {origin!r} is refused; only this '
                    f"server's own page ({site}) may talk to it\n")
    return None


def _not_a_client_fault(record: Any) -> bool:
    """
    Drop aiohttp's traceback of a client's fault: a logging filter.

    A malformed request (answered 400), or a client gone while answered (a tab reloaded
    mid-handshake: ``ClientConnectionResetError``, 31 lines of traceback per reload).
    """
    from aiohttp.http_exceptions import HttpProcessingError

    error = record.exc_info[1] if record.exc_info else None
    return not isinstance(error, (HttpProcessingError, ConnectionError))


def quiet_bad_requests() -> None:
    """
    Keep aiohttp from printing a traceback for each malformed request (once per process).

    A 20 kB header line, a 10 kB URL or ``Content-Length: -5`` is answered 400 by aiohttp,
    which also logs the parser's exception with its traceback on ``aiohttp.server``, as it
    does for a client that resets its connection while answered; that is the client's
    doing, not the server's, and it says nothing the 400 or the reset does not.
    """
    import logging

    server_log = logging.getLogger('aiohttp.server')
    if _not_a_client_fault not in server_log.filters:
        server_log.addFilter(_not_a_client_fault)


def page_url(host: str, port: int, token: Optional[str] = None) -> str:
    """Return the page's URL on ``host:port`` (an IPv6 address bracketed, the token quoted)."""
    where = f'[{host}]' if ':' in host else host
    return f'http://{where}:{port}/' + (f'?token={quote(token, safe="")}' if token else '')


def listen_error(host: str, port: int, exc: OSError) -> InputError:
    """Return the one-line error of a failed bind, naming ``host:port`` and the reason."""
    if isinstance(exc, socket.gaierror) or not isinstance(exc.errno, int) or exc.errno <= 0:
        reason = exc.strerror or str(exc)
    else:
        reason = os.strerror(exc.errno)
    return InputError(f'cannot listen on {host}:{port}: {reason}')


def make_token() -> str:
    """Return a fresh random token (URL-safe, 128 bits)."""
    return secrets.token_urlsafe(16)


def set_security_headers(headers: Any) -> None:
    """Put :data:`SECURITY_HEADERS` on an answer's ``headers`` (aiohttp's on_response_prepare)."""
    for key, value in SECURITY_HEADERS.items():
        headers[key] = value


class QuietLoopErrors:
    """
    An asyncio exception handler: out of file handles, once per :data:`LOOP_ERROR_EVERY_S`.

    At the file-handle limit asyncio logged ``socket.accept() out of system resource``
    with its traceback for every attempt: 9069 tracebacks (54 415 lines) in 7 s under 1100
    idle connections. Now one line, with the count, and the server goes on.
    """

    def __init__(self) -> None:
        self._last: Dict[str, float] = {}
        self._count: Dict[str, int] = {}

    def __call__(self, loop: Any, context: Dict[str, Any]) -> None:
        """Print an out-of-file-handles error at most so often; others as asyncio does."""
        import errno

        error = context.get('exception')
        if not (isinstance(error, OSError) and error.errno in (errno.EMFILE, errno.ENFILE)):
            loop.default_exception_handler(context)
            return
        key = str(context.get('message', ''))
        self._count[key] = self._count.get(key, 0) + 1
        now = time.monotonic()
        if now - self._last.get(key, -LOOP_ERROR_EVERY_S) < LOOP_ERROR_EVERY_S:
            return
        self._last[key] = now
        count, self._count[key] = self._count[key], 0
        detail = f': {type(error).__name__}: {error}' if error is not None else ''
        print(f'view server: {key}{detail} ({count} time{"s" if count > 1 else ""})',
              file=sys.stderr)


def raise_file_limit() -> None:
    """Raise the soft limit of open files to the hard one (each tab holds a socket)."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
        if hard == resource.RLIM_INFINITY or hard > soft:
            resource.setrlimit(resource.RLIMIT_NOFILE, (hard if hard != resource.RLIM_INFINITY
                                                        else max(soft, 65536), hard))
    except (ImportError, ValueError, OSError):
        pass
