"""PipelinedStitcher: same panoramas as one Stitcher, in order, bad input queues nothing."""
import math
import threading

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.panorama import render
from accelcal_ros.panorama.pipeline import PipelinedStitcher
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.stitch import Stitcher
import numpy as np
import pytest


def _rig():
    return ring_rig(4, 320, 240, 275.0, 40.0, distortion=(-0.1, 0.02, 0.0, 0.0, 0.0), seed=5)


@pytest.mark.parametrize('stages', [1, 2])
def test_pipeline_delivers_the_plain_stitchers_frames_in_order(stages):
    """Every frame (attitude changing each time) equals a plain Stitcher's, in order."""
    rig = _rig()
    geometry = PanoramaGeometry(480, 320)
    scene = render.make_scene(900, 450, seed=4)
    frames = []
    for k in range(6):
        roll, pitch = math.radians(2.0 * math.sin(k)), math.radians(3.0 * math.cos(k))
        frames.append((roll, pitch, render.render_camera_views(scene, rig, roll, pitch)))
    plain = Stitcher(rig, geometry)
    expected = [plain.stitch(views, roll, pitch) for roll, pitch, views in frames]
    got, threads = [], set()

    def consume(panorama):
        threads.add(threading.current_thread().name)
        got.append(panorama.copy())
        return len(got)

    pipeline = PipelinedStitcher(rig, geometry, stages=stages)
    futures = [pipeline.submit(roll, pitch, views, consume) for roll, pitch, views in frames]
    pipeline.close()
    assert [f.result() for f in futures] == list(range(1, len(frames) + 1))
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        assert np.array_equal(a, b)
    assert all(name.startswith('panorama_remap') for name in threads)
    assert pipeline.rebuild_count == len(frames)
    assert pipeline.last_rebuild_s > 0
    # the latest rebuild is the last frame's stage's (stage counts tie after an even run)
    assert pipeline.last_rebuild_s == pipeline.stitchers[(len(frames) - 1) % stages].last_rebuild_s


def test_pipeline_bad_input_queues_nothing_and_threshold_reaches_every_stage():
    """A wrong image raises in submit (nothing rendered); the threshold setter fans out."""
    rig = _rig()
    pipeline = PipelinedStitcher(rig, PanoramaGeometry(240, 160), stages=2)
    good = [np.zeros((240, 320, 3), np.uint8) for _ in range(4)]
    bad = list(good)
    bad[2] = np.zeros((240, 321, 3), np.uint8)
    calls = []
    with pytest.raises(InputError, match='camera 2'):
        pipeline.submit(0.0, 0.0, bad, calls.append)
    pipeline.drain()
    assert calls == [] and pipeline.rebuild_count == 0
    pipeline.rebuild_threshold_deg = 0.5
    assert [s.rebuild_threshold_deg for s in pipeline.stitchers] == [0.5, 0.5]
    pipeline.submit(0.0, 0.0, good, calls.append).result()
    assert len(calls) == 1
    pipeline.close()
    with pytest.raises(InputError, match='stages'):
        PipelinedStitcher(rig, PanoramaGeometry(240, 160), stages=3)
