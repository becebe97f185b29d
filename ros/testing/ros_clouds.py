"""What the bridge's ROS tests share: collecting messages by stamp, reading a PointCloud2 into
arrays, the publisher's stamps and the bridge's /diagnostics values."""

import threading

import ros_harness


def cloud_arrays(msg):
    """x, y, z (float32, n x 3) and rgb (uint32) of a PointCloud2, by its field offsets."""
    import numpy as np
    offsets = {f.name: f.offset for f in msg.fields}
    dtype = np.dtype({"names": ["x", "y", "z", "rgb"],
                      "formats": ["<f4", "<f4", "<f4", "<u4"],
                      "offsets": [offsets["x"], offsets["y"], offsets["z"], offsets["rgb"]],
                      "itemsize": msg.point_step})
    points = np.frombuffer(bytes(msg.data), dtype=dtype, count=msg.width * msg.height)
    xyz = np.stack([points["x"], points["y"], points["z"]], axis=1)
    return xyz, points["rgb"].copy()


class Collector:
    """Messages of one topic, by header stamp (nanoseconds)."""

    def __init__(self, topic, msg_type):
        import rospy
        self.lock = threading.Lock()
        self.by_stamp = {}
        self.all = []
        self.sub = rospy.Subscriber(topic, msg_type, self._cb, queue_size=100)

    def _cb(self, msg):
        with self.lock:
            self.all.append(msg)
            if hasattr(msg, "header"):
                self.by_stamp[msg.header.stamp.to_nsec()] = msg

    def wait_for(self, stamps, timeout):
        try:
            ros_harness.wait_until(lambda: all(s in self.by_stamp for s in stamps), timeout,
                                   f"messages stamped {sorted(stamps)}")
        except TimeoutError as e:
            # What had come by the timeout, not by the call (which an f-string argument says).
            with self.lock:
                have = sorted(self.by_stamp)
            raise TimeoutError(f"{e} (have {have})") from None
        with self.lock:
            return [self.by_stamp[s] for s in stamps]

    def clear(self):
        with self.lock:
            self.by_stamp.clear()
            self.all.clear()


def replay_to_own_bridge(harness, bag, topics, prefix, params, out_topic, stamps, timeout=60):
    """Plays `bag` (recorded on `topics`, all under `prefix`, e.g. "/stereo/") to a bridge of its
    own under /replay, with `params`, and returns its clouds on `out_topic` for `stamps` (raises
    TimeoutError naming what came).

    That bridge is the only subscriber under /replay: `rosbag play --wait-for-subscribers` starts
    once each topic has one subscriber, and on the live topics that could be a nodelet or another
    bridge while the compared one was still connecting (it then missed the whole playback, under
    load). --keep-alive: a player that exits right after its last publish can take messages still
    in its outgoing queues with it (a megabyte of image per frame; rosbag2 has the same,
    ros2/rosbag2#571): once 3 of 4 frames came back. The player stays up until the bridge has
    answered every frame; a frame the bridge loses still fails."""
    from sensor_msgs.msg import PointCloud2
    replayed = Collector(out_topic, PointCloud2)
    replay, replay_node = harness.start_bridge("cloudcast_replay", params, {"points2": out_topic},
                                               namespace="/replay")
    for t in topics:
        harness.wait_for_subscriber("/replay/" + t[len(prefix):], replay_node)
    ros_harness.wait_until(lambda: replayed.sub.get_num_connections() > 0, 20,
                           "a connection to " + out_topic)
    player = harness.start("rosbag_play", [
        "rosbag", "play", "--wait-for-subscribers", "--keep-alive", "--rate", "2", bag,
        "__name:=player"] + [f"{t}:=/replay/{t[len(prefix):]}" for t in topics])
    try:
        return replayed.wait_for(stamps, timeout)
    finally:
        player.stop()
        replay.stop()


def stamp_ns(base, k):
    """The stamp of frame k of a tsukuba_publisher.py run with --stamp-base `base`."""
    return (base + k) * 1_000_000_000


def diag_values(diagnostics, node):
    """The key/value dicts of `node`'s statuses on a /diagnostics Collector, oldest first."""
    with diagnostics.lock:
        msgs = [m for m in diagnostics.all
                if m.status and m.status[0].name.startswith(node + ":")]
    return [{kv.key: kv.value for kv in m.status[0].values} for m in msgs]
