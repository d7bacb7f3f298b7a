"""The server of ``accelcal serve`` over HTTP and WebSockets: frames, caps, tokens, leaks."""
import asyncio
import json
import math
import threading
import time

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama import render
from accelcal_ros.panorama.roi_study import render_view_truth
from accelcal_ros.panorama.serve import is_loopback, next_draw_due, RENDER_THREADS, ViewServer
from accelcal_ros.panorama.view import ViewPose
from accelcal_ros.panorama.view_set import ViewSet
import numpy as np
import pytest

aiohttp = pytest.importorskip('aiohttp', reason='aiohttp is not installed '
                              '(tools/requirements-ros.txt)')
ROLL, PITCH = math.radians(2.0), math.radians(5.0)


@pytest.fixture(scope='module')
def scene():
    """Return the equirectangular test scene."""
    return render.make_scene(1800, 900, seed=4)


def _server(scene, token=None, max_views=3, frames=1):
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    sets = []
    for k in range(frames):
        roll = ROLL + 0.01 * k
        sets.append((render.render_camera_views(scene, rig, roll, PITCH), roll, PITCH, k * 0.1))
    views = ViewSet(rig, max_views=max_views, width=320, height=240)
    server = ViewServer(views, sets, fps=20.0, token=token)
    server.start('127.0.0.1', 0)
    return server


async def _frame(ws):
    """Return ``(info, image)`` of the next frame (acknowledged)."""
    import cv2

    info = None
    async for msg in ws:
        if msg.type == aiohttp.WSMsgType.TEXT:
            data = json.loads(msg.data)
            if 'refused' in data or 'error' in data:
                return data, None
            info = data
        elif msg.type == aiohttp.WSMsgType.BINARY:
            image = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)
            await ws.send_str(json.dumps({'ack': info['sent']}))
            return info, image
    return None, None


async def _strict_frame(ws):
    """Return the next frame's header (acknowledged) or error, as strict JSON (no NaN)."""
    def not_json(name):
        raise AssertionError(f'{name} in a header: not JSON')

    info = None
    async for msg in ws:
        if msg.type == aiohttp.WSMsgType.TEXT:
            info = json.loads(msg.data, parse_constant=not_json)
            if 'error' in info:
                return info
        elif msg.type == aiohttp.WSMsgType.BINARY:
            await ws.send_str(json.dumps({'ack': info['sent']}))
            return info
    return None


def _psnr(image, scene, pose):
    truth = render_view_truth(scene, 320, 240, pose)
    covered = image.max(axis=2) > 8
    return render.psnr(image, truth, covered)


def test_each_socket_is_its_own_view_and_steers_it(scene):
    """Two sockets, two poses, two images matching the scene; a bad pose keeps the last."""
    server = _server(scene)

    async def run():
        async with aiohttp.ClientSession() as session:
            page = await session.get(server.url)
            assert page.status == 200 and 'WebSocket' in await page.text()
            a = await session.ws_connect(server.url + 'ws')
            b = await session.ws_connect(server.url + 'ws')
            info_a, _ = await _frame(a)
            await _frame(b)
            assert info_a['fov'] == pytest.approx(60.0)
            assert info_a['horizon_row'] == pytest.approx(119.5)
            await a.send_str(json.dumps({'az': -30, 'el': 2, 'fov': 40}))
            await b.send_str(json.dumps({'az': 35, 'el': -3, 'fov': 50}))
            while True:
                info_a, image_a = await _frame(a)
                if info_a['az'] == pytest.approx(-30):
                    break
            while True:
                info_b, image_b = await _frame(b)
                if info_b['az'] == pytest.approx(35):
                    break
            assert _psnr(image_a, scene, ViewPose.from_degrees(-30, 2, 40)) > 28
            assert _psnr(image_b, scene, ViewPose.from_degrees(35, -3, 50)) > 28
            assert np.abs(image_a.astype(int) - image_b).mean() > 10
            await a.send_str(json.dumps({'az': 0, 'el': 0, 'fov': 180}))
            error, _ = await _frame(a)
            assert 'fov_h' in error['error']
            await a.send_str('not json')
            error, _ = await _frame(a)
            assert 'JSON' in error['error']
            assert server.views.views[server.views.names()[0]].pose.degrees()[0] == \
                pytest.approx(-30)
            status = await (await session.get(server.url + 'status')).json()
            assert len(status['views']) == 2
            await a.close()
            await b.close()
            for _ in range(100):
                if not server.views.names():
                    break
                await asyncio.sleep(0.05)
            assert server.views.names() == []

    try:
        asyncio.run(run())
    finally:
        server.stop()


