"""Starts `edtmap node` and, optionally, RViz 2 with ros/edtmap.rviz.

    ros2 launch ros/launch/edtmap.launch.py config:=configs/ros2_lidar.toml
    ros2 launch ros/launch/edtmap.launch.py config:=my_robot.toml rviz:=false edtmap:=/path/to/edtmap

Arguments:
  config   the node's TOML configuration (default: configs/ros2_lidar.toml
           of this checkout)
  edtmap   the edtmap binary (default: `edtmap` on PATH, as `cargo install
           --path crates/cli` puts it)
  rviz     true | false: start rviz2 with ros/edtmap.rviz (default true)

edtmap is not a ROS package (no colcon build): the launch file runs its
binary as a process, which takes its topics, frames and rates from the
config's [ros] section, not from ROS parameters. Both processes take
ROS_DOMAIN_ID from the environment.
"""
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("config", default_value=str(ROOT / "configs" / "ros2_lidar.toml")),
        DeclareLaunchArgument("edtmap", default_value="edtmap"),
        DeclareLaunchArgument("rviz", default_value="true"),
        ExecuteProcess(
            cmd=[LaunchConfiguration("edtmap"), "node", "--config", LaunchConfiguration("config")],
            name="edtmap",
            output="screen",
            # Ctrl-C: the node finishes its frame, saves (save_on_exit) and exits.
            sigterm_timeout="10",
        ),
        ExecuteProcess(
            cmd=["rviz2", "-d", str(HERE.parent / "edtmap.rviz")],
            name="rviz2",
            output="screen",
            condition=IfCondition(LaunchConfiguration("rviz")),
        ),
    ])
