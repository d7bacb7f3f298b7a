"""
``accelcal serve``: levelled views of a recorded rig in a browser, one operator per tab.

An aiohttp server (no hand-written HTTP) serves one page; each browser tab opens a
WebSocket and is given a view of its own in a :class:`~.view_set.ViewSet` (all views
share one mosaic of the current frame set). The page sends the pose as JSON
(``{"az": deg, "el": deg, "fov": deg}``: drag to pan, wheel to zoom, ``r``/Home to
reset, arrow keys to step); the server renders the view (:class:`~.view.LevelledView`),
encodes it as JPEG (:func:`~accelcal_ros.jpeg.encode_jpeg`: libjpeg-turbo) and sends it as
one binary message, preceded by a JSON text message with the view's state (pose, horizon
row, null when not in view; covered fraction, frame number). The page acknowledges each
frame once drawn; the server sends the next one only then, so at most one frame is in
flight and a drag is answered by the newest pose, not by a queue of old ones; a tab is
drawn at most at the frame rate (playback, or live the frame sets' rate; at least 25 Hz,
for the drag latency), however fast its pose changes (why
a WebSocket and not MJPEG:
MJPEG over HTTP has no back channel, so the pose would need a second connection, and the
browser's MJPEG decoder gives no acknowledgement to pace frames by; see docs/roi.md
for the measured drag-to-image latency).

Closing the tab (or losing the connection, even mid-frame) removes its view; more tabs
than ``max_views`` get a clear refusal (close code 1013 and the reason on the page) while
the others keep working.

Who may look: the server binds to 127.0.0.1 unless ``--host`` says otherwise; on any
other address a token is required (``--token``, else one is generated and printed), and
every request -- the page, the WebSocket -- must carry it (``?token=...`` or
``Authorization: Bearer ...``), 401 otherwise. Other web pages the user visits get
nothing either (:func:`request_problem`, 403): a request whose ``Origin`` is not this
server's own (cross-site WebSocket hijacking) is refused, and without a token a request
whose ``Host`` is not a loopback name (DNS rebinding) is too. TLS: put the server behind a
reverse proxy (nginx, Caddy) that terminates HTTPS, forwards WebSocket upgrades and sets
``X-Forwarded-Host`` (Caddy does; nginx: ``proxy_set_header X-Forwarded-Host $host``).
"""
import asyncio
import hmac
import json
import math
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.jpeg import encode_jpeg
from accelcal_ros.panorama.serve_guard import (_hostname, is_loopback, listen_error,
                                               make_token, page_url, quiet_bad_requests,
                                               QuietLoopErrors, raise_file_limit,
                                               request_problem, set_security_headers)
from accelcal_ros.panorama.view_pose import ViewPose
from accelcal_ros.panorama.view_set import NoSuchView, ViewSet
import numpy as np

DEFAULT_POSE_DEG = (0.0, 0.0, 60.0)
"""Pose of a new tab and of the reset key: azimuth, elevation, fov_h (degrees)."""
RENDER_THREADS = 4
"""Threads that render and JPEG-encode the tabs' views (and copy in frame sets)."""
MIN_DRAW_RATE_HZ = 25.0
"""A dragged tab may be drawn this often even when frames come slower (drag latency)."""
LIVE_RATE_BOUNDS = (5.0, 60.0)
"""Live, a tab is drawn at most at the frame sets' rate, kept within these (Hz)."""
MAX_CONTROL_BYTES = 4096
"""Longest control message (a JSON object of a few numbers is under 100 bytes)."""
MAX_CONTROL_RATE = (2000, 1.0)
"""At most this many control messages per this many seconds from one tab (a drag sends
one per mouse move, up to a 480 Hz display's rate, the acks one per frame): a tab flooding
its socket (176 000 acks/s cut another tab from 24 to 3 frames/s) is closed with code 1008
and the reason."""
SEND_TIMEOUT_S = 10.0
"""A frame the tab has not taken in this long (it acks without reading, its socket's
buffers full: 4 MB) drops its connection (no close frame would get through either): its
view slot is freed; it held it for good."""
SHUTDOWN_S = 1.0
"""How long a stopping server waits for its tabs' handlers after closing them (1001)."""
__all__ = ['is_loopback', 'make_token', 'next_draw_due', 'page_url', 'serve_forever',
           'ViewServer']
