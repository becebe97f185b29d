#!/usr/bin/env python3
"""cloudcast-ros-bridge with ~input stereo against a real ROS master: rectified New Tsukuba pairs
matched on the server.

Everything runs on 127.0.0.1, started here: rosmaster on a free port, a cloudcast-server, the
bridge (/stereo/cloudcast_stereo: ~stereo/matcher sgm, 160 disparities, ~stereo/publish_disparity,
passthrough and voxel grid off; publishing /cloudcast/stereo_points and /cloudcast/disparity)
and the New Tsukuba publisher (ros/testing/tsukuba_publisher.py --kind stereo: the daylight left
image as bgr8, the right one as mono8, both CameraInfos with f = 615, B = 0.1 m). This process
subscribes with rospy.

Exit 77 (ctest: skipped) when ROS or the data are missing, and when the server answers stereo
frames with UNIMPLEMENTED (a server without the matching stage).

  ros_stereo_test.py --bin-dir build/bin --data ../shared/data/new_tsukuba [-k] [unittest args]
"""

import os
import subprocess
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "testing"))
import ros_harness  # noqa: E402
from ros_clouds import Collector, cloud_arrays, diag_values, stamp_ns  # noqa: E402

ARGS = None
FRAMES = ["00001", "00600", "01200", "01400"]  # ground-truth disparities up to 146
F, BASELINE = 615.0, 0.1
BRIDGE_PARAMS = {
    "input": "stereo",
    "delivery": "all",
    "stereo/matcher": "sgm",
    "stereo/num_disparities": 160,
    "stereo/publish_disparity": True,
    "passthrough/enabled": False,
    "voxel/enabled": False,
    "draco/position_bits": 20,
    "draco/encode_speed": 10,  # sequential coding keeps the point order
    "draco/decode_speed": 10,
    "diagnostics_period": 0.5,
}
STEREO_TOPICS = ["/stereo/left/image_rect_color", "/stereo/right/image_rect",
                 "/stereo/left/camera_info", "/stereo/right/camera_info"]
BAD_LIMIT = 0.30


def ground_truth(frame):
    import cv2
    return cv2.imread(f"{ARGS.data}/groundtruth/disparity_maps/left/"
                      f"tsukuba_disparity_L_{frame}.png", cv2.IMREAD_UNCHANGED).astype("float32")


def bad_2(disparity, valid, gt, offset):
    """bad-2.0 as docs/stereo.md scores the matchers: of the pixels with a match (a valid
    disparity above 0: 0 has no depth) and a ground truth (gt > 0), the share more than 2 pixels
    from gt + offset (the New Tsukuba truth reads 1 px low); and the density, the share of
    ground-truth pixels with a match."""
    import numpy as np
    scored = valid & (disparity > 0) & (gt > 0)
    wrong = np.abs(disparity - (gt + offset)) > 2.0
    return float((wrong & scored).sum()) / float(scored.sum()), float(scored.sum()) / float(
        (gt > 0).sum())


class RosStereoTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import PointCloud2
        from stereo_msgs.msg import DisparityImage
        cls.h = ros_harness.Harness(ARGS.bin_dir, keep=ARGS.keep)
        try:
            cls.server = cls.h.start_server()
            _, cls.bridge_node = cls.h.start_bridge(
                "cloudcast_stereo", dict(BRIDGE_PARAMS, server=cls.server),
                {"points2": "/cloudcast/stereo_points", "disparity": "/cloudcast/disparity"})
            rospy.init_node("ros_stereo_test", disable_signals=True)
            cls.clouds = Collector("/cloudcast/stereo_points", PointCloud2)
            cls.disparities = Collector("/cloudcast/disparity", DisparityImage)
            cls.diagnostics = Collector("/diagnostics", DiagnosticArray)
            for t in STEREO_TOPICS:
                cls.h.wait_for_subscriber(t, cls.bridge_node)
            for c in (cls.clouds, cls.disparities):
                ros_harness.wait_until(lambda: c.sub.get_num_connections() > 0, 20,
                                       f"a connection to {c.sub.resolved_name}")
            cls.skip_without_the_stereo_stage()
        except unittest.SkipTest:
            cls.h.close()
            raise
        except Exception:
            print(cls.h.logs(), file=sys.stderr)
            cls.h.close()
            raise

    @classmethod
    def skip_without_the_stereo_stage(cls):
        """One pair first: a server without the matching stage answers it with UNIMPLEMENTED."""
        cls.run_publisher(FRAMES[:1], 500)
        stamp = stamp_ns(500, 0)

        def answered():
            if stamp in cls.clouds.by_stamp:
                return True
            return any("UNIMPLEMENTED" in v.get("last_error", "")
                       for v in diag_values(cls.diagnostics, cls.bridge_node))
        ros_harness.wait_until(answered, 60, "the first stereo pair's cloud or error")
        if stamp not in cls.clouds.by_stamp:
            error = [v["last_error"] for v in diag_values(cls.diagnostics, cls.bridge_node)
                     if "UNIMPLEMENTED" in v.get("last_error", "")][-1]
            raise unittest.SkipTest(f"the server answers stereo pairs with {error}: its matching "
                                    "stage is not in this build (issue 19)")

    @classmethod
    def tearDownClass(cls):
        import rospy
        rospy.signal_shutdown("test done")
        cls.h.close()

    @classmethod
    def run_publisher(cls, frames, stamp_base, subscribers=1):
        waits = [f"{t[len('/stereo/'):]}={subscribers}" for t in STEREO_TOPICS]
        p = cls.h.start(f"publisher_{stamp_base}",
                        [sys.executable, os.path.join(ros_harness.HERE, "tsukuba_publisher.py"),
                         "--data", ARGS.data, "--kind", "stereo", "--frames", ",".join(frames),
                         "--rate", "5", "--stamp-base", str(stamp_base)]
                        + [a for w in waits for a in ("--wait", w)])
        try:
            p.popen.wait(60)
        except subprocess.TimeoutExpired:
            raise AssertionError("the publisher did not finish in 60 s:\n" + cls.h.logs())
        if p.popen.returncode != 0:
            raise AssertionError(p.output())

    def test_1_pairs_become_clouds_and_disparity_images(self):
        import numpy as np
        base = 1000
        self.run_publisher(FRAMES, base)
        stamps = [stamp_ns(base, k) for k in range(len(FRAMES))]
        clouds = self.clouds.wait_for(stamps, 60)
        disparities = self.disparities.wait_for(stamps, 60)
        ros_harness.wait_until(
            lambda: any(int(v.get("clouds", 0)) >= 1 + len(FRAMES)
                        for v in diag_values(self.diagnostics, self.bridge_node)),
            10, "diagnostics counting the clouds")
        values = diag_values(self.diagnostics, self.bridge_node)
        bound = max(float(v["position_error_bound"]) for v in values)
        self.assertGreater(max(float(v["match_ms_max"]) for v in values), 0)
        self.assertEqual(values[-1]["frame_errors"], "0")
        self.assertEqual(values[-1]["publish_errors"], "0")
        for frame, cloud, disp in zip(FRAMES, clouds, disparities):
            with self.subTest(frame=frame):
                for msg in (cloud, disp, disp.image):
                    self.assertEqual(msg.header.frame_id, "tsukuba_left_optical")
                    self.assertEqual(msg.header.stamp.to_nsec(), cloud.header.stamp.to_nsec())
                self.assertEqual((disp.image.width, disp.image.height), (640, 480))
                self.assertEqual(disp.image.encoding, "32FC1")
                self.assertAlmostEqual(disp.f, F, places=3)
                self.assertAlmostEqual(disp.T, BASELINE, places=6)
                self.assertEqual(disp.delta_d, 1.0 / 16)
                self.assertEqual((disp.min_disparity, disp.max_disparity), (0.0, 159.0))
                d = np.frombuffer(bytes(disp.image.data), dtype="<f4").reshape(480, 640)
                valid = d >= disp.min_disparity
                # 1/16 pixel steps.
                self.assertTrue(np.array_equal(d[valid] * 16, np.rint(d[valid] * 16)))
                # A reasonable cloud: most pixels matched, each matched pixel one point.
                xyz, _ = cloud_arrays(cloud)
                self.assertGreater(len(xyz), 0.5 * 640 * 480)
                keep = valid & (d > 0)
                self.assertEqual(len(xyz), int(keep.sum()))
                # The points are the disparity formula on the published map, in pixel order:
                # z = f T / d.
                z = (F * BASELINE / d[keep]).astype("float32")
                self.assertLessEqual(float(np.abs(xyz[:, 2] - z).max()),
                                     bound + 1e-6 * float(z.max()))
                gt = ground_truth(frame)
                (bad_gt, density), (bad_gt1, _) = (bad_2(d, valid, gt, o) for o in (0, 1))
                print(f"stereo {frame}: {len(xyz)} points, density {density:.1%}, bad-2.0 "
                      f"{bad_gt:.1%} against the ground truth, {bad_gt1:.1%} against GT+1",
                      file=sys.stderr)
                self.assertLess(bad_gt1, BAD_LIMIT)

    def test_2_the_stereo_launch_file_starts_the_bridge(self):
        from sensor_msgs.msg import PointCloud2
        if not ARGS.ros_package_path:
            self.skipTest("no --ros-package-path (build/ros_package)")
        clouds = Collector("/launched/stereo_points", PointCloud2)
        launch = self.h.start("roslaunch", [
            "roslaunch", "cloudcast_ros", "cloudcast_stereo.launch", "camera:=/stereo",
            f"server:={self.server}", "points:=/launched/stereo_points", "delivery:=all",
            "name:=launched_stereo", "matcher:=sgm", "num_disparities:=160"],
            extra_env={"ROS_PACKAGE_PATH": ARGS.ros_package_path})
        self.h.wait_for_subscriber(STEREO_TOPICS[0], "/stereo/launched_stereo", timeout=30)
        ros_harness.wait_until(lambda: clouds.sub.get_num_connections() > 0, 20,
                               "a connection to /launched/stereo_points")
        base = 2000
        self.run_publisher(FRAMES[:1], base, subscribers=2)
        (cloud,) = clouds.wait_for([stamp_ns(base, 0)], 60)
        self.assertEqual(cloud.header.frame_id, "tsukuba_left_optical")
        self.assertGreater(cloud.width, 0)
        code, _, value = self.h.master_api.getParam(
            "/harness", "/stereo/launched_stereo/stereo/num_disparities")
        self.assertEqual((code, value), (1, 160))
        launch.stop()

    def test_3_h264_pairs_match_nearly_as_well(self):
        """~encoding h264 (both views as H.264, the right one predicted from the left, veryfast
        crf 14: issue 27's measured +0.02 points of bad-2.0): a second bridge on the same
        topics gets disparity maps that are not the raw bridge's (the views did travel as
        video), score within 3 points of them against the ground truth, and keep at least
        three quarters of their density."""
        import numpy as np
        from stereo_msgs.msg import DisparityImage
        h264_disparities = Collector("/cloudcast/h264_disparity", DisparityImage)
        params = dict(BRIDGE_PARAMS, server=self.server, encoding="h264",
                      **{"h264/preset": "veryfast", "h264/crf": 14.0, "h264/mbps": 20.0,
                         "h264/fps": 5.0})
        bridge, node = self.h.start_bridge(
            "cloudcast_h264", params,
            {"points2": "/cloudcast/h264_points", "disparity": "/cloudcast/h264_disparity"})
        for t in STEREO_TOPICS:
            self.h.wait_for_subscriber(t, node)
        ros_harness.wait_until(lambda: h264_disparities.sub.get_num_connections() > 0, 20,
                               "a connection to /cloudcast/h264_disparity")
        base = 3000
        self.run_publisher(FRAMES, base, subscribers=2)
        stamps = [stamp_ns(base, k) for k in range(len(FRAMES))]
        raw = self.disparities.wait_for(stamps, 60)
        coded = h264_disparities.wait_for(stamps, 60)
        values = diag_values(self.diagnostics, node)
        self.assertTrue(values, "no diagnostics from the h264 bridge")
        self.assertEqual(values[-1]["frame_errors"], "0")
        differ = 0
        for frame, a, b in zip(FRAMES, raw, coded):
            with self.subTest(frame=frame):
                da = np.frombuffer(bytes(a.image.data), dtype="<f4").reshape(480, 640)
                db = np.frombuffer(bytes(b.image.data), dtype="<f4").reshape(480, 640)
                differ += int(not np.array_equal(da, db))
                gt = ground_truth(frame)
                bad_raw, density_raw = bad_2(da, da >= a.min_disparity, gt, 1)
                bad_h264, density = bad_2(db, db >= b.min_disparity, gt, 1)
                print(f"stereo {frame} over H.264: bad-2.0 {bad_h264:.1%} against GT+1 "
                      f"(raw {bad_raw:.1%}), density {density:.1%} (raw {density_raw:.1%})",
                      file=sys.stderr)
                self.assertLess(bad_h264, bad_raw + 0.03)
                self.assertLess(bad_h264, BAD_LIMIT)
                # The coding's smoothing fails some uniqueness checks: fewer pixels matched,
                # but not many fewer.
                self.assertGreater(density, 0.75 * density_raw)
        self.assertGreater(differ, 0, "every H.264 disparity map equals the raw one")
        bridge.stop()


def main():
    global ARGS
    ARGS, rest = ros_harness.parse_test_args()
    ros_harness.skip_unless_ready(ARGS, "illumination", nodelets=())
    ros_harness.run_tests(rest)


if __name__ == "__main__":
    main()
