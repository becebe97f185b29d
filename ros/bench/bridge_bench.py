#!/usr/bin/env python3
"""cloudcast-ros-bridge against Debian's stock ROS nodelets, on one machine and the same messages:
the New Tsukuba publisher (ros/testing/tsukuba_publisher.py) sends the same frames to each
consumer in turn, alone on the harness's ROS master (127.0.0.1), and this program counts the
clouds that come out.

Per consumer and publishing rate: frames published, clouds out, clouds/s (first to last cloud),
latency (publish stamp to arrival here; medians), CPU per cloud of the consumer's processes (the
nodelet; the bridge + cloudcast-server, from /proc ticks of 10 ms) and points per cloud (medians;
an organized cloud counted by its finite points). Inputs (--inputs) and their consumers:
  disparity  DisparityImage + colour + camera_info:
               stereo_image_proc point_cloud2 nodelet (organized, every pixel, no filter)
  depth      16UC1 depth (mm) + colour + camera_info:
               depth_image_proc point_cloud_xyzrgb nodelet (organized, every pixel, no filter)
and for each the bridge (~input disparity / depth) twice:
  bridge, no filters    passthrough and voxel grid off: the nodelet's points, via the server
  bridge, paper filters passthrough z in [0.3, 8] m and a 3 cm voxel grid (Tsukuba in metres)
The clouds are read here as raw bytes (rospy.AnyMsg), so that this process's own cost is the
same small one for every consumer.

  bridge_bench.py --bin-dir build/bin --data ../shared/data/new_tsukuba [--frames 100]
                  [--rates 10,20,30] [--inputs disparity,depth] [--json]
Rate 0 publishes as fast as the publisher can (the consumers' subscriber queues then drop what
they cannot keep up with).
"""

import argparse
import json
import os
import statistics
import struct
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
import ros_harness  # noqa: E402

FRAMES = ["00001", "00200", "00400", "00600", "00800", "01000", "01200", "01400", "01600",
          "01800"]
BRIDGES = [
    ("bridge, no filters", {"passthrough/enabled": False, "voxel/enabled": False,
                            "draco/position_bits": 16}),
    ("bridge, paper filters", {"passthrough/enabled": True, "passthrough/min": 0.3,
                               "passthrough/max": 8.0, "voxel/enabled": True, "voxel/leaf": 0.03}),
]


class Suite:
    """One input kind: what the publisher sends, where, and the stock nodelet that consumes it."""

    def __init__(self, name, kind, namespace, topics, nodelet, nodelet_name, nodelet_params,
                 nodelet_output):
        self.name, self.kind, self.namespace, self.topics = name, kind, namespace, topics
        self.nodelet, self.nodelet_name, self.nodelet_params = nodelet, nodelet_name, nodelet_params
        self.nodelet_output = nodelet_output

    def consumers(self):
        stock = self.nodelet.replace("/", " ")
        return [(stock, None)] + [(name, dict(params, input=self.name))
                                  for name, params in BRIDGES]


SUITES = {
    "disparity": Suite("disparity", "disparity", "/stereo",
                       ["disparity", "left/image_rect_color", "left/camera_info"],
                       "stereo_image_proc/point_cloud2", "point_cloud2", {}, "/stereo/points2"),
    "depth": Suite("depth", "depth16", "/camera",
                   ["depth_registered/image_rect", "rgb/image_rect_color", "rgb/camera_info"],
                   "depth_image_proc/point_cloud_xyzrgb", "point_cloud_xyzrgb",
                   {"exact_sync": True}, "/camera/depth_registered/points"),
}