FrameSet = Tuple[List[np.ndarray], float, float, float]
"""``(images in rig order, roll, pitch, stamp_s)`` (radians, seconds)."""


def next_draw_due(due_s: float, start_s: float, period_s: float) -> float:
    """
    Return when a tab's next drawing may start: paced on the clock, one per ``period_s``.

    ``due_s``: when the drawing that started at ``start_s`` was due (monotonic seconds).
    The due times advance a period per drawing, so one drawing that starts late (the
    render pool busy, a frame set late) does not push every later one back. Spacing each
    drawing a period after the previous one's start did: the lags added up, and every
    period of lag lost a frame set (4 tabs of 25 fps got 20-22 frames/s each while the
    server used 0.9 of 2 cores, ``benchmarks/bench_serve.py --stitcher``). A drawing
    more than half a period late starts the clock again half a period after it, so the
    rate stays at most one per period and two drawings are at least half a period apart.
    """
    return max(due_s + period_s, start_s + 0.5 * period_s)


class ViewServer:
    """
    The web server over a :class:`~.view_set.ViewSet` and recorded frame sets.

    ``frames`` are played in a loop at ``fps`` (one frame set: a still scene, rendered
    again only when a view moves); with ``live=True`` there may be none, and frame sets
    arrive through :meth:`push_frame` (the ``stitcher``'s, from any thread). ``token``
    (None: none required) must be carried by every request.
    """

    def __init__(self, views: ViewSet, frames: Sequence[FrameSet], fps: float = 10.0,
                 token: Optional[str] = None, jpeg_quality: int = 80,
                 live: bool = False) -> None:
        if not frames and not live:
            raise InputError('no frame set to serve')
        if not (math.isfinite(fps) and fps > 0):
            raise InputError(f'fps must be positive, got {fps!r}')
        self.views = views
        self.frames = list(frames)
        self.fps = float(fps)
        self.token = token
        self.jpeg_quality = int(jpeg_quality)
        self.frame_number = 0
        self.refused = 0
        self.served_frames = 0
        self.skipped_frames = 0
        """Frame sets of the recording skipped by the playback (it was too late for them)."""
        self._next_id = 0
        self._sockets: Dict[Any, Any] = {}
        """Open tabs: WebSocketResponse -> its transport (aborted if it will not close)."""
        self._changed: Optional[asyncio.Condition] = None
        self._playback: Optional['asyncio.Task[None]'] = None
        self._runner: Any = None
        self._thread: Optional[threading.Thread] = None
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self.url = ''
        """The page's URL once listening (without the token)."""
        self.port = 0
        """The port listened on (``port`` 0 picks one)."""
        self.live = live
        self._live_period: Optional[float] = None
        self._last_push: Optional[float] = None
        self._have_frame = bool(self.frames)
        if self.frames:
            images, roll, pitch, stamp = self.frames[0]
            views.set_frame(images, roll, pitch, stamp)

    def frame_rate(self) -> float:
        """
        Return the frame rate (Hz) tabs are paced by.

        The playback rate, or live the rate frame sets arrive at (within
        :data:`LIVE_RATE_BOUNDS`; the upper bound until known).
        """
        if not self.live:
            return self.fps
        low, high = LIVE_RATE_BOUNDS
        period = self._live_period
        return high if period is None else min(high, max(low, 1.0 / max(period, 1e-6)))

    def push_frame(self, images: Sequence[Any], roll: float, pitch: float,
                   stamp_s: float) -> None:
        """Show a new frame set in every tab (live mode; thread-safe, returns at once)."""
        now = time.monotonic()
        if self._last_push is not None:
            step = now - self._last_push
            self._live_period = step if self._live_period is None else \
                0.8 * self._live_period + 0.2 * step
        self._last_push = now
        self.views.set_frame(images, roll, pitch, stamp_s)
        loop = self._loop
        if loop is not None and self._changed is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._new_frame)

    def _new_frame(self) -> None:
        self._have_frame = True
        self.frame_number += 1
        loop = asyncio.get_running_loop()
        loop.create_task(self._notify())

    async def _notify(self) -> None:
        assert self._changed is not None
        async with self._changed:
            self._changed.notify_all()

    # -- the web application ------------------------------------------------------------
    def app(self) -> Any:
        """Return the aiohttp application (page, WebSocket, status)."""
        from aiohttp import web

        app = web.Application(middlewares=[self._auth])
        app.router.add_get('/', self._page)
        app.router.add_get('/ws', self._socket)
        app.router.add_get('/status', self._status)
        app.on_startup.append(self._start_playback)
        app.on_response_prepare.append(self._headers)
        app.on_shutdown.append(self._close_tabs)
        app.on_cleanup.append(self._stop_playback)
        return app

    async def _headers(self, request: Any, response: Any) -> None:
        set_security_headers(response.headers)

    async def _close_tabs(self, app: Any) -> None:
        """Close every tab with 1001 (going away): they were cut (1006) 14 s after Ctrl-C."""
        from aiohttp import WSCloseCode

        tabs = dict(self._sockets)
        closing = {asyncio.ensure_future(ws.close(code=WSCloseCode.GOING_AWAY,
                                                  message=b'server shutting down')): ws
                   for ws in tabs}
        if closing:
            done, pending = await asyncio.wait(closing, timeout=SHUTDOWN_S)
            for task in pending:   # a tab that does not read cannot take the close frame
                task.cancel()
                transport = tabs[closing[task]]
                if transport is not None:
                    transport.abort()
            for task in done:
                task.exception() if not task.cancelled() else None

    def _authorised(self, request: Any) -> bool:
        if self.token is None:
            return True
        given = request.query.get('token', '')
        header = request.headers.get('Authorization', '')
        if header.startswith('Bearer '):
            given = header[7:]
        return hmac.compare_digest(given.encode(), self.token.encode())

    @property
    def _auth(self) -> Any:
        from aiohttp import web

        @web.middleware
        async def auth(request: Any, handler: Any) -> Any:
            problem = request_problem(request.headers, request.host, self.token is not None)
            if problem:
                return web.Response(status=403, text=problem)
            if not self._authorised(request):
                return web.Response(status=401, text='401: this server needs its token '
                                    '(?token=... or Authorization: Bearer ...)\n')
            return await handler(request)
        return auth

    async def _page(self, request: Any) -> Any:
        from aiohttp import web

        from accelcal_ros.panorama.serve_page import PAGE

        return web.Response(text=PAGE, content_type='text/html',
                            headers={'Cache-Control': 'no-store'})

    async def _status(self, request: Any) -> Any:
        from aiohttp import web

        if self.token is None and ('X-Forwarded-Host' in request.headers
                                   or not is_loopback(_hostname(request.host))):
            # a DNS-rebinding page may send X-Forwarded-Host itself on a same-origin GET
            return web.Response(status=403, text='403: without a token the status is '
                                'answered on a loopback address only\n')
        return web.json_response({'views': self.views.names(), 'refused': self.refused,
                                  'max_views': self.views.max_views,
                                  'frame': self.frame_number, 'served': self.served_frames,
                                  'skipped': self.skipped_frames,
                                  'threads': threading.active_count()})

    async def _start_playback(self, app: Any) -> None:
        self._changed = asyncio.Condition()
        self._loop = asyncio.get_running_loop()
        # a bounded pool renders and encodes (OpenCV releases the GIL): threads stay flat
        from concurrent.futures import ThreadPoolExecutor

        self._loop.set_default_executor(ThreadPoolExecutor(
            max_workers=RENDER_THREADS, thread_name_prefix='view_render'))
        if len(self.frames) > 1:
            self._playback = asyncio.get_running_loop().create_task(self._play())

    async def _stop_playback(self, app: Any) -> None:
        if self._playback is not None:
            self._playback.cancel()
            try:
                await self._playback
            except asyncio.CancelledError:
                pass
            self._playback = None

    async def _play(self) -> None:
        """
        Play the frame sets at :attr:`fps` on the clock.

        A late frame set is shown at once; one later than a whole period is skipped
        (:attr:`skipped_frames`), as a live source drops them.

        Frame sets are copied in by a thread of their own. The playback used to sleep a
        period after each copy, queued behind the tabs' drawings in the render pool: at
        25 fps with 4 tabs and the stitcher beside it played 15-17 frame sets a second,
        23-24 now (``benchmarks/bench_serve.py --stitcher``, OpenCV 4.6, 2 cores).
        """
        from concurrent.futures import ThreadPoolExecutor

        loop = asyncio.get_running_loop()
        period = 1.0 / self.fps
        k = 0
        due = loop.time()
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix='view_frames') as copier:
            while True:
                due += period
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                elif wait < -period:  # more than a period late: drop, as a live source
                    missed = int(-wait // period)
                    self.skipped_frames += missed
                    k += missed
                    due += missed * period
                k = (k + 1) % len(self.frames)
                images, roll, pitch, stamp = self.frames[k]
                await loop.run_in_executor(copier, self.views.set_frame, images, roll, pitch,
                                           stamp)
                self.frame_number += 1
                assert self._changed is not None
                async with self._changed:
                    self._changed.notify_all()

    # -- one tab --------------------------------------------------------------------------
    async def _socket(self, request: Any) -> Any:
        from aiohttp import web, WSMsgType

        # no permessage-deflate (Chromium offers it; aiohttp accepts by default): a JPEG
        # frame deflates by 18 % (the scene) to 0.1 % (noise) for 1.4 to 22 ms of CPU
        # each, and a compressed send cut short by a closing tab left aiohttp's
        # "Task exception was never retrieved" traceback on the server's stderr
        # messages up to 16x the control limit are read and answered with the reason
        # (aiohttp closed a 4.2 kB one with 1009 and no reason, the view gone)
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=16 * MAX_CONTROL_BYTES,
                                   compress=False)
        await ws.prepare(request)   # a tab gone mid-handshake: quiet_bad_requests
        self._next_id += 1
        name = f'tab{self._next_id}'
        try:
            self.views.add(name, ViewPose.from_degrees(*DEFAULT_POSE_DEG))
        except InputError as exc:
            self.refused += 1
            try:
                await ws.send_str(json.dumps({'refused': str(exc)}))
                await ws.close(code=1013, message=b'too many views')
            except ConnectionError:
                pass
            return ws
        self._sockets[ws] = request.transport
        state: Dict[str, Any] = {'dirty': True, 'acked': True, 'sent': 0, 'due': 0.0}
        sender = asyncio.get_running_loop().create_task(self._send_frames(ws, name, state))
        window_start, count = time.monotonic(), 0
        try:
            async for msg in ws:
                now = time.monotonic()
                if now - window_start > MAX_CONTROL_RATE[1]:
                    window_start, count = now, 0
                count += 1
                if count > MAX_CONTROL_RATE[0]:
                    await ws.close(code=1008, message=(
                        f'more than {MAX_CONTROL_RATE[0]} messages in '
                        f'{MAX_CONTROL_RATE[1]:g} s').encode())
                    break
                if msg.type == WSMsgType.BINARY:
                    await ws.send_str(json.dumps({'error': 'binary messages are not '
                                                  'accepted: control messages are JSON text'}))
                elif msg.type == WSMsgType.TEXT:
                    await self._on_control(ws, name, state, msg.data)
        except ConnectionError:   # the tab went while we answered it
            pass
        finally:
            self._sockets.pop(ws, None)
            sender.cancel()
            try:
                await sender
            except (asyncio.CancelledError, ConnectionError):
                pass
            try:
                self.views.remove(name)
            except NoSuchView:
                pass
        return ws

    async def _on_control(self, ws: Any, name: str, state: Dict[str, Any], text: str) -> None:
        if len(text) > MAX_CONTROL_BYTES:
            await ws.send_str(json.dumps({'error': f'a control message is at most '
                                          f'{MAX_CONTROL_BYTES} bytes, got {len(text)}'}))
            return
        try:
            data = json.loads(text)
            if not isinstance(data, dict):
                raise ValueError('not an object')
        except (ValueError, RecursionError):  # RecursionError: '[' * 2000 nested too deeply
            await ws.send_str(json.dumps({'error': 'control messages are JSON objects'}))
            return
        if 'ack' in data:
            state['acked'] = True
        if {'az', 'el', 'fov'} & set(data):
            try:
                az, el, fov = self.views.pose(name).degrees()
            except NoSuchView:  # the view was removed meanwhile
                return
            try:
                pose = ViewPose.from_degrees(data.get('az', az), data.get('el', el),
                                             data.get('fov', fov))
                self.views.set_pose(name, pose)
            except InputError as exc:  # the view keeps its last good pose
                await ws.send_str(json.dumps({'error': str(exc)}))
                return
            state['dirty'] = True
        assert self._changed is not None
        async with self._changed:
            self._changed.notify_all()

    async def _send_frames(self, ws: Any, name: str, state: Dict[str, Any]) -> None:
        loop = asyncio.get_running_loop()
        assert self._changed is not None
        seen_frame = -1
        while not ws.closed:
            async with self._changed:
                await self._changed.wait_for(
                    lambda: ws.closed or (state['acked'] and self._have_frame and (
                        state['dirty'] or self.frame_number != seen_frame)))
            if ws.closed:
                return
            # a tab dragged all the time is drawn at the frame rate, not faster: the
            # newest pose when it is due (the first move after a rest goes at once)
            period = 1.0 / max(self.frame_rate(), MIN_DRAW_RATE_HZ)
            wait = state['due'] - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
                if ws.closed:
                    return
            state['due'] = next_draw_due(state['due'], time.monotonic(), period)
            state['dirty'] = False
            seen_frame = self.frame_number

            def render() -> Tuple[bytes, Dict[str, Any]]:
                with self.views.drawing(name) as (view, image):
                    az, el, fov = view.pose.degrees()
                    info = {'az': az, 'el': el, 'fov': fov, 'width': view.width,
                            'height': view.height, 'horizon_row': view.horizon_row(),
                            'covered': view.covered_fraction(), 'frame': seen_frame,
                            'name': name}
                # the view's buffer is only drawn again by this tab, after this frame:
                # encode outside the drawing, so that a new frame set need not wait
                jpeg = encode_jpeg(image, self.jpeg_quality)
                return jpeg, info

            try:
                data, info = await loop.run_in_executor(None, render)
            except NoSuchView:  # the view was removed meanwhile
                return
            state['acked'] = False
            state['sent'] += 1
            info['sent'] = state['sent']
            info['server_time'] = time.time()
            try:
                await asyncio.wait_for(self._send(ws, json.dumps(info), data), SEND_TIMEOUT_S)
            except asyncio.TimeoutError:   # acks without reading: its slot is freed
                transport = self._sockets.get(ws)   # no close frame gets through either
                if transport is not None:
                    transport.abort()
                return
            self.served_frames += 1

    @staticmethod
    async def _send(ws: Any, info: str, data: bytes) -> None:
        await ws.send_str(info)
        await ws.send_bytes(data)

    # -- running --------------------------------------------------------------------------
    async def _listen(self, host: str, port: int, handle_signals: bool = False) -> None:
        """
        Set the application up and listen on ``host:port``; set :attr:`url` (the bound port).

        A failed bind (no such host, the port in use) raises :class:`InputError` naming
        ``host:port``; the caller cleans :attr:`_runner` up. ``handle_signals``: SIGINT and
        SIGTERM stop the loop (the main thread only).
        """
        from aiohttp import web

        quiet_bad_requests()
        asyncio.get_running_loop().set_exception_handler(QuietLoopErrors())
        self._runner = web.AppRunner(self.app(), handle_signals=handle_signals,
                                     shutdown_timeout=SHUTDOWN_S)
        await self._runner.setup()
        site = web.TCPSite(self._runner, host, port)
        try:
            await site.start()
        except OSError as exc:
            raise listen_error(host, port, exc) from None
        sockets = site._server.sockets  # type: ignore[union-attr]
        self.port = int(sockets[0].getsockname()[1])
        self.url = page_url(host, self.port)

    def start(self, host: str = '127.0.0.1', port: int = 0) -> str:
        """Serve in a background thread (tests, benchmarks); return the page's URL."""
        ready = threading.Event()
        errors: List[BaseException] = []

        def main() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            asyncio.set_event_loop(loop)
            try:
                loop.run_until_complete(self._listen(host, port))
            except BaseException as exc:  # noqa: B902 - handed to the starting thread
                errors.append(exc)
                ready.set()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(self._runner.cleanup())
            loop.close()

        self._thread = threading.Thread(target=main, name='view_server', daemon=True)
        self._thread.start()
        ready.wait(30.0)
        if errors:
            if isinstance(errors[0], InputError):
                raise errors[0]
            raise InputError(f'cannot serve on {host}:{port}: {errors[0]}')
        return self.url

    def stop(self) -> None:
        """Stop a server started by :meth:`start` (again: nothing to do)."""
        if self._loop is not None and self._thread is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=10.0)


