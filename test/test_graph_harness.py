"""The graph harness's probe: entities destroyed while its executor spins."""
import threading
import time

import pytest
from std_msgs.msg import String


@pytest.mark.graph
def test_probe_survives_subscriptions_destroyed_while_it_spins(graph):
    """
    500 subscriptions made and destroyed under an 800 Hz topic: the executor thread lives on.

    The probe (:class:`~graph_harness.graph._ProbeNode`) destroys them in its executor's
    thread. rclpy's ``destroy_subscription`` from the test's thread raced the executor's
    wait-set building: rarely (3000 cycles here did not hit it), but once in CI, where the
    executor thread died of ``InvalidHandle`` and the probe received nothing more. Each
    destroy returns True (done, in that thread), no thread raised, and the probe still
    receives afterwards.
    """
    node = graph.node
    publisher = node.create_publisher(String, 'harness/fast', 50)
    stop = threading.Event()

    def publish():
        message = String(data='x')
        while not stop.is_set():
            publisher.publish(message)
            time.sleep(1 / 800)

    errors = []
    hook = threading.excepthook
    threading.excepthook = lambda args: errors.append(args.exc_value)
    publisher_thread = threading.Thread(target=publish, daemon=True)
    publisher_thread.start()
    try:
        destroyed = []
        for _ in range(500):
            collector = graph.collect(String, 'harness/fast')
            destroyed.append(graph.unsubscribe(collector))
        alive = graph._thread.is_alive()
        received = graph.collect(String, 'harness/fast').wait_for(1, timeout=10.0)
    finally:
        stop.set()
        publisher_thread.join()
        threading.excepthook = hook
    assert all(destroyed) and not errors and alive and received, errors
    assert graph.in_spin_thread(threading.current_thread) is graph._thread