def parse_cloud_header(buf):
    """Stamp (ns), height, width and point_step of a serialized PointCloud2."""
    _seq, secs, nsecs, id_len = struct.unpack_from("<IIII", buf, 0)
    off = 16 + id_len
    height, width = struct.unpack_from("<II", buf, off)
    off += 8
    (n_fields,) = struct.unpack_from("<I", buf, off)
    off += 4
    for _ in range(n_fields):
        (name_len,) = struct.unpack_from("<I", buf, off)
        off += 4 + name_len + 4 + 1 + 4  # name, offset, datatype, count
    off += 1  # is_bigendian
    point_step, _row_step = struct.unpack_from("<II", buf, off)
    return secs * 1_000_000_000 + nsecs, height, width, point_step


def finite_points(buf, count_limit=None):
    from sensor_msgs.msg import PointCloud2
    import numpy as np
    msg = PointCloud2()
    msg.deserialize(buf)
    offsets = {f.name: f.offset for f in msg.fields}
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
    z = raw[:, offsets["z"]:offsets["z"] + 4].copy().view("<f4").ravel()
    return int(np.isfinite(z).sum())


class CloudCounter:
    def __init__(self, topic):
        import rospy
        self.lock = threading.Lock()
        self.arrivals = []  # (arrival ns, stamp ns, points, bytes)
        self.samples = []   # a few raw clouds, for their finite points
        self.sub = rospy.Subscriber(topic, rospy.AnyMsg, self._cb, queue_size=100)

    def _cb(self, msg):
        now = time.time_ns()
        buf = msg._buff
        stamp, h, w, _step = parse_cloud_header(buf)
        with self.lock:
            self.arrivals.append((now, stamp, h * w, len(buf)))
            if len(self.samples) < len(FRAMES):
                self.samples.append(bytes(buf))


