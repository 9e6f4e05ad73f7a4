"""The inputs of the bridge, behind one protocol (``base.Source``), chosen by name
(``registry``): ``sim`` the simulated delivery robot, ``ros`` a ROS 2 graph through
rclpy, ``dds`` a ROS 2 graph over Cyclone DDS without ROS, ``bag`` a recorded rosbag2.
"""
