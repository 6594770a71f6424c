"""Launch the ship_ident identification node with the shipped parameter file.

    ros2 launch ship_ident ship_ident.launch.py
    ros2 launch ship_ident ship_ident.launch.py namespace:=boat1 use_sim_time:=true
    ros2 launch ship_ident ship_ident.launch.py params_file:=/path/to/my_boat.yaml

The parameter file is keyed ``/**`` (any node name and namespace), so its values apply in any
``namespace``; the node's topics then live under it (``/boat1/ship_ident/parameters``), and its
inputs too unless they are absolute (the shipped ones are: ``/usv/rudder`` ...).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

PACKAGE = "ship_ident"
PARAMETER_FILE = ("config", "ship_ident.yaml")  # in the package's share directory (setup.py data_files)


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "params_file",
                default_value=PathJoinSubstitution([FindPackageShare(PACKAGE), *PARAMETER_FILE]),
                description="parameter file of the node (keyed /**)",
            ),
            DeclareLaunchArgument("namespace", default_value="", description="namespace of the node"),
            DeclareLaunchArgument(
                "use_sim_time", default_value="false", description="follow /clock (a bag played with --clock)"
            ),
            Node(
                package=PACKAGE,
                executable="identifier_node",
                name="ship_ident",
                namespace=LaunchConfiguration("namespace"),
                parameters=[
                    LaunchConfiguration("params_file"),
                    {"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)},
                ],
                output="screen",
                emulate_tty=True,
            ),
        ]
    )
