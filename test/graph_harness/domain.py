"""
Allocate a ROS domain ID no other process on this machine is using (lock files).

Used by the test sessions and by the demo (unless ``ROS_DOMAIN_ID`` is set), so that
concurrent runs on one machine never see each other's topics, services or parameters.
"""
import fcntl
import os
import random
import tempfile


class DomainLease:
    """Holds the lock on one domain ID for the life of the process."""

    def __init__(self, domain_id, handle):
        self.domain_id = domain_id
        self._handle = handle


def allocate_domain_id(low=1, high=100):
    """Lock and return a free domain ID in ``[low, high]`` (localhost discovery)."""
    candidates = list(range(low, high + 1))
    random.shuffle(candidates)
    lock_dir = os.path.join(tempfile.gettempdir(), 'accelcal_ros_domains')
    os.makedirs(lock_dir, exist_ok=True)
    for domain_id in candidates:
        handle = open(os.path.join(lock_dir, f'{domain_id}.lock'), 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        return DomainLease(domain_id, handle)
    raise RuntimeError('no free ROS domain ID')
