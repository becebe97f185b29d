#!/usr/bin/env python3
"""cloudcast-ros-bridge with ~input depth against a real ROS master and Debian's
depth_image_proc.

Everything runs on 127.0.0.1, started here: rosmaster on a free port, a cloudcast-server, two
bridges in /camera (metres, publishing /cloudcast/depth_points, and ~depth_scale 1 on
millimetres, publishing /cloudcast/depth_points_mm), depth_image_proc's point_cloud_xyzrgb
nodelet (/camera/point_cloud_xyzrgb, publishing /camera/depth_registered/points) and the New
Tsukuba publisher (ros/testing/tsukuba_publisher.py --kind depth16 / depth32: the ground truth
as depth z = f B / d, f = 615, B = 0.1 m). This process subscribes to the clouds and to
/diagnostics with rospy.

Exit 77 (ctest: skipped) when ROS, depth_image_proc or the data are missing.

  ros_depth_test.py --bin-dir build/bin --data ../shared/data/new_tsukuba [-k] [unittest args]
"""

import os
import subprocess
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
import ros_harness  # noqa: E402
from ros_clouds import (Collector, cloud_arrays, diag_values, replay_to_own_bridge,  # noqa: E402
                        stamp_ns)

ARGS = None
# 00001 and 01200 have no ground-truth zero; 00600 and 01400 have 447 and 645 (no measurement).
FRAMES = ["00001", "00600", "01200", "01400"]
BRIDGE_PARAMS = {
    "input": "depth",
    "delivery": "all",
    "passthrough/enabled": False,
    "voxel/enabled": False,
    # Draco keeps the point order at speed 10 (sequential coding); 20 bits put the position error
    # bound at a few micrometres on these clouds.
    "draco/position_bits": 20,
    "draco/encode_speed": 10,
    "draco/decode_speed": 10,
    "diagnostics_period": 0.5,
}
DEPTH_TOPICS = ["/camera/depth_registered/image_rect", "/camera/rgb/image_rect_color",
                "/camera/rgb/camera_info"]


def published_depth(frame, kind):
    """The depth image tsukuba_publisher.py sends for `frame` (its own function)."""
    import cv2
    import tsukuba_publisher
    d = cv2.imread(f"{ARGS.data}/groundtruth/disparity_maps/left/"
                   f"tsukuba_disparity_L_{frame}.png", cv2.IMREAD_UNCHANGED)
    return tsukuba_publisher.depth_from_disparity(d, kind)


class RosDepthTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import PointCloud2
        cls.h = ros_harness.Harness(ARGS.bin_dir, keep=ARGS.keep)
        try:
            cls.server = cls.h.start_server()
            _, cls.bridge_node = cls.h.start_bridge(
                "cloudcast_depth", dict(BRIDGE_PARAMS, server=cls.server),
                {"points2": "/cloudcast/depth_points"}, namespace="/camera")
            _, cls.mm_node = cls.h.start_bridge(
                "cloudcast_depth_mm", dict(BRIDGE_PARAMS, server=cls.server, depth_scale=1.0),
                {"points2": "/cloudcast/depth_points_mm"}, namespace="/camera")
            _, cls.nodelet_node = cls.h.start_nodelet(
                "depth_image_proc/point_cloud_xyzrgb", "point_cloud_xyzrgb", "/camera",
                {"exact_sync": True, "queue_size": 10})
            rospy.init_node("ros_depth_test", disable_signals=True)
            cls.bridge_clouds = Collector("/cloudcast/depth_points", PointCloud2)
            cls.mm_clouds = Collector("/cloudcast/depth_points_mm", PointCloud2)
            cls.nodelet_clouds = Collector("/camera/depth_registered/points", PointCloud2)
            cls.diagnostics = Collector("/diagnostics", DiagnosticArray)
            # The nodelet subscribes to its inputs only once its output has a subscriber.
            for node in (cls.bridge_node, cls.mm_node, cls.nodelet_node):
                cls.h.wait_for_subscriber(DEPTH_TOPICS[0], node)
        except Exception:
            print(cls.h.logs(), file=sys.stderr)
            cls.h.close()
            raise

    @classmethod
    def tearDownClass(cls):
        import rospy
        rospy.signal_shutdown("test done")
        cls.h.close()

    def publish(self, kind, frames, stamp_base, subscribers=3):
        """Publishes once `subscribers` are connected to each input topic (both bridges and the
        nodelet, by default)."""
        waits = [f"{t[len('/camera/'):]}={subscribers}" for t in DEPTH_TOPICS]
        p = self.h.start(f"publisher_{stamp_base}",
                         [sys.executable, os.path.join(ros_harness.HERE, "tsukuba_publisher.py"),
                          "--data", ARGS.data, "--kind", kind, "--frames", ",".join(frames),
                          "--rate", "10", "--stamp-base", str(stamp_base)]
                         + [a for w in waits for a in ("--wait", w)])
        try:
            p.popen.wait(60)
        except subprocess.TimeoutExpired:
            self.fail("the publisher did not finish in 60 s:\n" + self.h.logs())
        self.assertEqual(p.popen.returncode, 0, p.output())

    def publish_frame_by_frame(self, kind, stamp_base, collectors):
        """Publishes FRAMES one at a time, each once every Collector in `collectors` (by what
        publishes to it, for the failure message) has the cloud of the one before; returns the
        stamps.

        depth_image_proc's nodelet subscribes to its three inputs with queues of one message and
        publishes with a queue of one: when it or this test falls behind (a loaded machine), a
        newer frame replaces one not taken yet, and that frame's cloud never comes (seen: "have
        1000, 1001, 1003"). These tests compare outputs, not rates, so the next frame waits for
        the last one's clouds. Our bridges must still answer every frame they are sent, each
        cloud is still compared point for point, and a frame a bridge loses fails here, naming
        the bridge."""
        stamps = [stamp_ns(stamp_base, k) for k in range(len(FRAMES))]
        for k, frame in enumerate(FRAMES):
            self.publish(kind, [frame], stamp_base + k)  # stamped stamp_ns(base + k, 0)
            for what, collector in collectors.items():
                try:
                    collector.wait_for(stamps[k:k + 1], 30)
                except TimeoutError as e:
                    self.fail(f"{what} never published frame {frame} ({kind}, stamp "
                              f"{stamps[k]}): {e}\n{self.h.logs()}")
        return stamps

    def error_bound(self, node, clouds):
        ros_harness.wait_until(
            lambda: any(int(v.get("clouds", 0)) >= clouds for v in diag_values(self.diagnostics,
                                                                                node)),
            10, f"diagnostics of {node} counting {clouds} clouds")
        bound = max(float(v["position_error_bound"]) for v in diag_values(self.diagnostics, node))
        self.assertGreater(bound, 0)
        return bound

    def compare(self, kind, frame, mine, ref, bound):
        """`mine` (the bridge's unorganized cloud) against `ref` (the nodelet's organized one):
        the same points in pixel order within `bound`, the same colours; returns the largest
        difference."""
        import numpy as np
        self.assertEqual(mine.header.frame_id, "tsukuba_left_optical")
        self.assertEqual(mine.header.frame_id, ref.header.frame_id)
        self.assertEqual(mine.header.stamp, ref.header.stamp)
        self.assertEqual(mine.height, 1)
        self.assertTrue(mine.is_dense)
        self.assertEqual((ref.height, ref.width), (480, 640))
        depth = published_depth(frame, kind)
        xyz, rgb = cloud_arrays(mine)
        ref_xyz, ref_rgb = cloud_arrays(ref)
        ref_xyz = ref_xyz.reshape(480, 640, 3)
        ref_rgb = ref_rgb.reshape(480, 640)
        # depth_image_proc's rule: 16UC1 0 is no measurement; 32FC1 only non-finite values are.
        ref_finite = np.isfinite(ref_xyz[..., 2])
        if kind == "depth16":
            self.assertTrue(np.array_equal(ref_finite, depth != 0))
            keep = depth != 0
        else:
            self.assertTrue(np.array_equal(ref_finite, np.isfinite(depth)))
            # The one difference: a 32FC1 0.0 is a point at the origin for depth_image_proc and
            # no point for cloudcast (REP 118: no reading). The publisher puts 100 of them in.
            zero = depth == 0
            self.assertEqual(int(zero.sum()), 100)
            self.assertTrue(np.all(ref_xyz[zero] == 0))
            keep = np.isfinite(depth) & ~zero
        self.assertEqual(len(xyz), int(keep.sum()))
        diff = float(np.abs(xyz - ref_xyz[keep]).max())
        self.assertLessEqual(diff, bound, f"frame {frame}: {diff} > bound {bound}")
        self.assertTrue(np.array_equal(rgb & 0xFFFFFF, ref_rgb[keep] & 0xFFFFFF))
        return diff

    def test_1_16uc1_millimetres_equal_depth_image_proc(self):
        import numpy as np
        base = 1000
        stamps = self.publish_frame_by_frame("depth16", base, {
            "the bridge (metres)": self.bridge_clouds,
            "the bridge (millimetres)": self.mm_clouds,
            "depth_image_proc's nodelet": self.nodelet_clouds})
        ours = self.bridge_clouds.wait_for(stamps, 1)
        theirs = self.nodelet_clouds.wait_for(stamps, 1)
        in_mm = self.mm_clouds.wait_for(stamps, 1)
        bound = self.error_bound(self.bridge_node, len(FRAMES))
        self.assertLess(bound, 1e-4)
        bound_mm = self.error_bound(self.mm_node, len(FRAMES))
        for frame, mine, ref, mm in zip(FRAMES, ours, theirs, in_mm):
            with self.subTest(frame=frame):
                diff = self.compare("depth16", frame, mine, ref, bound)
                print(f"depth16 {frame}: {mine.width} points, largest difference {diff:.3g} "
                      f"(bound {bound:.3g})", file=sys.stderr)
                # ~depth_scale 1: the same cloud in millimetres.
                xyz, _ = cloud_arrays(mine)
                xyz_mm, _ = cloud_arrays(mm)
                self.assertEqual(len(xyz_mm), len(xyz))
                # Both clouds' Draco errors, the second's scaled back, and float rounding.
                tolerance = 1000 * bound + bound_mm + 1e-3
                self.assertLessEqual(float(np.abs(xyz_mm - 1000 * xyz).max()), tolerance)
        v = diag_values(self.diagnostics, self.bridge_node)[-1]
        self.assertEqual(v["frame_errors"], "0")
        self.assertEqual(v["input_errors"], "0")

    def test_2_32fc1_metres_with_holes_equal_depth_image_proc(self):
        base = 2000
        before = max(int(v["clouds"]) for v in diag_values(self.diagnostics, self.bridge_node))
        stamps = self.publish_frame_by_frame("depth32", base, {
            "the bridge (metres)": self.bridge_clouds,
            "depth_image_proc's nodelet": self.nodelet_clouds})
        ours = self.bridge_clouds.wait_for(stamps, 1)
        theirs = self.nodelet_clouds.wait_for(stamps, 1)
        bound = self.error_bound(self.bridge_node, before + len(FRAMES))
        for frame, mine, ref in zip(FRAMES, ours, theirs):
            with self.subTest(frame=frame):
                diff = self.compare("depth32", frame, mine, ref, bound)
                print(f"depth32 {frame}: {mine.width} points, largest difference {diff:.3g} "
                      f"(bound {bound:.3g})", file=sys.stderr)

    def test_3_rosbag_plays_back_through_the_bridge(self):
        import numpy as np
        base = 3000
        bag = self.h.path("tsukuba_depth.bag")
        recorder = self.h.start("rosbag_record", ["rosbag", "record", "-O", bag,
                                                  "__name:=recorder"] + DEPTH_TOPICS)
        for t in DEPTH_TOPICS:
            self.h.wait_for_subscriber(t, "/recorder")
        self.publish("depth16", FRAMES, base, subscribers=4)
        stamps = [stamp_ns(base, k) for k in range(len(FRAMES))]
        live = self.bridge_clouds.wait_for(stamps, 30)
        recorder.stop()
        ros_harness.wait_until(lambda: os.path.exists(bag), 10, "rosbag record to close " + bag)
        # Played back under /replay to a bridge of its own with the same parameters
        # (ros_clouds.replay_to_own_bridge says why).
        try:
            played = replay_to_own_bridge(
                self.h, bag, DEPTH_TOPICS, "/camera/", dict(BRIDGE_PARAMS, server=self.server),
                "/cloudcast/replayed_depth_points", stamps)
        except TimeoutError as e:
            self.fail(f"the bridge did not answer every frame played back: {e}\n"
                      + self.h.logs())
        for frame, a, b in zip(FRAMES, live, played):
            with self.subTest(frame=frame):
                self.assertEqual(a.header.stamp, b.header.stamp)
                self.assertEqual(a.header.frame_id, b.header.frame_id)
                xa, ca = cloud_arrays(a)
                xb, cb = cloud_arrays(b)
                self.assertGreater(len(xa), 0)
                self.assertTrue(np.array_equal(xa, xb))
                self.assertTrue(np.array_equal(ca, cb))

    def test_4_the_depth_launch_file_starts_the_bridge(self):
        from sensor_msgs.msg import PointCloud2
        if not ARGS.ros_package_path:
            self.skipTest("no --ros-package-path (build/ros_package)")
        clouds = Collector("/launched/depth_points", PointCloud2)
        launch = self.h.start("roslaunch", [
            "roslaunch", "cloudcast_ros", "cloudcast_depth.launch", "camera:=/camera",
            f"server:={self.server}", "points:=/launched/depth_points", "delivery:=all",
            "name:=launched_depth", "depth_scale:=1.0"],
            extra_env={"ROS_PACKAGE_PATH": ARGS.ros_package_path})
        self.h.wait_for_subscriber(DEPTH_TOPICS[0], "/camera/launched_depth", timeout=30)
        ros_harness.wait_until(lambda: clouds.sub.get_num_connections() > 0, 20,
                               "a connection to /launched/depth_points")
        base = 4000
        self.publish("depth32", FRAMES[:1], base, subscribers=4)
        (cloud,) = clouds.wait_for([stamp_ns(base, 0)], 30)
        self.assertEqual(cloud.header.frame_id, "tsukuba_left_optical")
        # The server's default stages (passthrough z in [3, 12], 3 cm voxels) thin it out.
        self.assertGreater(cloud.width, 0)
        # The launch file's conditional parameter reached the node.
        code, _, value = self.h.master_api.getParam("/harness",
                                                    "/camera/launched_depth/depth_scale")
        self.assertEqual((code, value), (1, 1.0))
        launch.stop()


def main():
    global ARGS
    ARGS, rest = ros_harness.parse_test_args()
    ros_harness.skip_unless_ready(ARGS, "groundtruth", nodelets=("depth_image_proc",))
    ros_harness.run_tests(rest)


if __name__ == "__main__":
    main()
