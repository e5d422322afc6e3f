"""The offline tool, ``tof_calib``: calibrate a bag, a folder of stills or a simulated
recording with no robot and no ROS installation, check a calibration file against views, and
write the HTML report. A front end, beside ``ros``: may import everything below it (``core``,
``collect``, ``files``, ``sim``, ``settings``) but not ``ros``, and nothing here imports rclpy.
"""