def test_bad_control_messages_get_one_clear_reply_and_the_tab_keeps_its_view(scene, caplog):
    """
    Nesting too deep, a boolean or an integer past a float as an angle: an error, the tab kept.

    ``'[' * 2000 + ']' * 2000`` (under the 4 KiB cap) raised RecursionError in json.loads:
    a traceback on the server and the tab dropped; ``{"az": true}`` turned the view to 1 deg.
    """
    import logging

    server = _server(scene)

    async def run():
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(server.url + 'ws')
            await _frame(ws)
            await ws.send_str(json.dumps({'az': 10}))
            while (await _strict_frame(ws))['az'] != pytest.approx(10):
                pass
            name = server.views.names()[0]
            for text, reason in [
                    ('[' * 2000 + ']' * 2000, 'control messages are JSON objects'),
                    ('{"ack": 0, "x": ' + '[' * 1900 + ']' * 1900 + '}',
                     'control messages are JSON objects'),
                    ('{"az": true}', 'view azimuth must be a number'),
                    ('{"el": false, "fov": 30}', 'view elevation must be a number'),
                    ('{"fov": 1' + '0' * 400 + '}', 'view fov_h must be finite')]:
                await ws.send_str(text)
                error = await _strict_frame(ws)
                assert error is not None and reason in error.get('error', ''), (text[:20], error)
                assert server.views.pose(name).degrees() == pytest.approx((10.0, 0.0, 60.0))
            await ws.send_str(json.dumps({'az': -15}))   # the same tab still answers
            while (await _strict_frame(ws))['az'] != pytest.approx(-15):
                pass
            assert server.views.names() == [name]
            await ws.close()

    with caplog.at_level(logging.ERROR):
        try:
            asyncio.run(run())
        finally:
            server.stop()
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text


def test_headers_are_json_a_thin_view_covered_and_no_horizon_out_of_view(scene):
    """
    A 4096 x 16 view: a finite covered fraction; looking straight up: ``horizon_row`` null.

    The header said ``"covered": NaN`` (not JSON: the short side had no sample) and, at
    elevation 90 deg, ``"horizon_row": 1.357e+19``.
    """
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    sets = [(render.render_camera_views(scene, rig, ROLL, PITCH), ROLL, PITCH, 0.0)]
    server = ViewServer(ViewSet(rig, max_views=2, width=4096, height=16), sets, fps=20.0)
    server.start('127.0.0.1', 0)

    async def run():
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(server.url + 'ws')
            info = await _strict_frame(ws)
            assert 0.5 < info['covered'] <= 1.0 and info['horizon_row'] == 7.5
            await ws.send_str(json.dumps({'el': 90}))
            while info['el'] != pytest.approx(90):
                info = await _strict_frame(ws)
            assert info['horizon_row'] is None and info['covered'] == 0.0
            await ws.close()

    try:
        asyncio.run(run())
    finally:
        server.stop()


def test_more_tabs_than_the_cap_are_refused_and_the_others_keep_working(scene):
    """Ten sockets on a 3-view server: 3 get frames, 7 a clear refusal (1013)."""
    server = _server(scene, max_views=3, frames=3)

    async def run():
        async with aiohttp.ClientSession() as session:
            sockets = [await session.ws_connect(server.url + 'ws') for _ in range(10)]
            results = [await _frame(ws) for ws in sockets]
            served = [r for r in results if r[1] is not None]
            refused = [r for r in results if r[1] is None]
            assert len(served) == 3 and len(refused) == 7
            assert all('at most 3' in r[0]['refused'] for r in refused)
            for ws, (_, image) in zip(sockets, results):
                if image is None:
                    await ws.receive()
                    assert ws.closed and ws.close_code == 1013
            live = [ws for ws, r in zip(sockets, results) if r[1] is not None]
            for ws in live:  # playing at 20 fps: new frames keep coming
                first, _ = await _frame(ws)
                second, _ = await _frame(ws)
                assert second['frame'] != first['frame']
            for ws in sockets:
                await ws.close()

    try:
        asyncio.run(run())
        assert server.refused == 7
    finally:
        server.stop()


