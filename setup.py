import sys

from setuptools import find_packages, setup

package_name = "tof_calib_ros"
executables = ["calibration_node", "tof_sim_node", "tof_calib"]
# colcon puts the console scripts in lib/<package> (setup.cfg); a pip-built wheel cannot, so it
# carries small launchers there instead, where 'ros2 run' looks. Only in wheels (pip's PEP 517
# build runs 'setup.py bdist_wheel' too): in a colcon install they would overwrite the scripts.
# An sdist lists them as well, so that a wheel built from it ('python -m build') has them.
wheel_only = {"bdist_wheel", "sdist"} & set(sys.argv)
launchers = [("lib/" + package_name, ["launchers/" + e for e in executables])] if wheel_only else []

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "benchmarks"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ] + launchers,
    install_requires=["setuptools", "numpy", "scipy", "opencv-python-headless", "threadpoolctl", "PyYAML",
                      "rosbags", "mcap", "matplotlib", "tqdm", "psutil"],
    extras_require={
        "ros": ["ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"],
        "test": ["pytest", "hypothesis"],
    },
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="tof_calib_ros maintainers",
    maintainer_email="maintainers@tof-calib-ros.invalid",
    description="Depth-aided intrinsic calibration of time-of-flight cameras.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "calibration_node = tof_calib_ros.ros.node:main",
        "tof_sim_node = tof_calib_ros.ros.sim_node:main",
        "tof_calib = tof_calib_ros.offline.cli:main",
    ]},
)
