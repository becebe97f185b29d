#!/usr/bin/env python3
"""Publishes New Tsukuba frames as a calibrated stereo camera would, for the bridge's tests.

Topics (under /stereo, the layout stereo_image_proc uses):
  disparity               stereo_msgs/DisparityImage from the ground-truth left disparity (32FC1,
                          the PNG's value in pixels), f = 615, T = 0.1 m (the data's README),
                          min_disparity 4 (the smallest valid value in the sample); the ground
                          truth's 0 ("no disparity") becomes min_disparity - 1 = 3, the value
                          stereo_image_proc writes for the pixels it could not match
  left/image_rect_color   sensor_msgs/Image, bgr8 (the left colour PNG without its alpha)
  left/camera_info, right/camera_info
                          sensor_msgs/CameraInfo, 640x480, K = [615 0 320; 0 615 240; 0 0 1],
                          the right P with Tx = -f * B
Frame k of the run (0, 1, ...) is stamped --stamp-base + k seconds, so a test knows each stamp's
frame; every message of a frame has the same stamp (ExactTime matches them).

  tsukuba_publisher.py --data DIR --frames 00001,00600 [--repeat N] [--rate HZ]
                       [--wait TOPIC=N ...] [--stamp-base S]
"""

import argparse
import sys
import time

import cv2
import numpy as np
import rospy
from sensor_msgs.msg import CameraInfo, Image
from stereo_msgs.msg import DisparityImage

F, BASELINE, CX, CY, W, H = 615.0, 0.1, 320.0, 240.0, 640, 480
FRAME_ID = "tsukuba_left_optical"
MIN_DISPARITY = 4.0  # the ground truth's smallest valid value (its README); 0 is invalid


def paths(data, frame):
    return (f"{data}/groundtruth/disparity_maps/left/tsukuba_disparity_L_{frame}.png",
            f"{data}/illumination/daylight/left/tsukuba_daylight_L_{frame}.png")


def camera_info(tx):
    info = CameraInfo()
    info.width, info.height = W, H
    info.distortion_model = "plumb_bob"
    info.D = [0.0] * 5
    info.K = [F, 0, CX, 0, F, CY, 0, 0, 1]
    info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    info.P = [F, 0, CX, tx, 0, F, CY, 0, 0, 0, 1, 0]
    info.header.frame_id = FRAME_ID
    return info


def load(data, frame):
    """The frame's DisparityImage and colour Image (headers filled at publishing time)."""
    disparity_path, colour_path = paths(data, frame)
    d = cv2.imread(disparity_path, cv2.IMREAD_UNCHANGED)
    c = cv2.imread(colour_path, cv2.IMREAD_COLOR)  # BGR; the alpha is dropped
    if d is None or c is None:
        sys.exit(f"tsukuba_publisher: cannot read {disparity_path} or {colour_path}")
    disparity = DisparityImage()
    disparity.header.frame_id = FRAME_ID
    image = disparity.image
    image.header.frame_id = FRAME_ID
    image.height, image.width = d.shape
    image.encoding = "32FC1"
    image.is_bigendian = 0
    image.step = image.width * 4
    values = d.astype("<f4")
    values[d == 0] = MIN_DISPARITY - 1.0
    image.data = values.tobytes()
    disparity.f, disparity.T = F, BASELINE
    disparity.valid_window.width, disparity.valid_window.height = W, H
    disparity.min_disparity, disparity.max_disparity = MIN_DISPARITY, 255.0
    disparity.delta_d = 1.0
    colour = Image()
    colour.header.frame_id = FRAME_ID
    colour.height, colour.width = c.shape[:2]
    colour.encoding = "bgr8"
    colour.step = colour.width * 3
    colour.data = np.ascontiguousarray(c).tobytes()
    return disparity, colour


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="the New Tsukuba folder")
    ap.add_argument("--frames", required=True, help="comma-separated frame names, e.g. 00001")
    ap.add_argument("--repeat", type=int, default=1, help="publish the frames this many times")
    ap.add_argument("--rate", type=float, default=5.0, help="frames per second (0: no pause)")
    ap.add_argument("--wait", action="append", default=[], metavar="TOPIC=N",
                    help="first wait (up to 30 s) for N subscribers on TOPIC (relative to "
                         "/stereo, e.g. disparity=2); repeatable")
    ap.add_argument("--stamp-base", type=int, default=1000, help="stamp of frame 0, seconds")
    ap.add_argument("--stamp-now", action="store_true",
                    help="stamp each frame with the time it is published instead (latency)")
    args = ap.parse_args()

    rospy.init_node("tsukuba_publisher", disable_signals=False)
    frames = [load(args.data, f) for f in args.frames.split(",")]
    left_info, right_info = camera_info(0.0), camera_info(-F * BASELINE)
    ns = "/stereo/"
    pubs = {
        "disparity": rospy.Publisher(ns + "disparity", DisparityImage, queue_size=100),
        "colour": rospy.Publisher(ns + "left/image_rect_color", Image, queue_size=100),
        "left": rospy.Publisher(ns + "left/camera_info", CameraInfo, queue_size=100),
        "right": rospy.Publisher(ns + "right/camera_info", CameraInfo, queue_size=100),
    }
    by_topic = {p.resolved_name[len(ns):]: p for p in pubs.values()}
    wanted = {}
    for w in args.wait:
        topic, _, n = w.partition("=")
        if topic not in by_topic or not n.isdigit():
            sys.exit(f"tsukuba_publisher: --wait {w}: must be TOPIC=N, TOPIC one of "
                     f"{sorted(by_topic)}")
        wanted[topic] = int(n)
    deadline = time.monotonic() + 30
    while any(by_topic[t].get_num_connections() < n for t, n in wanted.items()):
        if time.monotonic() > deadline or rospy.is_shutdown():
            counts = {k: p.get_num_connections() for k, p in pubs.items()}
            sys.exit(f"tsukuba_publisher: not enough subscribers after 30 s: {counts}")
        time.sleep(0.05)
    time.sleep(0.5)  # connections are counted before their TCPROS handshakes finish
    k = 0
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    for _ in range(args.repeat):
        for (disparity, colour), name in zip(frames, args.frames.split(",")):
            if rospy.is_shutdown():
                return
            stamp = rospy.Time.now() if args.stamp_now else rospy.Time(args.stamp_base + k, 0)
            for msg in (disparity, disparity.image, colour, left_info, right_info):
                msg.header.stamp = stamp
            pubs["disparity"].publish(disparity)
            pubs["colour"].publish(colour)
            pubs["left"].publish(left_info)
            pubs["right"].publish(right_info)
            print(f"published {k} {name} {stamp.to_nsec()}", flush=True)
            k += 1
            if period:
                time.sleep(period)
    print("done", flush=True)
    time.sleep(1.0)  # let the last messages leave the queues


if __name__ == "__main__":
    main()
