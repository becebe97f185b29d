#!/usr/bin/env python3
"""cloudcast-ros-bridge against Debian's stock ROS nodelets, on one machine and the same messages:
the New Tsukuba publisher (ros/testing/tsukuba_publisher.py) sends the same frames to each
consumer in turn, alone on the harness's ROS master (127.0.0.1), and this program counts the
clouds that come out.

Per consumer and publishing rate: frames published, clouds out, clouds/s (first to last cloud),
latency (publish stamp to arrival here; medians), CPU per cloud of the consumer's processes (the
nodelets; the bridge + cloudcast-server, from /proc ticks of 10 ms), points per cloud (medians;
an organized cloud counted by its finite points; one cloud per frame of the 10, the first that
arrived) and, for stereo pairs, the bad-2.0 of the disparity maps (below). Inputs (--inputs) and their consumers:
  disparity  DisparityImage + colour + camera_info:
               stereo_image_proc point_cloud2 nodelet (organized, every pixel, no filter)
               bridge, no filters      passthrough and voxel grid off: the nodelet's points
               bridge, paper filters   passthrough z in [0.3, 8] m and a 3 cm voxel grid
  depth      16UC1 depth (mm) + colour + camera_info:
               depth_image_proc point_cloud_xyzrgb nodelet (organized, every pixel, no filter)
               bridge, no filters / paper filters, as above
  stereo     rectified left (bgr8) and right (mono8) images + both camera_infos:
               stereo_image_proc disparity + point_cloud2 nodelets (OpenCV StereoSGBM, 160
                 disparities, block 5, P1 200, P2 800, uniqueness 10, speckle 100 / 2,
                 disp12MaxDiff 1; the cloud organized, no filter)
               bridge, sgm, paper filters        the server's own SGM (160 disparities, the
                                                 rest the server's defaults)
               bridge, sgm, paper filters, disparity back
                                                 the same with ~stereo/publish_disparity
               bridge, sgbm, paper filters       OpenCV's StereoSGBM on the server, the
                                                 nodelet's settings
bad-2.0, as docs/stereo.md scores the matchers: of the pixels where the published DisparityImage
has a match (a valid disparity above 0) and the ground truth a value (> 0), the share more than
2 px from the ground truth + 1 (the New Tsukuba truth reads 1 px low); density: the share of
ground-truth pixels with a match; both means over the 10 frames (the first map of each that
arrived), "-" where no disparity is published.
The clouds and disparities are read here as raw bytes (rospy.AnyMsg), so that this process's own
cost is the same small one for every consumer.

  bridge_bench.py --bin-dir build/bin --data ../shared/data/new_tsukuba [--frames 100]
                  [--rates 10,20,30] [--inputs disparity,depth,stereo] [--json]
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
NO_FILTERS = {"passthrough/enabled": False, "voxel/enabled": False, "draco/position_bits": 16}
PAPER_FILTERS = {"passthrough/enabled": True, "passthrough/min": 0.3, "passthrough/max": 8.0,
                 "voxel/enabled": True, "voxel/leaf": 0.03}
# stereo_image_proc's disparity nodelet (dynamic_reconfigure names), as OpenCV StereoSGBM.
SGBM_NODELET = {"stereo_algorithm": 1, "correlation_window_size": 5, "min_disparity": 0,
                "disparity_range": 160, "P1": 200, "P2": 800, "uniqueness_ratio": 10,
                "speckle_size": 100, "speckle_range": 2, "disp12MaxDiff": 1, "fullDP": False}
SGBM_BRIDGE = {"stereo/matcher": "sgbm", "stereo/num_disparities": 160, "stereo/block_size": 5,
               "stereo/p1": 200, "stereo/p2": 800, "stereo/uniqueness_ratio": 10,
               "stereo/speckle_window_size": 100, "stereo/speckle_range": 2,
               "stereo/disp12_max_diff": 1}
SGM_BRIDGE = {"stereo/matcher": "sgm", "stereo/num_disparities": 160}


class Stock:
    """The stock consumer of an input: its nodelets (kind, name, params, remaps), the cloud topic
    and the DisparityImage topic it publishes (or None)."""

    def __init__(self, label, nodelets, output, disparity=None):
        self.label, self.nodelets, self.output, self.disparity = label, nodelets, output, disparity


class Suite:
    """One input kind: what the publisher sends (--kind), under which namespace, the topics it
    waits for, the stock consumer and the bridge rows (label, parameters)."""

    def __init__(self, name, kind, namespace, topics, stock, bridges):
        self.name, self.kind, self.namespace, self.topics = name, kind, namespace, topics
        self.stock, self.bridges = stock, bridges

    def consumers(self):
        return [(self.stock.label, None)] + [(label, dict(params, input=self.name))
                                             for label, params in self.bridges]


SUITES = {
    "disparity": Suite(
        "disparity", "disparity", "/stereo",
        ["disparity", "left/image_rect_color", "left/camera_info"],
        Stock("stereo_image_proc point_cloud2",
              [("stereo_image_proc/point_cloud2", "point_cloud2", {}, {})], "/stereo/points2"),
        [("bridge, no filters", NO_FILTERS), ("bridge, paper filters", PAPER_FILTERS)]),
    "depth": Suite(
        "depth", "depth16", "/camera",
        ["depth_registered/image_rect", "rgb/image_rect_color", "rgb/camera_info"],
        Stock("depth_image_proc point_cloud_xyzrgb",
              [("depth_image_proc/point_cloud_xyzrgb", "point_cloud_xyzrgb",
                {"exact_sync": True}, {})], "/camera/depth_registered/points"),
        [("bridge, no filters", NO_FILTERS), ("bridge, paper filters", PAPER_FILTERS)]),
    "stereo": Suite(
        "stereo", "stereo", "/stereo",
        ["left/image_rect_color", "right/image_rect", "left/camera_info", "right/camera_info"],
        Stock("stereo_image_proc disparity + point_cloud2",
              [("stereo_image_proc/disparity", "disparity", SGBM_NODELET,
                {"left/image_rect": "left/image_rect_color"}),
               ("stereo_image_proc/point_cloud2", "point_cloud2", {}, {})],
              "/stereo/points2", "/stereo/disparity"),
        [("bridge, sgm, paper filters", dict(PAPER_FILTERS, **SGM_BRIDGE)),
         ("bridge, sgm, paper filters, disparity back",
          dict(PAPER_FILTERS, **SGM_BRIDGE, **{"stereo/publish_disparity": True})),
         ("bridge, sgbm, paper filters", dict(PAPER_FILTERS, **SGBM_BRIDGE))]),
}


def parse_header(buf):
    """Stamp (ns) of a serialized message that starts with a std_msgs/Header, and the offset
    after the header."""
    _seq, secs, nsecs, id_len = struct.unpack_from("<IIII", buf, 0)
    return secs * 1_000_000_000 + nsecs, 16 + id_len


def parse_cloud_header(buf):
    """Stamp (ns), height, width and point_step of a serialized PointCloud2."""
    stamp, off = parse_header(buf)
    height, width = struct.unpack_from("<II", buf, off)
    off += 8
    (n_fields,) = struct.unpack_from("<I", buf, off)
    off += 4
    for _ in range(n_fields):
        (name_len,) = struct.unpack_from("<I", buf, off)
        off += 4 + name_len + 4 + 1 + 4  # name, offset, datatype, count
    off += 1  # is_bigendian
    point_step, _row_step = struct.unpack_from("<II", buf, off)
    return stamp, height, width, point_step


def finite_points(buf):
    from sensor_msgs.msg import PointCloud2
    import numpy as np
    msg = PointCloud2()
    msg.deserialize(buf)
    offsets = {f.name: f.offset for f in msg.fields}
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
    z = raw[:, offsets["z"]:offsets["z"] + 4].copy().view("<f4").ravel()
    return int(np.isfinite(z).sum())


def bad_2(buf, gt):
    """bad-2.0 and density (see the module's help) of a serialized DisparityImage."""
    from stereo_msgs.msg import DisparityImage
    import numpy as np
    msg = DisparityImage()
    msg.deserialize(buf)
    d = np.frombuffer(bytes(msg.image.data), dtype="<f4").reshape(msg.image.height,
                                                                 msg.image.width)
    scored = (d >= msg.min_disparity) & (d > 0) & (gt > 0)
    wrong = np.abs(d - (gt + 1.0)) > 2.0
    return (float((wrong & scored).sum()) / float(scored.sum()),
            float(scored.sum()) / float((gt > 0).sum()))


class Counter:
    """Raw messages of one topic: (arrival ns, stamp ns, bytes) each, and the first whole message
    of each frame (the publisher's --stamp-now puts the frame's index in the stamp's last three
    nanosecond digits), so that points and bad-2.0 are scored once per frame even when a consumer
    drops some."""

    def __init__(self, topic):
        import rospy
        self.lock = threading.Lock()
        self.arrivals = []
        self.samples = {}  # frame index -> serialized message
        self.sub = rospy.Subscriber(topic, rospy.AnyMsg, self._cb, queue_size=100)

    def _cb(self, msg):
        now = time.time_ns()
        buf = msg._buff
        stamp, _ = parse_header(buf)
        index = stamp % 1000
        with self.lock:
            self.arrivals.append((now, stamp, len(buf)))
            if index < len(FRAMES) and index not in self.samples:
                self.samples[index] = bytes(buf)


def start_consumer(h, suite, case, bridge_params):
    """The consumer's processes, the node to wait for, its cloud and disparity topics."""
    if bridge_params is None:
        processes, node = [], None
        for kind, name, params, remaps in suite.stock.nodelets:
            p, n = h.start_nodelet(kind, f"{name}_{case}", suite.namespace, params, remaps)
            processes.append(p)
            node = node or n
        return processes, node, suite.stock.output, suite.stock.disparity
    server = h.start_server()
    processes = [h.processes[-1]]
    params = dict(bridge_params, server=server, delivery="latest")
    disparity = (f"/cloudcast/disparity_{case}" if params.get("stereo/publish_disparity")
                 else None)
    remaps = {"points2": f"/cloudcast/points2_{case}"}
    if disparity:
        remaps["disparity"] = disparity
    p, node = h.start_bridge(f"bridge_{case}", params, remaps, namespace=suite.namespace)
    processes.append(p)
    return processes, node, f"/cloudcast/points2_{case}", disparity


def run_case(args, h, suite, case, name, bridge_params, rate):
    """One consumer at one rate, on the harness's master; the consumer is stopped afterwards."""
    import cv2
    processes, node, topic, disparity_topic = start_consumer(h, suite, case, bridge_params)
    try:
        counter = Counter(topic)
        disparities = Counter(disparity_topic) if disparity_topic else None
        # The nodelets subscribe to their inputs once their output has a subscriber.
        h.wait_for_subscriber(f"{suite.namespace}/{suite.topics[0]}", node)
        # Our own subscriptions must be connected too, or the first clouds go nowhere.
        for c in [counter] + ([disparities] if disparities else []):
            ros_harness.wait_until(lambda: c.sub.get_num_connections() > 0, 20,
                                   f"a connection to {c.sub.resolved_name}")
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
        # "published K NAME NS": the rate the publisher achieved.
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
        if disparities:
            disparities.sub.unregister()
        with counter.lock:
            arrivals = list(counter.arrivals)
            samples = dict(counter.samples)
        if not arrivals:
            raise RuntimeError(f"{name}: no cloud arrived\n{h.logs()}")
        span_s = (arrivals[-1][0] - arrivals[0][0]) / 1e9
        latencies = [(a - s) / 1e6 for a, s, _ in arrivals]
        points = []
        for b in samples.values():
            _, height, width, _ = parse_cloud_header(b)
            points.append(finite_points(b) if height > 1 else width)
        bad = density = None
        scored = 0
        if disparities:
            with disparities.lock:
                maps = dict(disparities.samples)
            scores = []
            for index, b in sorted(maps.items()):
                gt = cv2.imread(f"{args.data}/groundtruth/disparity_maps/left/"
                                f"tsukuba_disparity_L_{FRAMES[index]}.png",
                                cv2.IMREAD_UNCHANGED).astype("float32")
                scores.append(bad_2(b, gt))
            scored = len(scores)
            if scores:
                bad = statistics.mean(b for b, _ in scores)
                density = statistics.mean(d for _, d in scores)
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
            "frames_with_points": len(points),
            "cloud_bytes_median": statistics.median(b for _, _, b in arrivals),
            "bad_2_vs_gt_plus_1": bad,
            "disparity_density": density,
            "frames_scored": scored,
        }
    finally:
        for q in processes:
            q.stop()