def _rss_kb():
    with open('/proc/self/status') as handle:
        for line in handle:
            if line.startswith('VmRSS:'):
                return int(line.split()[1])
    return 0


def test_disconnects_mid_frame_leak_nothing_over_200_cycles(scene):
    """Connect, get half a frame, drop: views, threads and memory flat over 200 cycles."""
    server = _server(scene, max_views=4, frames=2)

    async def cycle(session, k):
        ws = await session.ws_connect(server.url + 'ws')
        if k % 2:
            await ws.receive()  # the JSON header only: drop before the JPEG is read
        else:
            await ws.send_str(json.dumps({'az': k % 40, 'fov': 30}))
        await ws.close() if k % 3 else ws._response.connection.transport.abort()

    async def run():
        async with aiohttp.ClientSession() as session:
            marks = []
            for k in range(300):  # 100 to warm up (pools, allocator), then 200 measured
                if k in (100, 200, 299):
                    await asyncio.sleep(0.3)
                    names = [t.name for t in threading.enumerate()]
                    pool = sum(n.startswith('view_render') for n in names)
                    marks.append((len(names) - pool, pool, _rss_kb()))
                await cycle(session, k)
            for _ in range(100):
                if not server.views.names():
                    break
                await asyncio.sleep(0.05)
            return marks

    try:
        marks = asyncio.run(run())
        assert server.views.names() == []
        (t100, _, r100), (t200, _, r200), (t300, _, r300) = marks
        # no thread per connection: the others stay, the render pool stays within its bound
        assert t300 <= t100 and t200 <= t100, marks
        assert all(pool <= RENDER_THREADS for _, pool, _ in marks), marks
        grown_kb = r300 - r100
        assert grown_kb < 20_000, marks  # a view and its lookup: ~1.5 MB; 200 leaked: 300 MB
    finally:
        server.stop()


class _SlowCopy(ViewSet):
    """A view set whose frame sets take 2.4 playback periods (at 20 fps) to copy in."""

    def set_frame(self, *args, **kwargs):
        time.sleep(0.12)
        super().set_frame(*args, **kwargs)


def test_playback_keeps_the_clock_and_skips_what_it_cannot_show(scene):
    """
    Frame sets shown or skipped keep pace with the clock at the playback rate.

    Frame sets slower to copy in than the period: the playback skips frame sets, as a
    live source drops them, instead of playing the recording slower (it slept a period
    after each one: 5.9 frame sets/s played of 20 here, none skipped).
    """
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    sets = [([np.full((240, 320, 3), 40 * k, np.uint8)] * 3, ROLL, PITCH, 0.1 * k)
            for k in range(3)]
    server = ViewServer(_SlowCopy(rig, max_views=2, width=64, height=48), sets, fps=20.0)
    server.start('127.0.0.1', 0)   # returns once serving: the playback began before
    start = time.monotonic()
    try:
        time.sleep(1.5)
        played = server.frame_number + server.skipped_frames
        elapsed = time.monotonic() - start
    finally:
        server.stop()
    assert server.skipped_frames > 0
    # only the frame set being copied in (0.12 s and whatever the machine adds) is not
    # counted yet
    assert played >= 20.0 * elapsed - 6, (played, elapsed, server.frame_number)


