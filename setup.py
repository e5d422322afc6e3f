from setuptools import find_packages, setup

package_name = "tof_calib_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "benchmarks"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools", "numpy", "scipy", "opencv-python-headless", "threadpoolctl", "PyYAML"],
    extras_require={
        "ros": ["ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"],
        "test": ["pytest"],
    },
    python_requires=">=3.10",
    zip_safe=True,
    maintainer="tof_calib_ros maintainers",
    maintainer_email="maintainers@tof-calib-ros.invalid",
    description="Depth-aided intrinsic calibration of time-of-flight cameras.",
    license="Apache-2.0",
    entry_points={"console_scripts": []},
)
