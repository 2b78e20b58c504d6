"""Sensors at the host PC (I/O shell): real stereo cameras through OpenCV, the camera
service that serves them over the zerocal protocol, and record / replay of a run.

    sources.py          SOURCE text -> an open cv2.VideoCapture (device, V4L2 path,
                        GStreamer pipeline, video file, image sequence); exposure and gain
    stereo_camera.py    the pair: grab both, then retrieve; timestamps, skew, frozen frames
    host_cameras.py     a RobotAdapter whose captures come from the host's cameras
    recording.py        RecordingAdapter (--record DIR) and ReplayAdapter (--replay DIR)
    camera_service.py   `hostpc camera serve`: the pair over the zerocal protocol
    calibrate_options.py  the `hostpc calibrate` options of this package

Images are 8-bit grey (H, W); times in seconds; see docs/hardware.md.
"""
