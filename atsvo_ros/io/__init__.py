"""I/O: event decoders, image conversion, bag reading, trajectory files. No ROS install needed."""
