"""The twin's RGB-D cameras: rendering colour, depth and instance ids of a running twin.

- :class:`twin.camera.rig.CameraRig` renders the cameras of a running twin into
  :class:`interfaces.camera.RgbdFrame` (the stepping loop calls ``capture`` at each camera's
  rate);
- :mod:`twin.camera.gl`: the fast renderer, OpenGL through moderngl on EGL (Mesa's llvmpipe
  without a GPU); :mod:`twin.camera.tiny`: the fallback, PyBullet's TinyRenderer;
  :mod:`twin.camera.choose` picks one and says so once;
- :mod:`twin.camera.depth_noise`: the sensor's depth errors;
- :func:`twin.camera.schedule.frame_due`: which steps take a camera's frame at its rate;
- :mod:`twin.camera.filters`: the belt's region of interest and the robot self-filter applied
  to every frame before its detector;
- ``cdw-twin bench render --json`` (:mod:`twin.bench_render`): frame and capture times.

The cameras read a running twin through :class:`twin.sim_view.CameraSim` and never import the
sim (:mod:`twin.sim`), which steps them through :mod:`twin.perception_source`.
"""