def print_table(rows):
    """The rows as a Markdown table (docs/ros.md)."""
    head = ("| input | consumer | publisher rate | published | clouds | clouds/s | "
            "latency ms (median) | CPU ms / cloud | CPU vs stock | points (median) | "
            "cloud bytes (median) | bad-2.0 (GT+1) | density |")
    print(head)
    print("|" + " --- |" * 13)
    for r in rows:
        rate = (f"max ({r['published_hz']:.0f} Hz)" if r["rate_hz"] == 0
                else f"{r['rate_hz']:g} Hz")
        bad = "-" if r["bad_2_vs_gt_plus_1"] is None else f"{100 * r['bad_2_vs_gt_plus_1']:.1f} %"
        if r["bad_2_vs_gt_plus_1"] is not None and r.get("frames_scored", 10) < len(FRAMES):
            bad += f" ({r['frames_scored']} of {len(FRAMES)} frames)"
        density = ("-" if r["disparity_density"] is None
                   else f"{100 * r['disparity_density']:.1f} %")
        print(f"| {r['input']} | {r['consumer']} | {rate} | {r['published']} | {r['clouds']} | "
              f"{r['clouds_per_s']:.1f} | {r['latency_ms_median']:.1f} | "
              f"{r['cpu_ms_per_cloud']:.1f} | {r['cpu_ratio_vs_nodelet']:.2f}x | "
              f"{r['points_median']:,.0f} | {r['cloud_bytes_median']:,.0f} | {bad} | "
              f"{density} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--frames", type=int, default=100, help="frames per case (whole cycles of 10)")
    ap.add_argument("--rates", default="10,20,30",
                    help="publishing rates, Hz (0: as fast as rospy can, whose publisher queues "
                         "then drop most frames)")
    ap.add_argument("--inputs", default="disparity,depth,stereo",
                    help=f"comma-separated input kinds, of {', '.join(SUITES)}")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    ap.add_argument("--table-from", metavar="JSON",
                    help="print the table of an earlier --json run and exit")
    args = ap.parse_args()
    if args.table_from:
        with open(args.table_from) as f:
            print_table(json.load(f)["rows"])
        return
    suites = []
    for name in args.inputs.split(","):
        if name not in SUITES:
            sys.exit(f"bridge_bench: --inputs {args.inputs}: '{name}' is not one of "
                     f"{', '.join(SUITES)}")
        suites.append(SUITES[name])
    why = ros_harness.ros_missing()
    for suite in suites:
        for kind, _, _, _ in suite.stock.nodelets:
            why = why or ros_harness.nodelet_missing(kind.split("/")[0])
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
    # Ratios against the stock consumer of the same input at the same rate (its row comes first).
    for r in rows:
        ref = next(x for x in rows if x["rate_hz"] == r["rate_hz"] and x["input"] == r["input"])
        r["cpu_ratio_vs_nodelet"] = r["cpu_ms_per_cloud"] / ref["cpu_ms_per_cloud"]
    if args.json:
        print(json.dumps({"frames": args.frames, "rows": rows}, indent=2))
        return
    print_table(rows)


if __name__ == "__main__":
    main()
