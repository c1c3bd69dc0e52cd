"""Pure algorithms: numpy, numba and OpenCV only; no ROS, no file or network I/O."""
