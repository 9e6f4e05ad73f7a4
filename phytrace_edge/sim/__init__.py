"""The simulated delivery robot (``world``, ``robot``), the mock rclpy layer it runs on
(``mock_ros``) and its rosbag2 recorder. It depends on nothing of the bridge: the
bridge hears it through ``ingest/sources/sim.py``."""
