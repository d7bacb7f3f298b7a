"""Randomly damaged bags: every failure is one FileFormatError, never another exception."""
import random
import shutil

from accelcal_ros.errors import FileFormatError
from accelcal_ros.recording.bag import BagReader
from accelcal_ros.recording.sim_bags import bag_path, FORMATS, write_imu_bag
import numpy as np
import pytest


def _damage(data, rng, kind):
    bad = bytearray(data)
    if kind == 0:  # cut short
        return bytes(bad[:rng.randrange(len(bad))])
    if kind == 1:  # a run of garbage
        start = rng.randrange(len(bad))
        for i in range(start, min(len(bad), start + rng.randrange(1, 400))):
            bad[i] = rng.randrange(256)
        return bytes(bad)
    for _ in range(20):  # scattered bit rot
        bad[rng.randrange(len(bad))] = rng.randrange(256)
    return bytes(bad)


@pytest.mark.parametrize('fmt', FORMATS)
def test_damaged_bag_raises_file_format_error_only(fmt, tmp_path):
    """Truncation, garbage and bit rot: the bag reads whole or raises FileFormatError."""
    src = bag_path(tmp_path, 'src', fmt)
    t = np.arange(200) * 0.01
    write_imu_bag(src, fmt, t, np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    storage = (next(p for p in src.iterdir() if p.suffix in ('.mcap', '.db3'))
               if src.is_dir() else src)
    data = storage.read_bytes()
    rng = random.Random(7)
    failures = 0
    for trial in range(30):
        bad = _damage(data, rng, trial % 3)
        if src.is_dir():
            target = tmp_path / f'bad{trial}'
            shutil.copytree(src, target)
            (target / storage.name).write_bytes(bad)
        else:
            target = tmp_path / f'bad{trial}.bag'
            target.write_bytes(bad)
        try:
            with BagReader(target) as bag:
                for _ in bag.messages(list(bag.topics())):
                    pass
        except FileFormatError as exc:
            failures += 1
            assert str(target) in str(exc) and '\n' not in str(exc)
    assert failures >= 10  # most damage is detected (a few bytes of payload may not be)


@pytest.mark.parametrize('fraction', [0.3, 0.8])
def test_cut_short_mcap_says_how_far_it_reads(fraction, tmp_path):
    """A cut-short MCAP (no footer): the error names the complete messages and their span."""
    src = bag_path(tmp_path, 'src', 'mcap')
    t = np.arange(400) * 0.01
    write_imu_bag(src, 'mcap', t, np.tile([0.0, 0.0, 9.81], (len(t), 1)))
    storage = next(src.glob('*.mcap'))
    data = storage.read_bytes()
    storage.write_bytes(data[:int(len(data) * fraction)])
    with pytest.raises(FileFormatError) as info:
        BagReader(src)
    text = str(info.value)
    assert f'{storage.name} is cut short' in text and '\n' not in text, text
    count = int(text.split(' complete messages')[0].split('(')[-1])
    span = float(text.split(' s after the first message')[0].split('read up to ')[-1])
    # the messages are evenly spread over the file: the part kept holds about its share
    assert 0 < count < 400 and abs(count - 400 * fraction) < 40, text
    assert span == pytest.approx((count - 1) * 0.01, abs=1e-6), text
