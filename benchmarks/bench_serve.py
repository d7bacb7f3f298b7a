"""
Benchmark of ``accelcal serve`` (issue 24): frames per second per tab with 1, 2 and 4 tabs.

A recorded rig (5 cameras of 640x480 rendered from the test scene, shifted a little from
one frame set to the next, or random noise with ``--noise``, the worst case for JPEG:
about 3x the encoding time and 15x the bytes; attitude changing every frame set) is
played at ``--fps`` (25); each tab is a WebSocket client that acknowledges every frame
as the page does (decoding the JPEG, as the browser must) and, with ``--moving``, turns
its view a little before every acknowledgement (an operator dragging all the time).
Prints per-tab frames/s and the load average. A tab is drawn at most at the frame rate
(at least 25 Hz), so 25 frames/s per tab is the most there is. Python clients stand in for
Chromium tabs here (a background Chromium tab is throttled); the browser test measures
the drag-to-image latency in the page.
Run: ``python benchmarks/bench_serve.py [--seconds 5] [--width 1280 --height 720]``.
"""
import argparse
import asyncio
import json
import math
import os
import time

from accelcal_ros.panorama import render
from accelcal_ros.panorama.horizon_study import REFERENCE_PITCH_RAD, study_rig
from accelcal_ros.panorama.serve import ViewServer
from accelcal_ros.panorama.view_set import ViewSet
import aiohttp
import cv2
import numpy as np


async def tab(url, seconds, moving, index):
    """Return frames received in ``seconds`` by one client."""
    count, az = 0, -40.0 + 25.0 * index
    async with aiohttp.ClientSession() as session:
        ws = await session.ws_connect(url + 'ws', max_msg_size=0)
        await ws.send_str(json.dumps({'az': az}))
        end = time.monotonic() + seconds
        info = None
        while time.monotonic() < end:
            msg = await ws.receive()
            if msg.type == aiohttp.WSMsgType.TEXT:
                info = json.loads(msg.data)
                continue
            if msg.type != aiohttp.WSMsgType.BINARY:
                break
            cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)
            count += 1
            if moving:
                az += 0.2
                await ws.send_str(json.dumps({'az': az}))
            await ws.send_str(json.dumps({'ack': info['sent'] if info else 0}))
        await ws.close()
    return count


def main():
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=5.0, help='per measurement (5)')
    parser.add_argument('--fps', type=float, default=25.0, help='playback rate (25)')
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=720)
    parser.add_argument('--threads', type=int, default=2, help='cv2.setNumThreads (2)')
    parser.add_argument('--noise', action='store_true', help='random images (worst case)')
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)
    rig = study_rig(640, 480)
    rng = np.random.default_rng(1)
    base = render.render_camera_views(render.make_scene(3600, 1800, seed=3), rig, 0.0,
                                      REFERENCE_PITCH_RAD)
    frames = []
    for k in range(25):
        if args.noise:
            images = [rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8)
                      for c in rig.cameras]
        else:
            images = [np.roll(image, 2 * k, axis=1) for image in base]
        frames.append((images, 0.02 * math.sin(k / 4), REFERENCE_PITCH_RAD, k / args.fps))
    print(f'serve benchmark: 5 cameras 640x480 ({"noise" if args.noise else "scene"}) played '
          f'at {args.fps:g} fps, views {args.width}x{args.height} JPEG q80, {args.seconds:g} '
          f's per row, cv2 {cv2.__version__}, {os.cpu_count()} CPUs')
    print('  tabs | view     | frames/s per tab           | total frames/s | load')
    for moving in (False, True):
        for count in (1, 2, 4):
            views = ViewSet(rig, max_views=8, width=args.width, height=args.height)
            server = ViewServer(views, frames, args.fps)
            url = server.start('127.0.0.1', 0)

            async def run():
                return await asyncio.gather(*[tab(url, args.seconds, moving, i)
                                              for i in range(count)])

            try:
                counts = asyncio.run(run())
            finally:
                server.stop()
            rates = [c / args.seconds for c in counts]
            print(f'  {count:4d} | {"moving" if moving else "still":8} | '
                  f'{" ".join(f"{r:5.1f}" for r in rates):26} | {sum(rates):14.1f} | '
                  f'{os.getloadavg()[0]:.1f}')


if __name__ == '__main__':
    main()
