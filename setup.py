"""ament_python package ship_ident: pip-installable as well as colcon-buildable."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ship_ident"

ROS_WHEELS = [  # only where no ROS 2 install provides rclpy (pip-only machines)
    "ros-kilted-rclpy[fastrtps]==9.1.2",
    "ros-kilted-std-msgs",
    "ros-kilted-sensor-msgs",
    "ros-kilted-diagnostic-msgs",
    "ros-kilted-rosgraph-msgs",
    "ros-kilted-geometry-msgs",
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.json") + glob("config/*.xml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/bags", glob("bags/*.mcap") + glob("bags/*.json")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "setuptools",
        "numpy>=1.24,<3",
        "scipy>=1.10,<2",
        "numba>=0.58,<1",
        "matplotlib>=3.6,<4",
        "filterpy>=1.4,<3",
        "mcap>=1.1,<2",
        "mcap-ros2-support>=0.5,<1",
        "rosbags>=0.9.20,<1",
    ],
    extras_require={
        "ros": ROS_WHEELS,
        "test": ["pytest>=7.4,<10", "pytest-xdist>=3.3,<4", "hypothesis>=6.80,<7", "ruff>=0.5,<1",
                 "colcon-common-extensions>=0.3,<1"],
        "bench": ["sysidentpy>=0.4,<1", "dask[distributed]>=2023.1", "shipmmg>=0.0.11,<0.1"],
        "fleet": ["dask[distributed]>=2023.1"],
    },
    zip_safe=True,
    maintainer="ship_ident team",
    maintainer_email="team@ship-ident.invalid",
    description="Online identification of USV steering dynamics with LS-SVM",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "identifier_node = ship_ident.ros.node:main",
            "ship-ident = ship_ident.cli:main",
        ],
    },
)