def test_no_deflate_of_jpeg_frames_and_no_traceback_when_a_tab_closes(scene, caplog):
    """
    A client offering permessage-deflate (as Chromium does) gets frames uncompressed.

    With deflate, tabs closing while a frame was sent left aiohttp's "Task exception
    was never retrieved" (a traceback) on the server's log.
    """
    import logging

    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    sets = [(render.render_camera_views(scene, rig, ROLL + 0.01 * k, PITCH), ROLL, PITCH, 0.1 * k)
            for k in range(2)]
    # frames of some 40 KB, which aiohttp deflates in a task of its own
    server = ViewServer(ViewSet(rig, max_views=4, width=1280, height=720), sets, fps=20.0)
    server.start('127.0.0.1', 0)

    async def run():
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(server.url + 'ws', compress=15)
            info, image = await _frame(ws)
            assert image is not None and ws.compress == 0   # the offer was declined
            await ws.close()
            for k in range(40):   # closed with a frame on its way
                ws = await session.ws_connect(server.url + 'ws', compress=15)
                await ws.receive()   # the JSON header: the JPEG follows
                await ws.close() if k % 2 else ws._response.connection.transport.abort()
            for _ in range(100):
                if not server.views.names():
                    break
                await asyncio.sleep(0.05)

    with caplog.at_level(logging.ERROR):
        try:
            asyncio.run(run())
        finally:
            server.stop()
    import gc

    gc.collect()
    assert server.views.names() == []
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text


def test_token_is_required_on_every_request(scene):
    """With a token: 401 without it or with a wrong one; the page and socket work with it."""
    server = _server(scene, token='s3cret')

    async def run():
        async with aiohttp.ClientSession() as session:
            for path in ('', 'ws', 'status'):
                assert (await session.get(server.url + path)).status == 401
            assert (await session.get(server.url + '?token=nope')).status == 401
            with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                await session.ws_connect(server.url + 'ws')
            assert info.value.status == 401
            assert (await session.get(server.url + '?token=s3cret')).status == 200
            header = {'Authorization': 'Bearer s3cret'}
            assert (await session.get(server.url + 'status', headers=header)).status == 200
            ws = await session.ws_connect(server.url + 'ws?token=s3cret')
            info, image = await _frame(ws)
            assert image is not None and image.shape == (240, 320, 3)
            await ws.close()

    try:
        asyncio.run(run())
    finally:
        server.stop()


def test_other_web_pages_get_nothing_cross_origin_and_dns_rebinding():
    """Another site's script (its Origin) and a rebound host name (its Host) get 403."""
    server = _server(scene=render.make_scene(360, 180, seed=1))
    own = f'127.0.0.1:{server.port}'

    async def run():
        async with aiohttp.ClientSession() as session:
            with pytest.raises(aiohttp.WSServerHandshakeError) as info:
                await session.ws_connect(server.url + 'ws', origin='http://evil.example')
            assert info.value.status == 403
            for headers in ({'Origin': 'http://evil.example'}, {'Host': 'evil.example'},
                            {'Host': f'evil.example:{server.port}',
                             'Origin': f'http://evil.example:{server.port}'}):
                reply = await session.get(server.url + 'status', headers=headers)
                assert reply.status == 403, headers
                assert 'refused' in await reply.text() or 'loopback' in await reply.text()
            # the page's own socket, and a page behind a proxy that says where it is
            ws = await session.ws_connect(server.url + 'ws', origin=f'http://{own}')
            info, image = await _frame(ws)
            assert image is not None
            await ws.close()
            behind = {'Origin': 'https://views.example', 'X-Forwarded-Host': 'views.example'}
            assert (await session.get(server.url, headers=behind)).status == 200
            ws = await session.ws_connect(server.url + 'ws', origin='https://views.example',
                                          headers={'X-Forwarded-Host': 'views.example'})
            assert (await _frame(ws))[1] is not None
            await ws.close()
            # a rebound page can send X-Forwarded-Host on a same-origin GET (no Origin):
            # /status leaked the tabs (200); without a token it answers loopback only
            for headers in (behind, {'Host': f'evil.example:{server.port}',
                                     'X-Forwarded-Host': f'evil.example:{server.port}'}):
                reply = await session.get(server.url + 'status', headers=headers)
                assert reply.status == 403 and 'loopback' in await reply.text(), headers
            for host in (f'localhost:{server.port}', f'[::1]:{server.port}'):
                reply = await session.get(server.url + 'status', headers={'Host': host})
                assert reply.status == 200, host

    try:
        asyncio.run(run())
    finally:
        server.stop()


