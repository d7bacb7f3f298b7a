"""The decode pool: keys in parallel, per key in order and newest only (rosutil.decode_pool)."""
import threading
import time

from accelcal_ros.rosutil.decode_pool import DecodePool


def _wait(condition, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def test_keys_run_in_parallel():
    """Five cameras' jobs run at once: a barrier of five is passed (serial: it times out)."""
    barrier = threading.Barrier(5, timeout=20.0)
    passed = []
    pool = DecodePool(5)
    try:
        for key in range(5):
            pool.submit(key, lambda k: passed.append((k, barrier.wait())), key)
        assert _wait(lambda: len(passed) == 5)
    finally:
        pool.close()
    assert sorted(k for k, _ in passed) == list(range(5))


def test_one_key_runs_in_order_and_keeps_only_the_newest_waiting_job():
    gate = threading.Event()
    seen = []
    pool = DecodePool(3)
    try:
        pool.submit('cam0', lambda v: (gate.wait(20.0), seen.append(v)), 0)
        assert _wait(lambda: not pool.idle() and pool.done == 0)
        for value in range(1, 6):            # 1..4 replaced while 0 runs
            pool.submit('cam0', seen.append, value)
        gate.set()
        assert _wait(pool.idle)
    finally:
        pool.close()
    assert seen == [0, 5] and pool.replaced == 4 and pool.done == 2
    assert pool.mean_job_s() is not None


def test_errors_go_to_the_handler_and_the_pool_goes_on():
    errors, seen = [], []

    def fail(value):
        raise ValueError(f'bad {value}')

    pool = DecodePool(1, on_error=lambda key, exc: errors.append((key, str(exc))))
    try:
        pool.submit('a', fail, 1)
        assert _wait(pool.idle)
        pool.submit('a', seen.append, 2)
        assert _wait(lambda: seen == [2])
    finally:
        pool.close()
    assert errors == [('a', 'bad 1')]
    pool.submit('a', seen.append, 3)         # closed: ignored
    assert seen == [2]


def test_replaced_jobs_are_handed_to_on_replace():
    """Each job replaced before it ran is counted and handed on (a node's DropCounter)."""
    gate = threading.Event()
    replaced = []
    pool = DecodePool(2, on_replace=replaced.append)
    try:
        pool.submit('cam0', lambda: gate.wait(20.0))
        assert _wait(lambda: not pool.idle() and pool.done == 0)
        for _ in range(4):                   # the first waits; three replace one another
            pool.submit('cam0', lambda: None)
        pool.submit('cam1', lambda: None)    # another key replaces nothing
        gate.set()
        assert _wait(pool.idle)
    finally:
        pool.close()
    assert replaced == ['cam0'] * 3 and pool.replaced == 3
