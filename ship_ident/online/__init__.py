"""Online identification: the sliding window, refits, trust, change detection and what is published; no ROS."""
