"""
``accelcal serve`` in headless Chromium (issue 24): frames drawn per second in 1, 2 and 4 pages.

``bench_serve.py`` stands Python clients in for the tabs; here the tabs are real Chromium
pages (Debian's ``chromium`` + ``chromium-driver`` through selenium), each its own window
(a background tab would be throttled by the browser), drawing every frame as an operator
sees it: the page decodes the JPEG, shows it, draws the HUD and the horizon and
acknowledges it. The recording is ``bench_serve.py``'s (5 cameras of 640x480 from the test
scene, played at ``--fps``), the views 1280x720, with the stitcher's panorama of every
frame set beside (``--stitcher``); "moving": each page turns its view by a key press every
20 ms (an operator panning all the time). Frames per page are read off the page's own
counter (``window.accelcal.drawn()``) over ``--seconds`` after ``--warmup``; the server's
cores are its process's CPU time over the wall time, Chromium's those of all its processes
(``/proc``): it runs on the same 2 cores.
Run: ``python benchmarks/bench_serve_browser.py [--seconds 5] [--warmup 2] [--stitcher]``.
"""
import argparse
import os
import shutil
import time

from accelcal_ros.panorama.horizon_study import study_rig
from accelcal_ros.panorama.serve import ViewServer
from accelcal_ros.panorama.view_set import ViewSet
from bench_serve import frame_sets, StitcherBeside
import cv2

PANNING = ('window._pan = setInterval(() => window.dispatchEvent('
           'new KeyboardEvent("keydown", {key: "ArrowRight"})), 20);')


def browser():
    """Start headless Chromium through chromedriver (None when either is missing)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    chromium = shutil.which('chromium') or shutil.which('chromium-browser')
    driver = shutil.which('chromedriver')
    if not (chromium and driver):
        return None
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ('--headless=new', '--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage',
                '--window-size=1300,800', '--disable-background-timer-throttling',
                '--disable-renderer-backgrounding', '--disable-backgrounding-occluded-windows'):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(driver), options=options)


def browser_cpu_s():
    """Return the CPU time (s) of every Chromium process so far (``/proc``, Linux)."""
    total, tick = 0.0, os.sysconf('SC_CLK_TCK')
    for pid in filter(str.isdigit, os.listdir('/proc')):
        try:
            with open(f'/proc/{pid}/cmdline', 'rb') as f:
                if b'chrom' not in f.read().split(b'\0')[0]:
                    continue
            with open(f'/proc/{pid}/stat') as f:
                fields = f.read().rsplit(')', 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            continue
    return total


def drawn(driver, handles):
    """Return the frames each page has drawn so far."""
    counts = []
    for handle in handles:
        driver.switch_to.window(handle)
        counts.append(driver.execute_script('return window.accelcal.drawn();'))
    return counts


def run_row(driver, url, pages, moving, warmup, seconds):
    """Open ``pages`` windows on ``url``; return frames/s drawn by each (then close them)."""
    handles = []
    for k in range(pages):
        if k:
            driver.switch_to.new_window('window')
        driver.get(url)
        handles.append(driver.current_window_handle)
    for handle in handles:
        driver.switch_to.window(handle)
        deadline = time.monotonic() + 30.0
        while not driver.execute_script('return window.accelcal && window.accelcal.drawn();'):
            if time.monotonic() > deadline:
                raise RuntimeError('a page drew nothing in 30 s')
            time.sleep(0.05)
        if moving:
            driver.execute_script(PANNING)
    time.sleep(warmup)
    start, before, cpu = time.monotonic(), drawn(driver, handles), time.process_time()
    chromium = browser_cpu_s()
    time.sleep(seconds)
    after, wall = drawn(driver, handles), time.monotonic() - start
    cores = ((time.process_time() - cpu) / wall, (browser_cpu_s() - chromium) / wall)
    for handle in handles[1:]:
        driver.switch_to.window(handle)
        driver.close()
    driver.switch_to.window(handles[0])
    driver.get('about:blank')
    return [(b - a) / wall for a, b in zip(before, after)], cores


def main():
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=5.0, help='per row (5)')
    parser.add_argument('--warmup', type=float, default=2.0, help='before each row (2)')
    parser.add_argument('--fps', type=float, default=25.0, help='playback rate (25)')
    parser.add_argument('--stitcher', action='store_true',
                        help="the stitcher's panorama of every frame set beside")
    args = parser.parse_args()
    driver = browser()
    if driver is None:
        print('bench_serve_browser: no chromium/chromedriver (Debian: apt-get install '
              'chromium chromium-driver); nothing measured')
        return
    rig = study_rig(640, 480)
    frames = frame_sets(rig, args.fps, noise=False)
    print(f'serve in Chromium: 5 cameras 640x480 played at {args.fps:g} fps, views 1280x720, '
          f'cv2 {cv2.__version__}, {os.cpu_count()} CPUs, stitcher beside: '
          f'{"yes" if args.stitcher else "no"}')
    print('  pages | view   | frames/s drawn per page    | frame sets/s | server cores '
          '| Chromium cores | load')
    try:
        for moving in (False, True):
            for pages in (1, 2, 4):
                server = ViewServer(ViewSet(rig, max_views=8, width=1280, height=720),
                                    frames, args.fps)
                url = server.start('127.0.0.1', 0)
                beside = StitcherBeside(rig, frames, args.fps) if args.stitcher else None
                played = server.frame_number
                t0 = time.monotonic()
                try:
                    rates, cores = run_row(driver, url, pages, moving, args.warmup,
                                           args.seconds)
                finally:
                    if beside is not None:
                        beside.stop()
                    sets = (server.frame_number - played) / (time.monotonic() - t0)
                    server.stop()
                print(f'  {pages:5d} | {"moving" if moving else "still":6} | '
                      f'{" ".join(f"{r:5.1f}" for r in rates):26} | {sets:12.1f} | '
                      f'{cores[0]:12.2f} | {cores[1]:14.2f} | {os.getloadavg()[0]:.1f}')
    finally:
        driver.quit()


if __name__ == '__main__':
    main()
