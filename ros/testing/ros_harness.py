"""Processes for the ROS bridge's tests and benchmark, all on 127.0.0.1.

A private ROS master on a free port (rosmaster from Debian), a cloudcast-server, the bridge,
Debian's stereo_image_proc and depth_image_proc nodelets and the New Tsukuba publisher, each a
child process with its log in a scratch folder, stopped (SIGINT, then SIGKILL) when the harness
closes.

Network: everything talks to 127.0.0.1 (ROS_IP=127.0.0.1, ROS_MASTER_URI=http://127.0.0.1:PORT),
but roscpp's and rospy's TCPROS servers bind 0.0.0.0 whatever ROS_IP says (the master's XML-RPC
server too); only loopback addresses are ever dialled.
"""

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import unittest
import xmlrpc.client

HERE = os.path.dirname(os.path.abspath(__file__))
NODELET = "/usr/lib/nodelet/nodelet"


def ros_missing():
    """Why ROS cannot run here (a sentence), or None when it can."""
    for program in ("rosmaster", "rosbag"):
        if shutil.which(program) is None:
            return f"{program} is not installed (Debian's ros-core / python3-rosbag; ./scripts/setup)"
    if not os.access(NODELET, os.X_OK):
        return f"{NODELET} is missing (Debian's libnodeletlib-tools)"
    if not os.path.exists("/usr/share/stereo_image_proc/nodelet_plugins.xml"):
        return "stereo_image_proc's nodelet XML is missing (libstereo-image-proc-dev)"
    try:
        import rospy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
        import stereo_msgs.msg  # noqa: F401
        import diagnostic_msgs.msg  # noqa: F401
        import numpy  # noqa: F401
        import cv2  # noqa: F401
    except ImportError as e:
        return f"a Python module is missing: {e} (python3-rospy, python3-sensor-msgs, ...)"
    return None


def nodelet_missing(package):
    """Why `package`'s nodelets (stereo_image_proc, depth_image_proc) cannot load, or None."""
    xml = f"/usr/share/{package}/nodelet_plugins.xml"
    if not os.path.exists(xml):
        dev = {"stereo_image_proc": "libstereo-image-proc-dev",
               "depth_image_proc": "libdepth-image-proc-dev"}.get(package, package)
        return f"{package}'s nodelet XML is missing ({dev}; ./scripts/setup)"
    return None