def test_a_malformed_request_is_400_without_a_traceback(scene, caplog):
    """A 20 kB header line, a 10 kB URL, a negative length: 400 and nothing logged."""
    import logging
    import socket

    server = _server(scene)
    caplog.set_level(logging.DEBUG, logger='aiohttp')
    requests = [b'GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX: ' + b'a' * 20000 + b'\r\n\r\n',
                b'GET /' + b'a' * 10000 + b' HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n',
                b'POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: -5\r\n\r\n']
    try:
        for request in requests:
            with socket.create_connection(('127.0.0.1', server.port), timeout=10) as sock:
                sock.sendall(request)
                assert sock.recv(64).split()[1].startswith(b'4'), request[:40]
        time.sleep(0.2)
    finally:
        server.stop()
    assert not [r for r in caplog.records if r.exc_info], caplog.text


def test_loopback_and_bad_server_arguments():
    """Only loopback addresses count as local; no frames or a bad fps is refused."""
    assert is_loopback('127.0.0.1') and is_loopback('::1') and is_loopback('localhost')
    assert not is_loopback('0.0.0.0') and not is_loopback('192.168.1.5')
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    with pytest.raises(InputError, match='no frame'):
        ViewServer(ViewSet(rig), [])
    frames = [([np.zeros((240, 320, 3), np.uint8)] * 3, 0.0, 0.0, 0.0)]
    with pytest.raises(InputError, match='fps'):
        ViewServer(ViewSet(rig), frames, fps=0.0)


def _shown(pace, late_s, period_s=0.04):
    """
    Simulate one tab of the server's loop; return the drawings' start times (s).

    Frame set ``k`` arrives at ``k * period_s``; the tab draws when a frame set newer than
    its last drawing has arrived and its pacing allows (``pace(due, start, period)`` gives
    the next due time); drawing ``n`` starts ``late_s[n]`` after that (the render pool
    busy). Each drawing shows the newest frame set at its start.
    """
    due, shown, starts = 0.0, -1, []
    for late in late_s:
        newest = math.floor(max(due, (shown + 1) * period_s) / period_s + 1e-9)
        start = max(due, newest * period_s) + late
        shown = math.floor(start / period_s + 1e-9)
        starts.append((start, shown))
        due = pace(due, start, period_s)
    return starts


def test_tabs_are_paced_on_the_clock_and_a_late_drawing_loses_no_frame_set():
    """
    Drawings late by up to nearly half a period show every frame set, never faster.

    The pacing before (a period after each drawing's start) added the lags up: here it
    loses frame sets, as 4 tabs of 25 fps got 20-22 frames/s each with the server at 0.9
    of 2 cores (``benchmarks/bench_serve.py --stitcher``).
    """
    rng = np.random.default_rng(5)
    period = 0.04
    late = rng.uniform(0.0, 0.45 * period, 2000)
    starts = _shown(next_draw_due, late, period)
    times, frames = np.array([s for s, _ in starts]), np.array([f for _, f in starts])
    assert np.all(np.diff(frames) == 1), 'every frame set shown once, in order'
    assert np.diff(times).min() >= 0.5 * period - 1e-12
    # never faster than the frame rate: in any span, at most one drawing more than periods
    span = times[100:] - times[:-100]
    assert span.min() >= 99 * period
    old = _shown(lambda due, start, p: start + p, late, period)
    old_frames = np.array([f for _, f in old])
    assert np.count_nonzero(np.diff(old_frames) > 1) > 50, 'the old pacing lost sets'
    # a tab that comes back after a rest draws at once, then at most one per period
    assert next_draw_due(0.0, 100.0, period) == pytest.approx(100.0 + 0.5 * period)
    assert next_draw_due(100.02, 100.02, period) == pytest.approx(100.06)
    # dragged with no new frames: drawings stay a period apart on average
    due, start = 0.0, []
    for _ in range(500):
        start.append(due + rng.uniform(0.0, 0.3 * period))
        due = next_draw_due(due, start[-1], period)
    start = np.array(start)
    assert (start[100:] - start[:-100]).min() >= 99 * period


