"""Files and recordings: what goes in and what comes out, checked as it is read.

Image messages decoded with their encodings and sizes checked (``image_decode``); the
calibration files camera_calibration_parsers reads, with the views beside them
(``calibration_file``); an output folder whose generations change as one (``output_folder``);
folders of stills (``image_folder``); ROS 1 and 2 bags, cut-off ones salvaged (``bag_io``,
``bag_salvage``, with rosbags: no ROS installation needed). May import ``core`` and
``collect``; nothing here imports rclpy.
"""
