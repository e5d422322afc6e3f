"""The calibration engine, read as the paper's algorithm: the board and its detection
(``board``, ``detection``), the camera model (``camera``), OpenCV's calibration as the first
guess (``traditional``), the denoised corner depths (``planarize``), K from the squares' true
size (``depth_init``), the joint fit (``bundle``) with the ToF depth error model
(``depth_bias``), the options and the model chosen (``options``), the views checked and
prepared (``inputs``), planarized together (``view_planes``), the model the data call for and
its joint fit (``model_choice``, ``wiggle_search``), the corners' check of the depth
(``depth_trust``), the whole method (``pipeline``) and its result (``result``). numpy, scipy
and OpenCV only: imports nothing of ours outside ``core``, so it runs, and can be changed,
without ROS, files or streams.
"""