def serve_forever(server: ViewServer, host: str, port: int,
                  announce: Callable[[str], Any] = print) -> None:
    """
    Run the server in this thread until interrupted (``accelcal serve``).

    ``announce`` is called with the page's link (:func:`page_url`: the bound port, for
    ``port`` 0 the one picked, and the token) once the server listens, not before; a
    failed bind raises :class:`InputError` naming ``host:port`` and announces nothing.
    Ctrl-C or SIGTERM stop it (cleaned up).
    """
    from aiohttp import web

    async def run() -> None:
        try:
            await server._listen(host, port, handle_signals=True)
            announce(page_url(host, server.port, server.token))
            while True:
                await asyncio.sleep(3600.0)
        finally:
            if server._runner is not None:
                await server._runner.cleanup()

    raise_file_limit()
    loop = asyncio.new_event_loop()
    asyncio.set_event_loop(loop)
    main = loop.create_task(run())
    try:
        loop.run_until_complete(main)
    except (web.GracefulExit, KeyboardInterrupt):
        pass
    finally:
        _close_loop(loop, main)


def _close_loop(loop: asyncio.AbstractEventLoop, main: 'asyncio.Task[None]') -> None:
    """Cancel ``main`` (cleaning the server up) and any task left, then close ``loop``."""
    for task in [main, *asyncio.all_tasks(loop)]:
        if not task.done():
            task.cancel()
            try:
                loop.run_until_complete(task)
            except (asyncio.CancelledError, Exception):  # noqa: B902 - shutting down
                pass
    loop.run_until_complete(loop.shutdown_asyncgens())
    loop.close()
    asyncio.set_event_loop(None)