def parse_test_args():
    """The ROS tests' command line: (their arguments, what is left for unittest)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--ros-package-path", default="",
                    help="the build's ROS package folder (build/ros_package), for roslaunch")
    ap.add_argument("-k", "--keep", action="store_true", help="keep the scratch folder and logs")
    return ap.parse_known_args()


def skip_unless_ready(args, data_folder, nodelets=()):
    """Exits 77 (ctest: skipped), saying why, unless ROS, the `nodelets`' packages, the data
    (its `data_folder`) and the programs are there."""
    why = ros_missing()
    for package in nodelets:
        why = why or nodelet_missing(package)
    if why is None and not os.path.isdir(os.path.join(args.data, data_folder)):
        why = f"the New Tsukuba data is not at {args.data}"
    for binary in ("cloudcast-server", "cloudcast-ros-bridge"):
        if why is None and not os.access(os.path.join(args.bin_dir, binary), os.X_OK):
            why = f"{binary} is not built in {args.bin_dir}"
    if why is not None:
        print(f"SKIPPED: {why}")
        sys.exit(77)


def run_tests(unittest_args):
    """unittest.main on this script's tests; exits 1 on a failure, and 77 (skipped) when every
    test was skipped (saying the first reason)."""
    # rospy leaves sockets to the garbage collector: its ResourceWarnings are not ours.
    program = unittest.main(argv=[sys.argv[0]] + unittest_args, verbosity=2, warnings="ignore",
                            exit=False)
    result = program.result
    if not result.wasSuccessful():
        sys.exit(1)
    if result.skipped and len(result.skipped) >= result.testsRun:
        print(f"SKIPPED: {result.skipped[0][1]}")
        sys.exit(77)
    sys.exit(0)


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, timeout, what, step=0.05):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(step)
    raise TimeoutError(f"timed out after {timeout} s waiting for {what}")


class Process:
    """One child process, its output in `log_path`."""

    def __init__(self, name, argv, env, log_path):
        self.name, self.argv, self.log_path = name, argv, log_path
        self.log = open(log_path, "wb")
        self.popen = subprocess.Popen(argv, env=env, stdin=subprocess.DEVNULL, stdout=self.log,
                                      stderr=subprocess.STDOUT, start_new_session=True)

    @property
    def pid(self):
        return self.popen.pid

    def running(self):
        return self.popen.poll() is None

    def stop(self, grace=5.0):
        """SIGINT (ROS nodes shut down on it), then SIGKILL, to the process's own group (rosbag
        record runs its recorder as a child); returns the exit code."""
        if self.running():
            self._signal_group(signal.SIGINT)
            try:
                self.popen.wait(grace)
            except subprocess.TimeoutExpired:
                self._signal_group(signal.SIGKILL)
                self.popen.wait(5)
        # Children left in the group (the recorder finishing its bag) get the grace period too.
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and self._group_alive():
            time.sleep(0.05)
        if self._group_alive():
            self._signal_group(signal.SIGKILL)
        self.log.close()
        return self.popen.returncode

    def _signal_group(self, sig):
        try:
            os.killpg(self.popen.pid, sig)  # start_new_session: the group is the child's pid
        except ProcessLookupError:
            pass

    def _group_alive(self):
        try:
            os.killpg(self.popen.pid, 0)
            return True
        except ProcessLookupError:
            return False

    def output(self):
        if not self.log.closed:
            self.log.flush()
        with open(self.log_path, "rb") as f:
            return f.read().decode(errors="replace")

    def cpu_seconds(self):
        """User + system CPU time so far, from /proc (ticks of 1 / SC_CLK_TCK s)."""
        with open(f"/proc/{self.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        ticks = int(fields[11]) + int(fields[12])
        return ticks / os.sysconf("SC_CLK_TCK")


class Harness:
    """A scratch folder, a ROS master, and the processes started through it."""

    def __init__(self, bin_dir, keep=False):
        self.bin_dir = bin_dir
        self.keep = keep
        self.dir = tempfile.mkdtemp(prefix="cloudcast_ros_")
        self.processes = []
        self.master_port = free_port()
        self.env = dict(os.environ)
        self.env.update({
            "ROS_MASTER_URI": f"http://127.0.0.1:{self.master_port}",
            "ROS_IP": "127.0.0.1",
            "ROS_HOME": os.path.join(self.dir, "ros_home"),
            "ROS_LOG_DIR": os.path.join(self.dir, "ros_log"),
            "PYTHONUNBUFFERED": "1",
        })
        self.env.pop("ROS_HOSTNAME", None)
        self.env.pop("ROS_NAMESPACE", None)
        os.environ.update({k: self.env[k] for k in
                           ("ROS_MASTER_URI", "ROS_IP", "ROS_HOME", "ROS_LOG_DIR")})
        self.master = self.start("rosmaster", ["rosmaster", "--core", "-p", str(self.master_port),
                                               "-w", "4"])
        self.master_api = xmlrpc.client.ServerProxy(self.env["ROS_MASTER_URI"])
        wait_until(self._master_up, 20, "rosmaster")

    def _master_up(self):
        try:
            return self.master_api.getSystemState("/harness")[0] == 1
        except OSError:
            return False

    def path(self, name):
        return os.path.join(self.dir, name)

    def start(self, name, argv, extra_env=None):
        env = dict(self.env)
        env.update(extra_env or {})
        p = Process(name, argv, env, self.path(f"{name}.log"))
        self.processes.append(p)
        return p

    def set_params(self, namespace, params):
        for key, value in params.items():
            self.master_api.setParam("/harness", f"{namespace}/{key}", value)

    def wait_for_subscriber(self, topic, node, timeout=20):
        def subscribed():
            subscribers = dict(self.master_api.getSystemState("/harness")[2][1])
            return node in subscribers.get(topic, [])
        wait_until(subscribed, timeout, f"{node} to subscribe to {topic}")

    def start_server(self, extra=()):
        port = free_port()
        address = f"127.0.0.1:{port}"
        p = self.start("cloudcast-server", [os.path.join(self.bin_dir, "cloudcast-server"),
                                            "--listen", address, "--metrics-listen", "",
                                            "--log-level", "warn", *extra])
        def serving():
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", port)) == 0
        wait_until(serving, 20, "cloudcast-server")
        return address

    def bridge_command(self):
        """This build's bridge, or another build's (CLOUDCAST_ROS_BRIDGE: the arm64 cross build)
        under an emulator (CLOUDCAST_ROS_BRIDGE_EMULATOR: qemu-aarch64-static), as
        tests/arm64_client_test.cc runs these tests."""
        program = os.environ.get("CLOUDCAST_ROS_BRIDGE") or os.path.join(
            self.bin_dir, "cloudcast-ros-bridge")
        emulator = os.environ.get("CLOUDCAST_ROS_BRIDGE_EMULATOR")
        if not emulator:
            return [program]
        print(f"[ bridge ] {emulator} {program}", flush=True)  # what the arm64 test looks for
        return [emulator, program]

    def start_bridge(self, name, params, remaps, namespace="/stereo", log=None):
        """The bridge as node `namespace`/`name`, its private parameters set on the master first."""
        node = f"{namespace}/{name}"
        self.set_params(node, params)
        argv = self.bridge_command() + [f"__name:={name}", f"__ns:={namespace}"]
        argv += [f"{a}:={b}" for a, b in remaps.items()]
        return self.start(log or name, argv), node

    def start_nodelet(self, kind, name, namespace, params=None, remaps=None):
        """`kind` (e.g. depth_image_proc/point_cloud_xyzrgb) as a standalone nodelet, node
        `namespace`/`name`, its private parameters set first, its topics remapped by `remaps`."""
        node = f"{namespace}/{name}"
        self.set_params(node, params or {})
        argv = [NODELET, "standalone", kind, f"__name:={name}", f"__ns:={namespace}"]
        argv += [f"{a}:={b}" for a, b in (remaps or {}).items()]
        return self.start(name, argv), node

    def start_point_cloud2(self, name="point_cloud2", namespace="/stereo", params=None):
        return self.start_nodelet("stereo_image_proc/point_cloud2", name, namespace, params)

    def close(self):
        for p in reversed(self.processes):
            p.stop()
        self.processes.clear()
        if not self.keep:
            shutil.rmtree(self.dir, ignore_errors=True)

    def logs(self):
        return "\n".join(f"--- {p.name} ({' '.join(p.argv)}):\n{p.output()[-4000:]}"
                         for p in self.processes)