def test_hostile_tabs_get_a_reason_and_the_others_keep_their_frames(scene, capfd, monkeypatch):
    """
    Answer hostile tabs with a reason, close the abusive ones, keep the others going.

    A binary frame, a 5 kB message, numbers as strings: a reason each, the view kept; a
    flood of messages closes that tab (1008); a reload mid-handshake and a reset after
    answers print nothing; every answer carries the security headers; a tab that acks
    but never reads is closed once a frame waits SEND_TIMEOUT_S; stop() closes the tabs
    with 1001 at once. Before: no reply, 1009 without a reason (view gone), "45" read as
    45, another tab cut from 24 to 3 frames/s, tracebacks, a stuck slot, 14 s to stop.
    """
    import socket

    from accelcal_ros.panorama import serve

    monkeypatch.setattr(serve, 'SEND_TIMEOUT_S', 1.0)
    server = _server(scene, frames=20)

    async def run():
        async with aiohttp.ClientSession() as session:
            page = await session.get(server.url)
            assert page.headers['X-Frame-Options'] == 'DENY'
            assert "frame-ancestors 'none'" in page.headers['Content-Security-Policy']
            assert page.headers['X-Content-Type-Options'] == 'nosniff'
            assert page.headers['Server'] == 'accelcal'
            status = await session.get(server.url + 'status')
            assert status.headers['Cache-Control'] == 'no-store'
            good = await session.ws_connect(server.url + 'ws')
            assert (await _frame(good))[1] is not None
            await good.send_bytes(b'\x00' * 10)
            assert 'binary messages' in (await _frame(good))[0]['error']
            await good.send_str(json.dumps({'az': 1.0, 'pad': 'x' * 5000}))
            assert 'at most 4096 bytes' in (await _frame(good))[0]['error']
            await good.send_str(json.dumps({'az': '45'}))
            assert "must be a number, got '45'" in (await _frame(good))[0]['error']
            await good.send_str(json.dumps({'az': 12.0}))
            info, image = await _frame(good)
            while info is not None and abs(info['az'] - 12.0) > 1e-6:
                info, image = await _frame(good)
            assert image is not None   # kept: the view still draws
            flood = await session.ws_connect(server.url + 'ws')
            for _ in range(serve.MAX_CONTROL_RATE[0] + 50):
                await flood.send_str('{"ack": 1}')
            async for _ in flood:
                pass
            assert flood.close_code == 1008
            assert (await _frame(good))[1] is not None

    asyncio.run(run())
    # a reload mid-handshake: the upgrade request, then a reset before the answer
    for _ in range(5):
        raw = socket.create_connection(('127.0.0.1', server.port))
        raw.sendall(b'GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n'
                    b'Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n'
                    b'Sec-WebSocket-Version: 13\r\n\r\n')
        raw.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b'\x01\x00\x00\x00\x00\x00\x00\x00')
        raw.close()

    # a tab that acks without reading: a tiny receive buffer, masked acks, no recv; its
    # 1280x720 frames fill the server's socket buffer (4 MB at most) in about 2 s
    server.stop()
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    sets = [(render.render_camera_views(scene, rig, ROLL + 0.01 * k, PITCH), ROLL, PITCH,
             0.1 * k) for k in range(5)]
    server = ViewServer(ViewSet(rig, max_views=3, width=1280, height=720), sets, fps=20.0)
    server.start('127.0.0.1', 0)
    stuck = socket.socket()
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
    stuck.connect(('127.0.0.1', server.port))
    stuck.sendall(b'GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n'
                  b'Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n'
                  b'Sec-WebSocket-Version: 13\r\n\r\n')
    ack = b'{"ack": 1}'
    frame = bytes([0x81, 0x80 | len(ack)]) + b'\x00' * 4 + ack   # masked with key 0
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not server.views.names():
        time.sleep(0.05)
    assert server.views.names(), 'the stuck tab got no view'
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline and server.views.names():
        stuck.sendall(frame)
        time.sleep(0.05)
    freed = not server.views.names()   # while its socket is still open
    stuck.close()
    assert freed, server.views.names()

    async def stop_with_a_tab():
        async with aiohttp.ClientSession() as session:
            last = await session.ws_connect(server.url + 'ws')
            assert (await _frame(last))[1] is not None
            started = time.monotonic()
            stopping = asyncio.get_running_loop().run_in_executor(None, server.stop)
            async for _ in last:   # a browser answers the close at once
                pass
            await stopping
            return last.close_code, time.monotonic() - started

    try:
        code, took = asyncio.run(stop_with_a_tab())
    finally:
        server.stop()
    assert code == 1001 and took < 3.0, (code, took)
    err = capfd.readouterr().err
    assert 'Traceback' not in err and 'Error handling request' not in err, err
