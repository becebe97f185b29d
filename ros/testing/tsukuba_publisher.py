#!/usr/bin/env python3
"""Publishes New Tsukuba frames as a calibrated camera would, for the bridge's tests and benchmark.

The camera: 640x480, K = [615 0 320; 0 615 240; 0 0 1], baseline B = 0.1 m (the data's README).
Kinds (--kind), each under the namespace and with the topic names its stock ROS consumer uses:

  disparity (/stereo, stereo_image_proc's point_cloud2)
    disparity               stereo_msgs/DisparityImage from the ground-truth left disparity (32FC1,
                            the PNG's value in pixels), f = 615, T = 0.1, min_disparity 4 (the
                            smallest valid value in the sample); the ground truth's 0 ("no
                            disparity") becomes min_disparity - 1 = 3, the value stereo_image_proc
                            writes for the pixels it could not match
    left/image_rect_color   sensor_msgs/Image, bgr8 (the left colour PNG without its alpha)
    left/camera_info, right/camera_info
                            sensor_msgs/CameraInfo, the right P with Tx = -f * B
  depth16, depth32 (/camera, depth_image_proc's point_cloud_xyzrgb)
    depth_registered/image_rect
                            the ground truth as depth, z = f * B / d: 16UC1 millimetres rounded
                            to the nearest (d = 0: 0, no measurement) or 32FC1 metres (d = 0:
                            NaN; and, on every frame, rows 0-9 of columns 0-9 set to 0.0, of
                            columns 10-19 to +inf, rows 10-19 of columns 0-19 to NaN: the holes
                            a depth camera leaves)
    rgb/image_rect_color    bgr8, as above
    rgb/camera_info         the left CameraInfo
  stereo (/stereo, stereo_image_proc's disparity nodelet, with the left image in colour)
    left/image_rect_color   bgr8, the left image
    right/image_rect        mono8, the right image in grey (cv2's BGR to grey)
    left/camera_info, right/camera_info
Frame k of the run (0, 1, ...) is stamped --stamp-base + k seconds, so a test knows each stamp's
frame (with --stamp-now, the stamp's last three nanosecond digits give its position in
--frames); every message of a frame has the same stamp (ExactTime matches them) and frame_id
tsukuba_left_optical, the right camera's too (image_geometry's StereoCameraModel asserts that
both CameraInfos name one frame: the right P carries the offset).

  tsukuba_publisher.py --data DIR --frames 00001,00600 [--kind KIND] [--repeat N] [--rate HZ]
                       [--wait TOPIC=N ...] [--stamp-base S] [--stamp-now]
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
KINDS = ("disparity", "depth16", "depth32", "stereo")


def paths(data, frame):
    return (f"{data}/groundtruth/disparity_maps/left/tsukuba_disparity_L_{frame}.png",
            f"{data}/illumination/daylight/left/tsukuba_daylight_L_{frame}.png",
            f"{data}/illumination/daylight/right/tsukuba_daylight_R_{frame}.png")


def read(path, flags):
    image = cv2.imread(path, flags)
    if image is None:
        sys.exit(f"tsukuba_publisher: cannot read {path}")
    return image


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


def image_msg(pixels, encoding, frame_id=FRAME_ID):
    msg = Image()
    msg.header.frame_id = frame_id
    msg.height, msg.width = pixels.shape[:2]
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = msg.width * pixels.dtype.itemsize * (1 if pixels.ndim == 2 else pixels.shape[2])
    msg.data = np.ascontiguousarray(pixels).tobytes()
    return msg


def depth_from_disparity(d, kind):
    """The ground-truth disparity `d` (uint8) as the depth image of `kind` (depth16: uint16 mm,
    depth32: float32 m with the holes described above)."""
    with np.errstate(divide="ignore"):
        z = F * BASELINE / d.astype(np.float64)  # metres; inf where d = 0
    if kind == "depth16":
        mm = np.where(d == 0, 0, np.rint(z * 1000.0))
        return mm.astype("<u2")
    metres = np.where(d == 0, np.nan, z).astype("<f4")
    metres[0:10, 0:10] = 0.0
    metres[0:10, 10:20] = np.inf
    metres[10:20, 0:20] = np.nan
    return metres


def load(data, frame, kind):
    """The frame's messages (headers' stamps filled at publishing time), by topic."""
    disparity_path, left_path, right_path = paths(data, frame)
    colour = image_msg(read(left_path, cv2.IMREAD_COLOR), "bgr8")  # BGR; the alpha is dropped
    if kind == "stereo":
        right = read(right_path, cv2.IMREAD_COLOR)
        grey = cv2.cvtColor(right, cv2.COLOR_BGR2GRAY)
        return {"left/image_rect_color": colour,
                "right/image_rect": image_msg(grey, "mono8")}
    d = read(disparity_path, cv2.IMREAD_UNCHANGED)
    if kind in ("depth16", "depth32"):
        depth = depth_from_disparity(d, kind)
        return {"depth_registered/image_rect":
                image_msg(depth, "16UC1" if kind == "depth16" else "32FC1"),
                "rgb/image_rect_color": colour}
    disparity = DisparityImage()
    disparity.header.frame_id = FRAME_ID
    values = d.astype("<f4")
    values[d == 0] = MIN_DISPARITY - 1.0
    disparity.image = image_msg(values, "32FC1")
    disparity.f, disparity.T = F, BASELINE
    disparity.valid_window.width, disparity.valid_window.height = W, H
    disparity.min_disparity, disparity.max_disparity = MIN_DISPARITY, 255.0
    disparity.delta_d = 1.0
    return {"disparity": disparity, "left/image_rect_color": colour}


def infos(kind):
    """The CameraInfos of `kind`, by topic."""
    if kind in ("depth16", "depth32"):
        return {"rgb/camera_info": camera_info(0.0)}
    return {"left/camera_info": camera_info(0.0),
            "right/camera_info": camera_info(-F * BASELINE)}


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="the New Tsukuba folder")
    ap.add_argument("--frames", required=True, help="comma-separated frame names, e.g. 00001")
    ap.add_argument("--kind", choices=KINDS, default="disparity", help="what to publish")
    ap.add_argument("--repeat", type=int, default=1, help="publish the frames this many times")
    ap.add_argument("--rate", type=float, default=5.0, help="frames per second (0: no pause)")
    ap.add_argument("--wait", action="append", default=[], metavar="TOPIC=N",
                    help="first wait (up to 30 s) for N subscribers on TOPIC (relative to the "
                         "kind's namespace, e.g. disparity=2); repeatable")
    ap.add_argument("--stamp-base", type=int, default=1000, help="stamp of frame 0, seconds")
    ap.add_argument("--stamp-now", action="store_true",
                    help="stamp each frame with the time it is published instead (latency), the "
                         "nanoseconds' last three digits replaced by the frame's position in "
                         "--frames (so that a consumer's output names its frame)")
    args = ap.parse_args()

    rospy.init_node("tsukuba_publisher", disable_signals=False)
    names = args.frames.split(",")
    frames = [load(args.data, f, args.kind) for f in names]
    camera_infos = infos(args.kind)
    ns = "/camera/" if args.kind.startswith("depth") else "/stereo/"
    topics = list(frames[0]) + list(camera_infos)
    pubs = {t: rospy.Publisher(ns + t, type(frames[0].get(t) or camera_infos.get(t)),
                               queue_size=100) for t in topics}
    wanted = {}
    for w in args.wait:
        topic, _, n = w.partition("=")
        if topic not in pubs or not n.isdigit():
            sys.exit(f"tsukuba_publisher: --wait {w}: must be TOPIC=N, TOPIC one of "
                     f"{sorted(pubs)}")
        wanted[topic] = int(n)
    deadline = time.monotonic() + 30
    while any(pubs[t].get_num_connections() < n for t, n in wanted.items()):
        if time.monotonic() > deadline or rospy.is_shutdown():
            counts = {k: p.get_num_connections() for k, p in pubs.items()}
            sys.exit(f"tsukuba_publisher: not enough subscribers after 30 s: {counts}")
        time.sleep(0.05)
    time.sleep(0.5)  # connections are counted before their TCPROS handshakes finish
    k = 0
    period = 1.0 / args.rate if args.rate > 0 else 0.0
    for _ in range(args.repeat):
        for index, (messages, name) in enumerate(zip(frames, names)):
            if rospy.is_shutdown():
                return
            if args.stamp_now:
                ns = rospy.Time.now().to_nsec()
                ns += index - ns % 1000  # under a microsecond off
                stamp = rospy.Time(ns // 1_000_000_000, ns % 1_000_000_000)
            else:
                stamp = rospy.Time(args.stamp_base + k, 0)
            every = dict(messages, **camera_infos)
            for msg in every.values():
                msg.header.stamp = stamp
                if isinstance(msg, DisparityImage):
                    msg.image.header.stamp = stamp
            for topic in topics:
                pubs[topic].publish(every[topic])
            print(f"published {k} {name} {stamp.to_nsec()}", flush=True)
            k += 1
            if period:
                time.sleep(period)
    print("done", flush=True)
    time.sleep(1.0)  # let the last messages leave the queues


if __name__ == "__main__":
    main()
