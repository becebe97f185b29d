#!/usr/bin/python3
"""The ROS 2 bridge builds and links without ROS 1 (docs/ros2.md, issue 28).

Three checks, each on what the build really did, not on what CMake was asked:
  1. compile lines (compile_commands.json) of the ROS 2 bridge's targets and of the shared core
     (bridge/): no include folder of a ROS 1 package or of the ROS 1 node (ros/), no ROS_*
     definition (rosconsole-extras.cmake adds two globally);
  2. the headers each of their objects read (ninja -t deps: the compiler's own depfiles): none
     installed by a ROS 1 package (Debian builds ROS 1 from source packages named ros-*) or
     from the repository's ros/ folder;
  3. the libraries cloudcast-ros2-bridge loads (ldd, transitively): none from a ROS 1 package.
A check that finds nothing to look at fails (no objects, no headers, no libraries), so that it
cannot pass by reading the wrong build.
"""
import argparse
import json
import os
import re
import shlex
import subprocess
import sys

# The targets whose objects must be free of ROS 1 (their CMakeFiles folders).
TARGET_DIRS = [
    "ros2/CMakeFiles/cloudcast_ros2_messages.dir/",
    "ros2/CMakeFiles/cloudcast_ros2_dds.dir/",
    "ros2/CMakeFiles/cloudcast_ros2_bridge.dir/",
    "ros2/CMakeFiles/cloudcast-ros2-bridge.dir/",
    "bridge/CMakeFiles/cloudcast_bridge_core.dir/",
    "bridge/CMakeFiles/cloudcast_bridge_link.dir/",
]


def source_packages(paths):
    """{path: set of the Debian source packages of its owners} for the paths dpkg knows."""
    owners = {}
    paths = sorted(set(paths))
    for i in range(0, len(paths), 200):
        chunk = paths[i:i + 200]
        out = subprocess.run(["dpkg-query", "-S"] + chunk, capture_output=True, text=True).stdout
        for line in out.splitlines():
            pkgs, _, path = line.partition(": ")
            owners.setdefault(path.strip(), set()).update(p.strip() for p in pkgs.split(", "))
    binaries = sorted(set().union(*owners.values())) if owners else []
    if not binaries:
        return {}
    out = subprocess.run(["dpkg-query", "-W", "-f", "${binary:Package} ${source:Package}\n"]
                         + binaries, capture_output=True, text=True).stdout
    source = {}
    for line in out.splitlines():
        b, _, s = line.partition(" ")
        s = s.split(" ")[0] or b.split(":")[0]
        source[b] = s
        source[b.split(":")[0]] = s
    return {path: {source.get(p, p) for p in pkgs} for path, pkgs in owners.items()}


def ros1_sources(sources):
    """The ROS 1 ones among Debian source packages (Debian builds ROS 1 from ros-*)."""
    return sorted(s for s in sources if s.startswith("ros-"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build-dir", required=True)
    ap.add_argument("--source-dir", required=True)
    ap.add_argument("--program", required=True, help="the built cloudcast-ros2-bridge")
    args = ap.parse_args()
    build = os.path.realpath(args.build_dir)
    ros1_node = os.path.join(os.path.realpath(args.source_dir), "ros") + os.sep
    failures = []

    # 1. The compile lines.
    with open(os.path.join(build, "compile_commands.json")) as f:
        commands = json.load(f)
    objects = []
    include_dirs = {}  # folder -> an object compiled with it
    for c in commands:
        argv = shlex.split(c["command"]) if "command" in c else c["arguments"]
        out = argv[argv.index("-o") + 1] if "-o" in argv else ""
        if not any(out.startswith(t) for t in TARGET_DIRS):
            continue
        objects.append(out)
        for i, a in enumerate(argv):
            inc = None
            if a in ("-I", "-isystem", "-iquote", "-idirafter") and i + 1 < len(argv):
                inc = argv[i + 1]
            elif a.startswith("-I") and len(a) > 2:
                inc = a[2:]
            if inc is not None:
                real = os.path.realpath(os.path.join(c.get("directory", build), inc))
                include_dirs.setdefault(real, out)
                if (real + os.sep).startswith(ros1_node):
                    failures.append(f"{out}: includes {inc} (the ROS 1 node's folder)")
            if a.startswith("-DROS") or (a == "-D" and argv[i + 1].startswith("ROS")):
                failures.append(f"{out}: defines {a} (ROS 1's rosconsole)")
    # A folder a ROS 1 package installs (/usr/include/xmlrpcpp: roscpp's CMake package adds it);
    # /usr/include itself is every package's.
    system_dirs = [d for d in include_dirs if d.startswith("/usr/") and
                   d not in ("/usr/include", "/usr/local/include")]
    for d, srcs in source_packages(system_dirs).items():
        if ros1_sources(srcs):
            failures.append(f"{include_dirs.get(d, '?')}: includes {d} (Debian source package "
                            f"{', '.join(ros1_sources(srcs))}: ROS 1)")
    if len(objects) < 10:
        failures.append(f"only {len(objects)} objects of the ROS 2 targets in compile_commands.json")

    # 2. The headers each object read.
    deps = subprocess.run(["ninja", "-C", build, "-t", "deps"] + objects, capture_output=True,
                          text=True)
    if deps.returncode != 0:
        failures.append(f"ninja -t deps failed: {deps.stderr.strip()}")
    headers = {}  # path -> an object that read it
    current = None
    for line in deps.stdout.splitlines():
        if line and not line.startswith(" "):
            current = line.split(":")[0]
        elif line.strip():
            headers.setdefault(os.path.realpath(os.path.join(build, line.strip())), current)
    if len(headers) < 100:
        failures.append(f"only {len(headers)} headers in the depfiles of the ROS 2 objects "
                        "(a stale or other build folder?)")
    for h, obj in sorted(headers.items()):
        if h.startswith(ros1_node):
            failures.append(f"{obj} read {h} (the ROS 1 node's folder)")
    system = [h for h in headers if not h.startswith(build) and
              not h.startswith(os.path.realpath(args.source_dir))]
    for h, srcs in source_packages(system).items():
        if ros1_sources(srcs):
            failures.append(f"{headers.get(os.path.realpath(h), '?')} read {h} (Debian source "
                            f"package {', '.join(ros1_sources(srcs))}: ROS 1)")

    # 3. The libraries the program loads.
    ldd = subprocess.run(["ldd", args.program], capture_output=True, text=True)
    libs = re.findall(r"=> (/\S+)", ldd.stdout)
    if ldd.returncode != 0 or len(libs) < 5:
        failures.append(f"ldd {args.program}: {ldd.stderr.strip() or ldd.stdout[:200]}")
    for lib, srcs in source_packages([os.path.realpath(x) for x in libs] + libs).items():
        if ros1_sources(srcs):
            failures.append(f"{args.program} loads {lib} (Debian source package "
                            f"{', '.join(ros1_sources(srcs))}: ROS 1)")

    print(f"checked {len(objects)} objects ({len(include_dirs)} include folders), "
          f"{len(headers)} headers, {len(libs)} libraries")
    for f in failures:
        print("FAIL:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
