"""ROS bags as a measurement source: reading, pairing by time, pose and image topics."""
