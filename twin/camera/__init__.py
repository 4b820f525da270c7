"""The twin's RGB-D cameras: rendering colour, depth and instance ids of a running twin.

- :class:`twin.camera.rig.CameraRig` renders the cameras of a :class:`twin.sim.Twin` into
  :class:`interfaces.camera.RgbdFrame` (the stepping loop calls ``capture`` at each camera's
  rate);
- :mod:`twin.camera.gl`: the fast renderer, OpenGL through moderngl on EGL (Mesa's llvmpipe
  without a GPU); :mod:`twin.camera.tiny`: the fallback, PyBullet's TinyRenderer;
  :mod:`twin.camera.choose` picks one and says so once;
- :mod:`twin.camera.depth_noise`: the sensor's depth errors;
- :func:`twin.camera.schedule.frame_due`: which steps take a camera's frame at its rate;
- ``cdw-twin bench render --json`` (:mod:`twin.camera.bench`): frame and capture times.
"""
