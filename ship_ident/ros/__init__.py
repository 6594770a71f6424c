"""The ROS 2 doors: the identification node and the live demo."""
