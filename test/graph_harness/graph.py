"""
Run installed node executables as separate processes and talk to them with rclpy.

This is what ``ros2 run``, ``ros2 topic echo``, ``ros2 service call`` and ``ros2 param
set`` do, in a real DDS graph (no mocked rclpy). Used by the demo (``run-demo``) and by
the graph tests. Executables are found as ``ros2 run`` finds them: in
``<prefix>/lib/accelcal_ros`` of the package's install prefix (ament index, i.e. after
sourcing ``install/setup.bash``), or under ``$ACCELCAL_INSTALL`` when that is set.
"""
import json
import os
import signal
import subprocess
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data


def executable(name):
    """Return the path of the installed node executable ``name`` (clear error if unbuilt)."""
    if os.environ.get('ACCELCAL_INSTALL'):
        prefix = os.path.join(os.environ['ACCELCAL_INSTALL'], 'accelcal_ros')
    else:
        from ament_index_python.packages import get_package_prefix
        prefix = get_package_prefix('accelcal_ros')
    path = os.path.join(prefix, 'lib', 'accelcal_ros', name)
    if not os.path.exists(path):
        raise FileNotFoundError(f'{path} not found: run tools/bootstrap.sh (colcon build) '
                                'and source tools/env.sh')
    return path


def ros_arg_value(value):
    """Format a parameter value as ``--ros-args -p name:=VALUE`` wants it (YAML)."""
    return json.dumps(value)


