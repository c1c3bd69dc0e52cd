"""Pure algorithms: numpy, numba and OpenCV only; no ROS, no file or network I/O.

Layered by concern, each layer importing only those before it:

- the floor: :mod:`.geometry` (SE(3)), :mod:`.camera` (intrinsics, distortion), :mod:`.frame` (what goes
  in and out), :mod:`.imu`, :mod:`.frame_clock`, :mod:`.rolling_shutter` and :mod:`.image` (pyramids,
  patterns, sampling, the colour/depth front end);
- :mod:`.events`: event batches, time surfaces (ATS, constant tau, speed-invariant), event pixel
  selection, the event front end and the temporary event map;
- :mod:`.mapping`: map points, keyframes (nine-region health), the mapper and the ports tracking talks to it by;
- :mod:`.tracking`: residual blocks of Eq. 4, the coarse-to-fine optimiser, checks and the motion model;
- :mod:`.odometry`: the facade the runtime, the replay and the nodes drive.
"""