def run_case(args, h, suite, case, name, bridge_params, rate):
    """One consumer at one rate, on the harness's master; the consumer is stopped afterwards."""
    processes = []
    if bridge_params is None:
        p, node = h.start_nodelet(suite.nodelet, f"{suite.nodelet_name}_{case}", suite.namespace,
                                  suite.nodelet_params)
        processes.append(p)
        topic = suite.nodelet_output
    else:
        server = h.start_server()
        processes.append(h.processes[-1])
        params = dict(bridge_params, server=server, delivery="latest")
        p, node = h.start_bridge(f"bridge_{case}", params, {"points2": f"/cloudcast/points2_{case}"},
                                 namespace=suite.namespace)
        processes.append(p)
        topic = f"/cloudcast/points2_{case}"
    try:
        counter = CloudCounter(topic)
        h.wait_for_subscriber(f"{suite.namespace}/{suite.topics[0]}", node)
        # Our own subscription must be connected too, or the first clouds go nowhere.
        ros_harness.wait_until(lambda: counter.sub.get_num_connections() > 0, 20,
                               f"a connection to {topic}")
        cpu_before = sum(q.cpu_seconds() for q in processes)
        n = args.frames
        repeat = max(1, n // len(FRAMES))
        waits = [f"{t}=1" for t in suite.topics]
        pub = h.start(f"publisher_{case}", [sys.executable, os.path.join(ros_harness.HERE,
                                                                "tsukuba_publisher.py"),
                                    "--data", args.data, "--frames", ",".join(FRAMES),
                                    "--kind", suite.kind, "--repeat", str(repeat),
                                    "--rate", str(rate), "--stamp-now"]
                      + [a for w in waits for a in ("--wait", w)])
        pub.popen.wait(600)
        published = repeat * len(FRAMES)
        # The rate the publisher achieved: its first and last stamps ("published K NAME NS").
        sent = [int(line.split()[3]) for line in pub.output().splitlines()
                if line.startswith("published ")]
        publish_hz = ((len(sent) - 1) / ((sent[-1] - sent[0]) / 1e9)
                      if len(sent) > 1 and sent[-1] > sent[0] else 0.0)
        # The last clouds: until nothing arrived for a second (bounded).
        deadline = time.monotonic() + 30
        last = -1
        while time.monotonic() < deadline:
            with counter.lock:
                count = len(counter.arrivals)
            if count == last:
                break
            last = count
            time.sleep(1.0)
        cpu = sum(q.cpu_seconds() for q in processes) - cpu_before
        counter.sub.unregister()
        with counter.lock:
            arrivals = list(counter.arrivals)
            samples = list(counter.samples)
        if not arrivals:
            raise RuntimeError(f"{name}: no cloud arrived\n{h.logs()}")
        span_s = (arrivals[-1][0] - arrivals[0][0]) / 1e9
        latencies = [(a - s) / 1e6 for a, s, _, _ in arrivals]
        points = ([finite_points(b) for b in samples] if bridge_params is None
                  else [p for _, _, p, _ in arrivals])
        return {
            "input": suite.name,
            "consumer": name,
            "rate_hz": rate,
            "published": published,
            "published_hz": publish_hz,
            "clouds": len(arrivals),
            "clouds_per_s": (len(arrivals) - 1) / span_s if span_s > 0 else 0.0,
            "latency_ms_median": statistics.median(latencies),
            "cpu_ms_per_cloud": 1000.0 * cpu / len(arrivals),
            "points_median": statistics.median(points),
            "cloud_bytes_median": statistics.median(b for _, _, _, b in arrivals),
        }
    finally:
        for q in processes:
            q.stop()


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--frames", type=int, default=100, help="frames per case (whole cycles of 10)")
    ap.add_argument("--rates", default="10,20,30",
                    help="publishing rates, Hz (0: as fast as rospy can, whose publisher queues "
                         "then drop most frames)")
    ap.add_argument("--inputs", default="disparity,depth",
                    help=f"comma-separated input kinds, of {', '.join(SUITES)}")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    suites = []
    for name in args.inputs.split(","):
        if name not in SUITES:
            sys.exit(f"bridge_bench: --inputs {args.inputs}: '{name}' is not one of "
                     f"{', '.join(SUITES)}")
        suites.append(SUITES[name])
    why = ros_harness.ros_missing()
    for suite in suites:
        why = why or ros_harness.nodelet_missing(suite.nodelet.split("/")[0])
    if why:
        sys.exit(f"bridge_bench: {why}")
    import rospy
    rows = []
    h = ros_harness.Harness(args.bin_dir)
    try:
        rospy.init_node("bridge_bench", disable_signals=True)
        for suite in suites:
            for rate in [float(r) for r in args.rates.split(",")]:
                for name, params in suite.consumers():
                    rows.append(run_case(args, h, suite, len(rows), name, params, rate))
                    print(f"  {suite.name}: {name} at {rate:g} Hz: done", file=sys.stderr)
    finally:
        rospy.signal_shutdown("bench done")
        h.close()
    # Ratios against the stock nodelet of the same input at the same rate (its row comes first).
    for r in rows:
        ref = next(x for x in rows if x["rate_hz"] == r["rate_hz"] and x["input"] == r["input"])
        r["cpu_ratio_vs_nodelet"] = r["cpu_ms_per_cloud"] / ref["cpu_ms_per_cloud"]
    if args.json:
        print(json.dumps({"frames": args.frames, "rows": rows}, indent=2))
        return
    head = ("| input | consumer | publisher rate | published | clouds | clouds/s | "
            "latency ms (median) | CPU ms / cloud | CPU vs nodelet | points (median) | "
            "cloud bytes (median) |")
    print(head)
    print("|" + " --- |" * 11)
    for r in rows:
        rate = (f"max ({r['published_hz']:.0f} Hz)" if r["rate_hz"] == 0
                else f"{r['rate_hz']:g} Hz")
        print(f"| {r['input']} | {r['consumer']} | {rate} | {r['published']} | {r['clouds']} | "
              f"{r['clouds_per_s']:.1f} | {r['latency_ms_median']:.1f} | "
              f"{r['cpu_ms_per_cloud']:.1f} | {r['cpu_ratio_vs_nodelet']:.2f}x | "
              f"{r['points_median']:,.0f} | {r['cloud_bytes_median']:,.0f} |")


if __name__ == "__main__":
    main()
