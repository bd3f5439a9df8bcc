"""The paper's model as pure numpy: no ROS, no files, no command line."""
