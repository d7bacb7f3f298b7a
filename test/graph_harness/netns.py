"""
Two "hosts" on one machine: network namespaces joined by a veth pair (root and iproute2).

:class:`TwoHosts` creates namespaces ``a`` and ``b`` with unique names
(``accelcal-<pid>-<random>-a``), a veth pair between them, an address each in a private
/24 chosen at random (``10.<200..254>.<0..255>.1`` and ``.2``: they exist only inside the
two namespaces, no other address is touched), loopback up and a multicast route on the
veth (DDS discovery, ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``). Processes run in a host
with :meth:`TwoHosts.prefix` (``ip netns exec NAME``); :meth:`TwoHosts.inside` moves the
calling thread (and the threads it starts, e.g. an rclpy context's) into one.
:meth:`TwoHosts.shape` limits each direction of the link with a token bucket (``tc
qdisc tbf``). :meth:`TwoHosts.remove` deletes both namespaces (the veth pair and the
qdiscs go with them); it runs at the end, also after a failure, and namespaces left by a
run that was killed (its pid gone) are removed by the next one.

:func:`unavailable` returns why the machine cannot do this (not root, no ``ip``, netns
refused), or ``''``.
"""
import contextlib
import ctypes
import os
import random
import re
import shutil
import subprocess

CLONE_NEWNET = 0x40000000
NAME_PATTERN = re.compile(r'^accelcal-(\d+)-[0-9a-f]+-[ab]$')


def _ip(*args, check=True):
    return subprocess.run(['ip', *args], check=check, capture_output=True, text=True,
                          timeout=30)


def unavailable():
    """Return why two network namespaces cannot be made here, or '' when they can."""
    if os.name != 'posix' or not hasattr(os, 'geteuid'):
        return 'network namespaces need Linux'
    if os.geteuid() != 0:
        return 'network namespaces need root (ip netns add); run the suite as root'
    if shutil.which('ip') is None:
        return 'iproute2 (the ip command) is not installed'
    name = f'accelcal-{os.getpid()}-{random.randrange(16 ** 6):06x}-a'
    result = _ip('netns', 'add', name, check=False)
    if result.returncode != 0:
        return f'ip netns add failed: {result.stderr.strip()}'
    _ip('netns', 'del', name, check=False)
    return ''


def remove_stale():
    """Delete namespaces of this harness whose creating process is gone."""
    listing = _ip('netns', 'list', check=False).stdout.split()
    for name in listing:
        match = NAME_PATTERN.match(name)
        if match and not os.path.exists(f'/proc/{match.group(1)}'):
            _ip('netns', 'del', name, check=False)


class TwoHosts:
    """Namespaces ``a`` and ``b`` joined by a veth pair (see the module)."""

    def __init__(self):
        remove_stale()
        tag = f'{random.randrange(16 ** 6):06x}'
        self.names = {h: f'accelcal-{os.getpid()}-{tag}-{h}' for h in 'ab'}
        self.links = {h: f'ac{tag}{h}' for h in 'ab'}
        net = f'10.{random.randint(200, 254)}.{random.randint(0, 255)}'
        self.addresses = {'a': f'{net}.1', 'b': f'{net}.2'}
        self._created = []
        try:
            for host in 'ab':
                _ip('netns', 'add', self.names[host])
                self._created.append(self.names[host])
            _ip('link', 'add', self.links['a'], 'netns', self.names['a'], 'type', 'veth',
                'peer', 'name', self.links['b'], 'netns', self.names['b'])
            for host in 'ab':
                ns, link = self.names[host], self.links[host]
                _ip('-n', ns, 'addr', 'add', f'{self.addresses[host]}/24', 'dev', link)
                _ip('-n', ns, 'link', 'set', 'lo', 'up')
                _ip('-n', ns, 'link', 'set', link, 'up')
                _ip('-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', link)
        except BaseException:
            self.remove()
            raise

    def prefix(self, host):
        """Return the command prefix that runs a program in ``host`` ('a' or 'b')."""
        return ['ip', 'netns', 'exec', self.names[host]]

    def run(self, host, *command, check=True):
        """Run a command in ``host``; returns the CompletedProcess."""
        return subprocess.run([*self.prefix(host), *command], check=check,
                              capture_output=True, text=True, timeout=60)

    def shape(self, rate='1gbit', burst='256kb', latency='50ms'):
        """Limit each direction of the link to ``rate`` (tc tbf on both veth ends)."""
        for host in 'ab':
            self.run(host, 'tc', 'qdisc', 'replace', 'dev', self.links[host], 'root', 'tbf',
                     'rate', rate, 'burst', burst, 'latency', latency)

    def link_bytes(self, host):
        """Bytes sent and received on ``host``'s veth end so far: ``(tx, rx)``."""
        base = f'/sys/class/net/{self.links[host]}/statistics'
        out = self.run(host, 'cat', f'{base}/tx_bytes', f'{base}/rx_bytes').stdout.split()
        return int(out[0]), int(out[1])

    @contextlib.contextmanager
    def inside(self, host):
        """Move the calling thread into ``host`` (and back); threads it starts stay there."""
        libc = ctypes.CDLL(None, use_errno=True)
        own = os.open('/proc/thread-self/ns/net', os.O_RDONLY)
        target = os.open(f'/var/run/netns/{self.names[host]}', os.O_RDONLY)
        try:
            if libc.setns(target, CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), f'setns into {self.names[host]} failed')
            try:
                yield
            finally:
                if libc.setns(own, CLONE_NEWNET) != 0:
                    raise OSError(ctypes.get_errno(), 'setns back failed')
        finally:
            os.close(target)
            os.close(own)

    def remove(self):
        """Delete both namespaces (veth and qdiscs with them); errors ignored."""
        for name in self._created:
            _ip('netns', 'del', name, check=False)
        self._created = []
