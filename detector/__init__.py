"""The camera's detector: RGB-D frames (or photos) to the detections the controllers read.

Its own package and process, like ``control``: pure modules that import ``interfaces``, numpy,
scipy, Pillow and onnxruntime, never ``twin``, ``control``, ``experiments`` or rclpy. Three edge
modules do: :mod:`detector.ros_node` and :mod:`detector.cmd_node` (rclpy: ``cdw-twin
detector-node``) and :mod:`detector.bench_perception` (the twin's renderer: ``cdw-twin bench
perception``); nothing else imports them.

- :func:`detector.factory.detector_for`: the detector of a dataset and a camera set, its
  classifier trained on the dataset's own photos (:mod:`detector.training_set`), cached on disk
  and per process (what the twin and the node build).
- :mod:`detector.frames_in`: image messages to arrays, colour and depth paired by stamp,
  detections to message fields (the node's logic, without ROS).
- :class:`detector.detector.Detector`: constructed once (configuration, classifier or a
  plug-in segmenter, the belt's height); ``detect(frame)`` per
  :class:`interfaces.camera.RgbdFrame` gives a :class:`detector.detector.DetectorOutput`
  (mode, label image, instances with image and world geometry) whose ``detection_frame()`` is
  the :class:`interfaces.detections.DetectionFrame` the controllers consume.
- :mod:`detector.instances`: the plug-in point, ``Segmenter`` (image -> masks + class +
  score), which the baseline (:mod:`detector.baseline`) and the ONNX adapter
  (:mod:`detector.onnx_segmenter`) implement.
- :mod:`detector.classifier`: the colour/texture classifier, trained on a dataset's own photos,
  saved as JSON.
- :mod:`detector.score`: perception scored against ground truth (recall, precision, class
  accuracy, confusion, centroid and yaw errors).
- :mod:`detector.bench_photos`: the detector on a dataset's real photos against their polygons
  (``python -m detector photos DATASET --json``); :mod:`detector.bench_perception`: those
  photos beside the twin's renders of the same pieces; :mod:`detector.bench_speed`: time per
  frame. ``docs/detector.md`` says how to use all of it and how to plug in your own model.
"""
