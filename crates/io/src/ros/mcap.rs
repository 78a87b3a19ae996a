//! ROS 2 MCAP files. Being written.
