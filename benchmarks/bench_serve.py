"""
Benchmark of ``accelcal serve`` (issue 24): frames per second per tab with 1, 2 and 4 tabs.

A recorded rig (5 cameras of 640x480 rendered from the test scene, shifted a little from
one frame set to the next, or random noise with ``--noise``, the worst case for JPEG:
about 3x the encoding time and 15x the bytes; attitude changing every frame set) is
played at ``--fps`` (25); each tab is a WebSocket client that acknowledges every frame
as the page does (decoding the JPEG, as the browser must) and, with ``--moving``, turns
its view a little before every acknowledgement (an operator dragging all the time).
Prints per-tab frames/s, the frame sets played per second, the cores the server's
process kept busy (its CPU time over the wall time) and the load average. A tab is drawn
at most at the frame rate (at least 25 Hz), so 25 frames/s per tab is the most there is.
Python clients stand in for Chromium tabs here (a background Chromium tab is throttled);
the browser test measures the drag-to-image latency in the page.

The clients run in a process of their own and decode with libjpeg-turbo (``simplejpeg``
when installed, as a browser does; else ``cv2.imdecode``), as browsers do on the same
machine; ``--clients here`` runs them in the server's process (the figures before:
there they shared its GIL, and on OpenCV 4.6 decoded without SIMD, about 9 ms a frame).
``--stitcher`` runs the ``stitcher``'s panorama of every frame set beside (one thread at
the frame rate, attitude fixed: issue 24's "views beside the stitcher").
Each row counts ``--seconds`` after ``--warmup`` (1 s): the tabs connect, the views' first
maps and the stitcher's lookup are built first (counted in, they cost a row 1-3 frame sets).
Run: ``python benchmarks/bench_serve.py [--seconds 5] [--warmup 1] [--width 1280 --height 720]
[--stitcher] [--clients process|here]``.
"""
import argparse
import asyncio
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
import json
import math
import multiprocessing
import os
import threading
import time

from accelcal_ros.panorama import render
from accelcal_ros.panorama.horizon_study import REFERENCE_PITCH_RAD, study_rig
from accelcal_ros.panorama.params import panorama_size
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.serve import ViewServer
from accelcal_ros.panorama.stitch import Stitcher
from accelcal_ros.panorama.view_set import ViewSet
import aiohttp
import cv2
import numpy as np


def decode(data):
    """Decode a JPEG as a browser does (libjpeg-turbo: simplejpeg if installed)."""
    try:
        import simplejpeg
    except ImportError:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    return simplejpeg.decode_jpeg(data, colorspace='BGR')


def run_tabs(url, seconds, moving, count, warmup=0.0):
    """Return the frames each of ``count`` clients received (run in a process of its own)."""
    async def run():
        return await asyncio.gather(*[tab(url, seconds, moving, i, warmup)
                                      for i in range(count)])
    return asyncio.run(run())


class StitcherBeside:
    """The stitcher's panorama of the played frame sets, in a thread at ``fps``."""

    def __init__(self, rig, frames, fps):
        width, height, _ = panorama_size(rig, 0, 0, 180.0, 120.0)
        self.stitcher = Stitcher(rig, PanoramaGeometry(width, height, 180.0, 120.0))
        self.frames, self.period, self.done = frames, 1.0 / fps, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        due = time.monotonic()
        while not self._stop.is_set():
            images, _, pitch, _ = self.frames[self.done % len(self.frames)]
            self.stitcher.update(0.0, pitch, images)
            self.stitcher.render()
            self.done += 1
            due += self.period
            self._stop.wait(max(0.0, due - time.monotonic()))

    def stop(self):
        """Stop the thread; return the panoramas made."""
        self._stop.set()
        self._thread.join()
        return self.done


