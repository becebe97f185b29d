# A ROS 2 launch file for cloudcast-ros2-bridge (Humble, Jazzy): the bridge is a plain program
# (no rclcpp), so it runs as an ExecuteProcess with ROS 2's own arguments. docs/ros2.md.
#
#   ros2 launch cloudcast.launch.py camera:=/stereo server:=robot-pc:50051
#   ros2 launch cloudcast.launch.py camera:=/camera input:=depth params:=/path/cloudcast.yaml
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration


def generate_launch_description():
    args = [
        DeclareLaunchArgument("camera", default_value="/stereo",
                              description="the camera's namespace (its topics' prefix)"),
        DeclareLaunchArgument("server", default_value="127.0.0.1:50051",
                              description="the cloudcast server, host:port"),
        DeclareLaunchArgument("input", default_value="disparity",
                              description="disparity | depth | stereo"),
        DeclareLaunchArgument("points", default_value="cloudcast/points2",
                              description="the output topic, relative to the camera"),
        DeclareLaunchArgument("params", default_value="",
                              description="a parameters file (optional)"),
        DeclareLaunchArgument("bridge", default_value="cloudcast-ros2-bridge",
                              description="the program (on PATH, or a path)"),
    ]
    cmd = [
        LaunchConfiguration("bridge"), "--ros-args",
        "-r", ["__ns:=", LaunchConfiguration("camera")],
        "-p", ["server:=", LaunchConfiguration("server")],
        "-p", ["input:=", LaunchConfiguration("input")],
        "-r", ["points2:=", LaunchConfiguration("points")],
    ]
    params = ExecuteProcess(
        cmd=cmd + ["--params-file", LaunchConfiguration("params")],
        output="screen",
        condition=_if_set("params"),
    )
    plain = ExecuteProcess(cmd=cmd, output="screen", condition=_unless_set("params"))
    return LaunchDescription(args + [params, plain])


def _if_set(name):
    from launch.conditions import LaunchConfigurationNotEquals
    return LaunchConfigurationNotEquals(name, "")


def _unless_set(name):
    from launch.conditions import LaunchConfigurationEquals
    return LaunchConfigurationEquals(name, "")
