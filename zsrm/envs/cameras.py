"""Where world points land in a camera's image: pinhole projection with MuJoCo's camera pose.

Pixel coordinates are ``(x, row)``: x to the right, row down, in pixel-index units (the centre
of the top-left pixel is ``(0, 0)``, of the bottom-right one ``(size - 1, size - 1)``), the
frame of ``env.render_cameras`` images and of Grad-CAM coordinates.

>>> import gymnasium as gym, zsrm.envs
>>> env = gym.make("zsrm/Tabletop-v0", task="stack", cameras=("front",))
>>> obs, info = env.reset(seed=0)
>>> xy = project(env.unwrapped, "front", info["object_positions"]["red"], size=64)
>>> xy.shape
(2,)
"""
from __future__ import annotations

import mujoco
import numpy as np

from zsrm.envs.base import TABLE_TOP
from zsrm.tasks.relations import CAMERAS, TABLE_PLANE_CAMERAS


def _camera_id(model: mujoco.MjModel, camera: str) -> int:
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if cam < 0:
        raise ValueError(f"unknown camera {camera!r}; known cameras: {', '.join(CAMERAS)}")
    return cam


def camera_frame(env, camera: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Camera position (3,), rotation (3, 3) whose columns are the camera's x (right), y (up)
    and z (backward) axes in world coordinates, and the vertical field of view in degrees."""
    base = getattr(env, "unwrapped", env)
    cam = _camera_id(base.model, camera)
    # cam_xpos/cam_xmat are only filled by mj_forward/mj_step; recompute them from the pose the
    # model gives (the scenes' cameras are fixed to the world body).
    pos = base.data.cam_xpos[cam].copy()
    rot = base.data.cam_xmat[cam].reshape(3, 3).copy()
    if not np.any(rot):
        mujoco.mj_kinematics(base.model, base.data)
        mujoco.mj_camlight(base.model, base.data)
        pos = base.data.cam_xpos[cam].copy()
        rot = base.data.cam_xmat[cam].reshape(3, 3).copy()
    return pos, rot, float(base.model.cam_fovy[cam])


def project(env, camera: str, xyz, size: int) -> np.ndarray:
    """World points ``(..., 3)`` to pixel coordinates ``(..., 2)`` (x right, row down) in a
    square ``size`` x ``size`` image of ``camera``. Points behind the camera give NaN."""
    pos, rot, fovy = camera_frame(env, camera)
    p = np.asarray(xyz, dtype=np.float64)
    local = (p - pos) @ rot  # coordinates along the camera's x, y, z axes
    depth = -local[..., 2]  # MuJoCo cameras look down their -z axis
    focal = 0.5 * size / np.tan(np.deg2rad(fovy) / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 0.5 * size + focal * local[..., 0] / depth - 0.5
        v = 0.5 * size - focal * local[..., 1] / depth - 0.5
    out = np.stack([u, v], axis=-1)
    out[depth <= 0] = np.nan
    return out


def object_width_px(env, camera: str, size: int, half_size: float | None = None,
                    at=(0.0, 0.0, None)) -> float:
    """Width in pixels of one object (2 * ``half_size`` metres, the scene's object by default)
    seen by ``camera``, measured along the image's x axis at the table centre."""
    base = getattr(env, "unwrapped", env)
    half = base.object_half_size if half_size is None else half_size
    centre = np.array([at[0], at[1], TABLE_TOP + half if at[2] is None else at[2]])
    _, rot, _ = camera_frame(base, camera)
    right = rot[:, 0]
    a, b = project(base, camera, np.stack([centre - half * right, centre + half * right]), size)
    return float(np.linalg.norm(a - b))


def table_homography(env, camera: str, size: int, height: float | None = None) -> np.ndarray:
    """3x3 matrix taking pixel coordinates ``(x, row, 1)`` of a point at ``height`` (the centre of
    an object resting on the table by default) to its table coordinates ``(x, y, 1)`` in metres, up to scale.

    This is camera calibration, not state: it lets the labeler read "close to" on the tilted
    camera in metres, where pixel distances shrink by half from the near to the far edge of the
    table and the table's depth shows at sin 45 deg of its length.
    """
    base = getattr(env, "unwrapped", env)
    pos, rot, fovy = camera_frame(base, camera)
    z = TABLE_TOP + base.rest_height if height is None else height
    # (X, Y, 1) -> camera-axis coordinates, then -> pixels
    to_camera = np.column_stack([rot.T[:, 0], rot.T[:, 1], rot.T @ (np.array([0.0, 0.0, z]) - pos)])
    return np.linalg.inv(_to_pixels(size, fovy) @ to_camera)


def _to_pixels(size: int, fovy: float) -> np.ndarray:
    """3x3: camera-axis coordinates -> ``(u w, v w, w)``, with w the depth (see :func:`project`)."""
    focal = 0.5 * size / np.tan(np.deg2rad(fovy) / 2)
    c = 0.5 * size - 0.5
    return np.array([[focal, 0.0, -c], [0.0, -focal, -c], [0.0, 0.0, -1.0]])


def table_homographies(env, size: int, cameras=CAMERAS) -> dict[str, list[list[float]]]:
    """:func:`table_homography` of each camera that reads the table plane (JSON-ready)."""
    return {cam: table_homography(env, cam, size).tolist() for cam in cameras if cam in TABLE_PLANE_CAMERAS}


def apply_homography(h, xy) -> np.ndarray:
    """``(..., 2)`` points through a 3x3 homography (NaN stays NaN)."""
    xy = np.asarray(xy, dtype=np.float64)
    out = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ np.asarray(h, np.float64).T
    return out[..., :2] / out[..., 2:]


def pixel_rays(env, camera: str, size: int) -> dict[str, list]:
    """Calibration, not state: the camera's centre (``origin``, 3) and the 3x3 ``direction`` map taking
    pixel coordinates ``(x, row, 1)`` to the world direction of the ray through that pixel
    (:func:`triangulate` reads two cameras' rays). JSON-ready."""
    pos, rot, fovy = camera_frame(env, camera)
    # pixels -> a camera-axis point at depth 1 on the ray, then -> world axes
    return {"origin": pos.tolist(), "direction": (rot @ np.linalg.inv(_to_pixels(size, fovy))).tolist()}


def triangulate(rays_a: dict, xy_a, rays_b: dict, xy_b) -> np.ndarray:
    """``(N, 3)`` world points seen at pixels ``xy_a`` (N, 2) of one camera and ``xy_b`` of another
    (their :func:`pixel_rays`): the midpoint of the two rays' closest approach; NaN where a pixel is."""
    def ray(rays, xy):
        xy = np.asarray(xy, np.float64)
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ np.asarray(rays["direction"]).T
        return np.asarray(rays["origin"], np.float64), d / np.linalg.norm(d, axis=-1, keepdims=True)

    (pa, da), (pb, db) = ray(rays_a, xy_a), ray(rays_b, xy_b)
    w, b = pa - pb, np.sum(da * db, axis=-1)
    d, e = da @ w, db @ w
    with np.errstate(divide="ignore", invalid="ignore"):  # unit directions; parallel rays give NaN
        s, t = (b * e - d) / (1 - b * b), (e - b * d) / (1 - b * b)
    return 0.5 * (pa + s[..., None] * da + pb + t[..., None] * db)


def triangulate_rays(rays: list[dict], xys: list) -> np.ndarray:
    """``(..., 3)`` world points seen at pixels ``xys[i]`` (..., 2) of cameras ``rays[i]`` (their
    :func:`pixel_rays`, two or more): the point nearest all the rays in the least-squares sense (two
    rays: :func:`triangulate`'s midpoint); NaN where a pixel is."""
    a = b = 0.0
    for r, xy in zip(rays, xys):
        xy = np.asarray(xy, np.float64)
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ np.asarray(r["direction"]).T
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        m = np.eye(3) - d[..., :, None] * d[..., None, :]  # projects onto the plane normal to the ray
        a, b = a + m, b + m @ np.asarray(r["origin"], np.float64)
    ok = np.isfinite(a).all(axis=(-2, -1)) & np.isfinite(b).all(axis=-1)
    out = np.full(np.shape(b), np.nan)
    out[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    return out


def object_pixels(env, cameras=CAMERAS, size: int | None = None) -> dict[str, dict[str, np.ndarray]]:
    """True pixel coordinates of every object of a scene: ``{camera: {colour: (x, row)}}``."""
    base = getattr(env, "unwrapped", env)
    size = size or base.image_size
    positions = base.object_positions()
    return {cam: {c: project(base, cam, p, size) for c, p in positions.items()} for cam in cameras}
