"""The ROS 2 layer, thin on the rest: the calibration node (``node``), the simulated camera
driver (``sim_node``), a clean start and stop for both (``run``), the killable worker process
the node calibrates in (``calibration_worker``), the helpers that start nodes and call them as
``ros2 run`` and ``ros2 service call`` do, for the demo, the tests and the benchmarks
(``processes``), and the no-hardware demo (``demo``). The only place that imports rclpy and
the message packages; may import everything else of ours, and nothing imports it.
"""