class NodeProcess:
    """One node executable running as its own process; output goes to a log file."""

    def __init__(self, exe, params=None, remaps=None, log_dir='.', name=None, args=(),
                 prefix=(), env=None, argv=None):
        """
        Start ``exe`` (an installed executable; ``argv``: this command line instead).

        ``prefix``: words before the command (e.g. ``ip netns exec HOST``); ``env``:
        variables set on top of this process's environment.
        """
        self.exe = exe
        self.log_path = os.path.join(str(log_dir), f'{name or exe}.log')
        cmd = list(argv) if argv is not None else [executable(exe), *args, '--ros-args']
        for key, value in (params or {}).items():
            cmd += ['-p', f'{key}:={ros_arg_value(value)}']
        for src, dst in (remaps or {}).items():
            cmd += ['-r', f'{src}:={dst}']
        self._log = open(self.log_path, 'w')
        self.proc = subprocess.Popen([*prefix, *cmd], stdout=self._log,
                                     stderr=subprocess.STDOUT,
                                     env=dict(os.environ, PYTHONUNBUFFERED='1', **(env or {})))

    def output(self):
        """Everything the process printed so far."""
        self._log.flush()
        with open(self.log_path) as handle:
            return handle.read()

    def wait_exit(self, timeout=20.0):
        """Wait for the process to exit by itself; returns its exit code."""
        return self.proc.wait(timeout=timeout)

    def stop(self, timeout=10.0):
        """SIGINT, then SIGKILL if it does not stop; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


class _ProbeNode(Node):
    """
    The probe node: what is destroyed while its executor spins is destroyed in that thread.

    rclpy 7's executor builds its wait set from the node's entities without a lock: a
    subscription (with its QoS event handlers) destroyed from another thread meanwhile
    raised ``InvalidHandle: cannot use Destroyable because destruction was requested`` in
    the executor's thread, which died, and the probe received nothing more (CI:
    ``test_still_scene_panorama_horizon_is_steady[800.0]``, "0 panoramas received", after
    the test dropped its 800 Hz subscription). So ``destroy_*`` (tests, the drive helpers)
    hand the destruction to :meth:`Graph.in_spin_thread`.
    """

    graph = None

    def _in_spin_thread(self, destroy, entity):
        if self.graph is None:
            return destroy(self, entity)
        return self.graph.in_spin_thread(lambda: destroy(self, entity))

    def destroy_publisher(self, publisher):
        return self._in_spin_thread(Node.destroy_publisher, publisher)

    def destroy_subscription(self, subscription):
        return self._in_spin_thread(Node.destroy_subscription, subscription)

    def destroy_client(self, client):
        return self._in_spin_thread(Node.destroy_client, client)

    def destroy_service(self, service):
        return self._in_spin_thread(Node.destroy_service, service)

    def destroy_timer(self, timer):
        return self._in_spin_thread(Node.destroy_timer, timer)


class Graph:
    """
    A probe node (own context and executor thread) plus the node processes it started.

    The default timeouts (30 s) bound a hang, not a speed: a node's start-up (imports,
    discovery) on a loaded 2-core machine takes seconds, and a wait ends as soon as its
    condition holds.
    """

    def __init__(self, log_dir='.', name='probe'):
        self.log_dir = log_dir
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = _ProbeNode(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = False
        self._pending = []
        self._pending_lock = threading.Lock()
        self._wake = self.node.create_guard_condition(lambda: None)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self.node.graph = self
        self.processes = []
        self._clients = {}

    def _spin(self):
        while not self._stop and self.context.ok():
            with self._pending_lock:
                pending, self._pending = self._pending, []
            for run in pending:
                run()
            self.executor.spin_once(timeout_sec=0.05)

    def in_spin_thread(self, function, timeout=30.0):
        """
        Run ``function()`` in the probe's executor thread, between two waits; return its result.

        Run at once when called from that thread or once it has stopped (:meth:`close`).
        """
        if threading.current_thread() is self._thread or not self._thread.is_alive():
            return function()
        done, outcome = threading.Event(), {}

        def run():
            try:
                outcome['value'] = function()
            except BaseException as exc:  # handed to the caller
                outcome['error'] = exc
            finally:
                done.set()

        with self._pending_lock:
            self._pending.append(run)
        self._wake.trigger()  # ends the executor's wait now
        if not done.wait(timeout):
            raise TimeoutError(f"the probe's executor thread did not run {function!r} "
                               f'in {timeout} s')
        if 'error' in outcome:
            raise outcome['error']
        return outcome.get('value')

    def unsubscribe(self, collector):
        """Stop ``collector``'s subscription (destroyed in the executor's thread); True if done."""
        return self.node.destroy_subscription(collector._sub)

    def start(self, exe, params=None, remaps=None, name=None, args=()):
        """Start an installed executable as a process; it is stopped in :meth:`close`."""
        proc = NodeProcess(exe, params, remaps, self.log_dir, name, args)
        self.processes.append(proc)
        return proc

    def collect(self, msg_type, topic, qos=qos_profile_sensor_data):
        """Subscribe and collect messages with their receive time: returns a Collector."""
        return Collector(self.node, msg_type, topic, qos)

    def call(self, srv_type, name, request=None, timeout=30.0, resend_s=None):
        """
        Call a service (waiting for it to appear); returns the response.

        A server answers a client only once it has matched the client's reply reader, and
        it waits 100 ms for that (rmw_fastrtps' send_response): a request sent just after
        a client was made can lose its answer while discovery is slow (a loaded machine).
        (and a node started again under the same name meets the probe's clients anew). So:

        - ``resend_s`` set (an idempotent service: parameters): the request is sent again
          when no answer came within that many seconds;
        - otherwise (a service that changes state: start, capture, ...; a second request
          would be a second action) the request waits until the node has matched the
          client (:meth:`_until_server_knows_client`).

        Clients are kept for the graph's life (one per service: none is destroyed while the
        probe's executor may still hold an answer for it).
        """
        client = self._clients.get((srv_type, name))
        fresh = client is None
        if fresh:
            client = self.node.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                raise TimeoutError(f'service {name} did not appear in {timeout} s')
            if resend_s is None:
                self._until_server_knows_client(name, timeout)
        except BaseException:
            if fresh:
                self.node.destroy_client(client)
            raise
        if fresh:
            self._clients[(srv_type, name)] = client
        return self._send(client, name, request if request is not None else srv_type.Request(),
                          timeout, resend_s)

    @staticmethod
    def _send(client, name, request, timeout, resend_s):
        """Send ``request`` (again every ``resend_s`` if set) until answered or ``timeout``."""
        deadline = time.monotonic() + timeout
        sends = 0
        while True:
            future = client.call_async(request)
            sends += 1
            resend_at = deadline if resend_s is None else time.monotonic() + resend_s
            while not future.done() and time.monotonic() < min(deadline, resend_at):
                time.sleep(0.01)
            if future.done():
                return future.result()
            client.remove_pending_request(future)
            if time.monotonic() >= deadline:
                raise TimeoutError(f'service {name} did not answer in {timeout} s '
                                   f'({sends} requests)')

    def _until_server_knows_client(self, name, timeout):
        """
        Return once the node serving ``name`` has matched the probe's client of it.

        The node's own get_parameters (idempotent, sent again until answered) is called
        through a client made after that one: the probe announces its endpoints to the node
        in order on one reliable discovery channel, so the node's answer to the later client
        shows it has matched the earlier one's reply reader too. Services outside a node's
        namespace (no ``<node>/get_parameters`` beside them) are sent as they are.
        """
        from rcl_interfaces.srv import GetParameters

        node_name = name.rsplit('/', 1)[0] if '/' in name.strip('/') else ''
        if not node_name:
            return
        node_name = '/' + node_name.lstrip('/')
        services = {n for n, _ in self.node.get_service_names_and_types()}
        if f'{node_name}/get_parameters' not in services:
            return
        later = self.node.create_client(GetParameters, f'{node_name}/get_parameters')
        try:
            if later.wait_for_service(timeout_sec=timeout):
                self._send(later, f'{node_name}/get_parameters', GetParameters.Request(),
                           timeout, 5.0)
        finally:
            self.node.destroy_client(later)

    def set_parameters(self, node_name, values, timeout=30.0):
        """``ros2 param set``: returns the list of SetParametersResult."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        request = SetParameters.Request()
        request.parameters = [Parameter(k, value=v).to_parameter_msg()
                              for k, v in values.items()]
        return self.call(SetParameters, f'/{node_name}/set_parameters', request,
                         timeout, resend_s=5.0).results

    def get_parameters(self, node_name, names, timeout=30.0):
        """``ros2 param get``: returns {name: python value}."""
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        request = GetParameters.Request()
        request.names = list(names)
        response = self.call(GetParameters, f'/{node_name}/get_parameters', request, timeout,
                             resend_s=5.0)
        return {n: parameter_value_to_python(v) for n, v in zip(names, response.values)}

    def close(self):
        """Stop every started process and the probe."""
        for proc in self.processes:
            proc.stop()
        self._stop = True
        self._thread.join(timeout=10.0)
        self.node.graph = None  # the executor is done: destroyed here, at once
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


class Collector:
    """Messages of one topic, each with its receive time (time.time())."""

    def __init__(self, node, msg_type, topic, qos):
        self.messages = []
        self.receive_times = []
        self._lock = threading.Lock()
        self._sub = node.create_subscription(msg_type, topic, self._on_msg, qos)

    def _on_msg(self, msg):
        with self._lock:
            self.messages.append(msg)
            self.receive_times.append(time.time())

    def wait_for(self, count, timeout=30.0):
        """Wait until at least ``count`` messages arrived; returns a copy of them."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if len(self.messages) >= count:
                    return list(self.messages)
            time.sleep(0.02)
        with self._lock:
            got = len(self.messages)
        raise TimeoutError(f'got {got} of {count} messages in {timeout} s')

    def snapshot(self):
        """``(messages, receive_times)`` copied."""
        with self._lock:
            return list(self.messages), list(self.receive_times)

    def clear(self):
        """Forget what was collected."""
        with self._lock:
            self.messages.clear()
            self.receive_times.clear()


def newest_status_values(diag, name):
    """Return the key-value pairs of the newest status ``name`` a /diagnostics Collector holds."""
    values = {}
    for msg in diag.snapshot()[0]:
        for status in msg.status:
            if status.name == name:
                values = {kv.key: kv.value for kv in status.values}
    return values
