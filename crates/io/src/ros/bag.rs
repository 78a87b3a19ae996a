//! ROS 1 bags (format 2.0). Being written.