async def tab(url, seconds, moving, index, warmup=0.0):
    """Return frames received in ``seconds`` by one client, after ``warmup`` seconds."""
    count, az = 0, -40.0 + 25.0 * index
    async with aiohttp.ClientSession() as session:
        ws = await session.ws_connect(url + 'ws', max_msg_size=0, compress=15)  # as Chromium
        await ws.send_str(json.dumps({'az': az}))
        begin = time.monotonic() + warmup
        end = begin + seconds
        info = None
        while time.monotonic() < end:
            msg = await ws.receive()
            if msg.type == aiohttp.WSMsgType.TEXT:
                info = json.loads(msg.data)
                continue
            if msg.type != aiohttp.WSMsgType.BINARY:
                break
            decode(msg.data)
            count += time.monotonic() >= begin
            if moving:
                az += 0.2
                await ws.send_str(json.dumps({'az': az}))
            await ws.send_str(json.dumps({'ack': info['sent'] if info else 0}))
        await ws.close()
    return count


def frame_sets(rig, fps, noise):
    """Return the 25 played frame sets: the scene shifted 2 px a set, or noise; attitude moving."""
    rng = np.random.default_rng(1)
    base = render.render_camera_views(render.make_scene(3600, 1800, seed=3), rig, 0.0,
                                      REFERENCE_PITCH_RAD)
    frames = []
    for k in range(25):
        if noise:
            images = [rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8)
                      for c in rig.cameras]
        else:
            images = [np.roll(image, 2 * k, axis=1) for image in base]
        frames.append((images, 0.02 * math.sin(k / 4), REFERENCE_PITCH_RAD, k / fps))
    return frames


def main():
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=5.0, help='per measurement (5)')
    parser.add_argument('--fps', type=float, default=25.0, help='playback rate (25)')
    parser.add_argument('--warmup', type=float, default=1.0,
                        help='seconds each row runs before it counts (1): the tabs connect, '
                        "the views' first maps and the stitcher's lookup are built")
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=720)
    parser.add_argument('--threads', type=int, default=2, help='cv2.setNumThreads (2)')
    parser.add_argument('--noise', action='store_true', help='random images (worst case)')
    parser.add_argument('--stitcher', action='store_true',
                        help="the stitcher's panorama of every frame set beside")
    parser.add_argument('--clients', choices=('process', 'here'), default='process',
                        help='the tabs in a process of their own (default) or in this one')
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)
    rig = study_rig(640, 480)
    frames = frame_sets(rig, args.fps, args.noise)
    print(f'serve benchmark: 5 cameras 640x480 ({"noise" if args.noise else "scene"}) played '
          f'at {args.fps:g} fps, views {args.width}x{args.height} JPEG q80, {args.seconds:g} '
          f's per row, cv2 {cv2.__version__}, {os.cpu_count()} CPUs')
    print(f'  clients: {"own process" if args.clients == "process" else "this process"}; '
          f'stitcher beside: {"yes" if args.stitcher else "no"}')
    print('  tabs | view     | frames/s per tab           | total frames/s | frame sets/s '
          '| panoramas/s | server cores | load')
    clients = ProcessPoolExecutor(1, multiprocessing.get_context('spawn')) \
        if args.clients == 'process' else ThreadPoolExecutor(1)
    clients.submit(sum, ()).result()   # started before the measurements
    for moving in (False, True):
        for count in (1, 2, 4):
            views = ViewSet(rig, max_views=8, width=args.width, height=args.height)
            server = ViewServer(views, frames, args.fps)
            url = server.start('127.0.0.1', 0)
            beside = StitcherBeside(rig, frames, args.fps) if args.stitcher else None
            stitched = '-'
            try:
                running = clients.submit(run_tabs, url, args.seconds, moving, count,
                                         args.warmup)
                time.sleep(args.warmup)
                start, cpu = time.monotonic(), time.process_time()
                played, made = server.frame_number, beside.done if beside else 0
                counts = running.result()
                wall = time.monotonic() - start
                cores = (time.process_time() - cpu) / wall
                played = (server.frame_number - played) / wall
                if beside is not None:
                    stitched = f'{(beside.done - made) / wall:.1f}'
            finally:
                if beside is not None:
                    beside.stop()
                server.stop()
            rates = [c / args.seconds for c in counts]
            print(f'  {count:4d} | {"moving" if moving else "still":8} | '
                  f'{" ".join(f"{r:5.1f}" for r in rates):26} | {sum(rates):14.1f} | '
                  f'{played:12.1f} | {stitched:>11} | {cores:12.2f} | {os.getloadavg()[0]:.1f}')
    clients.shutdown()


if __name__ == '__main__':
    main()
