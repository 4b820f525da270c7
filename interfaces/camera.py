"""RGB-D cameras over the belt: their description, pinhole model, frames and pixel geometry.

What the cell file declares (:class:`RgbdCameraSpec`), what the twin renders and a real camera
delivers (:class:`RgbdFrame`), and the arithmetic both sides of a detector need (deprojecting a
depth image to points, projecting points to pixels), free of any renderer and of ROS.

Conventions, as ROS users expect them:

- Frames (REP 103 / 105): a camera ``NAME`` has a body frame ``NAME_link`` (x forward, y left,
  z up) and an optical frame ``NAME_optical_frame`` (z forward along the view, x right in the
  image, y down in the image). Both are static children of ``world``; ``/tf_static`` carries
  them.
- Depth (REP 118): metres along the optical z axis, ``float32``; NaN where the sensor returned
  nothing (dropout, out of range), as ``sensor_msgs/Image`` ``32FC1`` carries it.
- Intrinsics: the ``plumb_bob`` model with zero distortion; ``K = [fx 0 cx; 0 fy cy; 0 0 1]``,
  pixel centres at integer coordinates (``u = fx x / z + cx``, column ``u``, row ``v``).
- Poses are named ``aMb``: the 4x4 homogeneous transform of frame ``b`` in frame ``a``
  (``worldMoptical`` maps optical-frame points to world points).

The default camera looks straight down over the belt with image rows increasing along the
belt's travel (+x) and columns along +y: the orientation of the source photos in meshgen's
belt frame (+x image down, +y image right), so a render of a piece looks like its photo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from interfaces.errors import require

__all__ = [
    "CameraInfoFields",
    "DepthNoise",
    "Intrinsics",
    "RgbdCameraSpec",
    "RgbdFrame",
    "StaticFrame",
    "belt_view_x_m",
    "camera_info",
    "deproject",
    "linkMoptical",
    "project",
    "rpy_matrix",
    "sees_point",
    "static_frames",
    "world_points",
]

OPTICAL_SUFFIX = "_optical_frame"
LINK_SUFFIX = "_link"


def rpy_matrix(rpy_rad: tuple[float, float, float]) -> np.ndarray:
    """The rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` of URDF's and tf's ``rpy``, ``(3, 3)``."""
    roll, pitch, yaw = rpy_rad
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    rotation: np.ndarray = rz @ ry @ rx
    return rotation


def linkMoptical() -> np.ndarray:  # noqa: N802 (a pose name, aMb)
    """The optical frame in the camera's body frame (REP 103: rpy ``(-pi/2, 0, -pi/2)``),
    ``(4, 4)``."""
    m = np.eye(4)
    m[:3, :3] = rpy_matrix((-math.pi / 2, 0.0, -math.pi / 2))
    return m


@dataclass(frozen=True, kw_only=True)
class Intrinsics:
    """A pinhole camera's image size and focal lengths, pixels (``plumb_bob``, no distortion)."""

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float

    def __post_init__(self) -> None:
        require(self.width_px > 0, "width_px", self.width_px, "must be a positive pixel count")
        require(self.height_px > 0, "height_px", self.height_px, "must be a positive pixel count")
        for key in ("fx_px", "fy_px", "cx_px", "cy_px"):
            value = getattr(self, key)
            require(math.isfinite(value), key, value, "must be finite")
        require(self.fx_px > 0 and self.fy_px > 0, "fx_px", self.fx_px, "must be positive")

    @classmethod
    def from_hfov(cls, width_px: int, height_px: int, hfov_deg: float) -> Intrinsics:
        """Square pixels, the principal point at the image centre, ``hfov_deg`` across."""
        require(0.0 < hfov_deg < 180.0, "hfov_deg", hfov_deg, "must lie in (0, 180)")
        f = 0.5 * width_px / math.tan(math.radians(hfov_deg) / 2.0)
        return cls(
            width_px=width_px,
            height_px=height_px,
            fx_px=f,
            fy_px=f,
            cx_px=(width_px - 1) / 2.0,
            cy_px=(height_px - 1) / 2.0,
        )

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the matrix's name in CameraInfo)
        """``(3, 3)`` camera matrix."""
        return np.array(
            [[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]]
        )

    @property
    def vfov_rad(self) -> float:
        """The vertical field of view."""
        return 2.0 * math.atan(0.5 * self.height_px / self.fy_px)

    def camera_info(self) -> dict[str, object]:
        """The fields of ``sensor_msgs/CameraInfo`` (``plumb_bob``, zero distortion, ``R = I``,
        ``P = [K | 0]``) as plain values, row-major."""
        k = self.K
        p = np.zeros((3, 4))
        p[:, :3] = k
        return {
            "width": self.width_px,
            "height": self.height_px,
            "distortion_model": "plumb_bob",
            "d": [0.0] * 5,
            "k": [float(v) for v in k.ravel()],
            "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "p": [float(v) for v in p.ravel()],
        }


@dataclass(frozen=True, kw_only=True)
class DepthNoise:
    """A structured-light / stereo depth sensor's errors (all zero: a perfect sensor).

    - ``std_m`` at ``z``: ``base_std_m + quadratic_std_per_m * z**2`` (error grows with the
      square of the distance, as a stereo or structured-light sensor's);
    - ``edge_dropout``: probability that a pixel on a depth discontinuity larger than
      ``edge_jump_m`` returns nothing (shadowing, mixed pixels);
    - ``dropout``: probability that any other pixel returns nothing;
    - ``quantum_m``: depth resolution (0: none).
    """

    base_std_m: float = 0.0005
    quadratic_std_per_m: float = 0.0015
    edge_jump_m: float = 0.01
    edge_dropout: float = 0.3
    dropout: float = 0.002
    quantum_m: float = 0.0005

    def __post_init__(self) -> None:
        for key in ("base_std_m", "quadratic_std_per_m", "edge_jump_m", "quantum_m"):
            value = getattr(self, key)
            require(math.isfinite(value) and value >= 0.0, f"noise.{key}", value, "must be >= 0")
        for key in ("edge_dropout", "dropout"):
            value = getattr(self, key)
            require(0.0 <= value < 1.0, f"noise.{key}", value, "must lie in [0, 1)")

    @classmethod
    def none(cls) -> DepthNoise:
        """A perfect depth sensor."""
        return cls(
            base_std_m=0.0,
            quadratic_std_per_m=0.0,
            edge_dropout=0.0,
            dropout=0.0,
            quantum_m=0.0,
        )


@dataclass(frozen=True, kw_only=True)
class RgbdCameraSpec:
    """One RGB-D camera of a cell: where it is, what it sees, how often and how well.

    ``position_m`` and ``rpy_rad`` are the pose of its body frame ``NAME_link`` in the world
    (REP 103: x forward along the view). The default looks straight down from 1.2 m over the
    reference belt's centreline, upstream of its pick window, rows along +x (see the module).
    """

    name: str = "camera"
    position_m: tuple[float, float, float] = (-0.9, 0.5, 1.2)
    rpy_rad: tuple[float, float, float] = (0.0, math.pi / 2, math.pi)
    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 60.0
    rate_hz: float = 15.0
    depth_min_m: float = 0.3
    depth_max_m: float = 3.0
    noise: DepthNoise = field(default_factory=DepthNoise)

    def __post_init__(self) -> None:
        require(
            bool(self.name) and self.name.replace("_", "").isalnum(),
            "camera.name",
            self.name,
            "must be a non-empty name of letters, digits and underscores (a frame name)",
        )
        require(
            all(math.isfinite(v) for v in (*self.position_m, *self.rpy_rad)),
            f"cameras.{self.name}.position_m",
            self.position_m,
            "position and rpy must be finite",
        )
        require(0 < self.rate_hz <= 120, f"cameras.{self.name}.rate_hz", self.rate_hz, "(0, 120]")
        require(
            0 < self.depth_min_m < self.depth_max_m,
            f"cameras.{self.name}.depth_min_m",
            self.depth_min_m,
            "must be positive and below depth_max_m",
        )
        self.intrinsics  # noqa: B018 (validates size and field of view)

    @property
    def intrinsics(self) -> Intrinsics:
        """The pinhole model of this camera."""
        return Intrinsics.from_hfov(self.width_px, self.height_px, self.hfov_deg)

    @property
    def link_frame(self) -> str:
        """The body frame's name (``NAME_link``)."""
        return self.name + LINK_SUFFIX

    @property
    def optical_frame(self) -> str:
        """The optical frame's name (``NAME_optical_frame``)."""
        return self.name + OPTICAL_SUFFIX

    def worldMlink(self) -> np.ndarray:  # noqa: N802 (a pose name, aMb)
        """The body frame in the world, ``(4, 4)``."""
        m = np.eye(4)
        m[:3, :3] = rpy_matrix(self.rpy_rad)
        m[:3, 3] = self.position_m
        return m

    def worldMoptical(self) -> np.ndarray:  # noqa: N802 (a pose name, aMb)
        """The optical frame in the world, ``(4, 4)``."""
        m: np.ndarray = self.worldMlink() @ linkMoptical()
        return m


@dataclass(frozen=True, eq=False)
class RgbdFrame:
    """One capture of one camera.

    ``rgb`` ``(H, W, 3) uint8``; ``depth_m`` ``(H, W) float32``, metres along the optical axis,
    NaN where nothing was returned; ``instance_ids`` ``(H, W) int32``, the twin's object id seen
    at each pixel (0: belt, robot or background), ground truth for scoring only and ``None`` from
    a real camera; ``worldMoptical`` ``(4, 4)``; ``stamp_s`` the exposure time (sim clock).
    """

    camera: str
    stamp_s: float
    rgb: np.ndarray
    depth_m: np.ndarray
    intrinsics: Intrinsics
    worldMoptical: np.ndarray
    instance_ids: np.ndarray | None = None


def deproject(depth_m: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Every pixel's point in the optical frame, ``(H, W, 3)`` m (NaN where depth is NaN)."""
    h, w = depth_m.shape
    v, u = np.mgrid[0:h, 0:w]
    z = depth_m.astype(np.float64)
    x = (u - intrinsics.cx_px) / intrinsics.fx_px * z
    y = (v - intrinsics.cy_px) / intrinsics.fy_px * z
    return np.stack((x, y, z), axis=-1)


def world_points(frame: RgbdFrame) -> np.ndarray:
    """Every pixel's point in the world frame, ``(H, W, 3)`` m (NaN where depth is NaN)."""
    points = deproject(frame.depth_m, frame.intrinsics)
    rotation = frame.worldMoptical[:3, :3]
    world: np.ndarray = points @ rotation.T + frame.worldMoptical[:3, 3]
    return world


def project(
    points_world_m: np.ndarray,
    intrinsics: Intrinsics,
    worldMoptical: np.ndarray,  # noqa: N803 (a pose name, aMb)
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(n, 3)`` to pixel coordinates ``(n, 2)`` (column ``u``, row ``v``) and
    their depth ``(n,)`` along the optical axis (points behind the camera: depth <= 0)."""
    opticalMworld = np.linalg.inv(worldMoptical)  # noqa: N806 (a pose name, aMb)
    pts = np.asarray(points_world_m, dtype=np.float64) @ opticalMworld[:3, :3].T
    pts += opticalMworld[:3, 3]
    z = pts[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx_px * pts[:, 0] / z + intrinsics.cx_px
        v = intrinsics.fy_px * pts[:, 1] / z + intrinsics.cy_px
    return np.stack((u, v), axis=-1), z


@dataclass(frozen=True, kw_only=True)
class CameraInfoFields:
    """The fields of one camera's ``sensor_msgs/CameraInfo`` as plain values (row-major): the
    ``plumb_bob`` model with zero distortion ``d`` (5), ``k`` (9), ``r = I`` (9), ``p = [K | 0]``
    (12), stamped in ``frame_id`` (the camera's optical frame)."""

    frame_id: str
    width: int
    height: int
    distortion_model: str
    d: tuple[float, ...]
    k: tuple[float, ...]
    r: tuple[float, ...]
    p: tuple[float, ...]


@dataclass(frozen=True, kw_only=True)
class StaticFrame:
    """One static transform for ``/tf_static``: frame ``child`` in frame ``parent``, a
    translation (m) and a unit quaternion ``(x, y, z, w)``."""

    parent: str
    child: str
    translation_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]


def camera_info(spec: RgbdCameraSpec) -> CameraInfoFields:
    """The ``CameraInfo`` of camera ``spec`` (see :class:`CameraInfoFields`)."""
    k = spec.intrinsics.K
    p = np.zeros((3, 4))
    p[:, :3] = k
    return CameraInfoFields(
        frame_id=spec.optical_frame,
        width=spec.width_px,
        height=spec.height_px,
        distortion_model="plumb_bob",
        d=(0.0,) * 5,
        k=tuple(float(v) for v in k.ravel()),
        r=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        p=tuple(float(v) for v in p.ravel()),
    )


def _quaternion_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion ``(x, y, z, w)`` of a rotation matrix ``(3, 3)`` (w >= 0)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = float(np.trace(m))
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
        v = [0.0, 0.0, 0.0]
        v[i] = s / 4
        v[j] = (m[j, i] + m[i, j]) / s
        v[k] = (m[k, i] + m[i, k]) / s
        q = (v[0], v[1], v[2], (m[k, j] - m[j, k]) / s)
    quat = np.array(q, dtype=np.float64)
    quat /= np.linalg.norm(quat)
    if quat[3] < 0.0:
        quat = -quat
    return (float(quat[0]), float(quat[1]), float(quat[2]), float(quat[3]))


def static_frames(spec: RgbdCameraSpec, world_frame: str = "world") -> tuple[StaticFrame, ...]:
    """The camera's two static frames (REP 103 / 105): ``NAME_link`` in ``world_frame`` (its
    pose in the cell file) and ``NAME_optical_frame`` in ``NAME_link`` (rpy ``(-pi/2, 0,
    -pi/2)``)."""
    worldMlink = spec.worldMlink()  # noqa: N806 (a pose name, aMb)
    optical = linkMoptical()
    return (
        StaticFrame(
            parent=world_frame,
            child=spec.link_frame,
            translation_m=(
                float(worldMlink[0, 3]),
                float(worldMlink[1, 3]),
                float(worldMlink[2, 3]),
            ),
            rotation_xyzw=_quaternion_xyzw(worldMlink[:3, :3]),
        ),
        StaticFrame(
            parent=spec.link_frame,
            child=spec.optical_frame,
            translation_m=(0.0, 0.0, 0.0),
            rotation_xyzw=_quaternion_xyzw(optical[:3, :3]),
        ),
    )


def sees_point(spec: RgbdCameraSpec, point_m: tuple[float, float, float]) -> bool:
    """Whether world point ``point_m`` projects inside camera ``spec``'s image at a depth within
    its range (nothing in between considered)."""
    uv, z = project(np.array([point_m], dtype=np.float64), spec.intrinsics, spec.worldMoptical())
    u, v = float(uv[0, 0]), float(uv[0, 1])
    k = spec.intrinsics
    return (
        spec.depth_min_m <= float(z[0]) <= spec.depth_max_m
        and -0.5 <= u <= k.width_px - 0.5
        and -0.5 <= v <= k.height_px - 0.5
    )


def belt_view_x_m(
    spec: RgbdCameraSpec, *, centre_y_m: float, surface_z_m: float, step_m: float = 0.01
) -> tuple[float, float] | None:
    """The x interval of the belt's centreline (``y = centre_y_m`` on ``z = surface_z_m``)
    that camera ``spec`` sees, to ``step_m`` (None: it sees none of it within 50 m of itself)."""
    x0 = spec.position_m[0]
    xs = np.arange(x0 - 50.0, x0 + 50.0 + step_m / 2, step_m)
    points = np.stack((xs, np.full_like(xs, centre_y_m), np.full_like(xs, surface_z_m)), axis=1)
    uv, z = project(points, spec.intrinsics, spec.worldMoptical())
    k = spec.intrinsics
    with np.errstate(invalid="ignore"):
        seen = (
            (z >= spec.depth_min_m)
            & (z <= spec.depth_max_m)
            & (uv[:, 0] >= -0.5)
            & (uv[:, 0] <= k.width_px - 0.5)
            & (uv[:, 1] >= -0.5)
            & (uv[:, 1] <= k.height_px - 0.5)
        )
    if not seen.any():
        return None
    return float(xs[seen].min()), float(xs[seen].max())
