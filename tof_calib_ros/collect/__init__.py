"""Collection: which frames of a stream become calibration views.

Finding the board from frame to frame (``tracking``), judging whether it was still and sharp
(``motion``), keeping the views that add coverage (``collector``), pairing amplitude and depth
by stamp (``stamp_sync``), the worker processes that do all that for a recording
(``replay``), and the live picture of it (``board_picture``). The same rules serve the node,
``tof_calib bag`` and ``tof_calib images``. May import ``core`` only: no files, no ROS.
"""
