"""The ROS-free calibration engine: numpy, scipy and OpenCV only."""
