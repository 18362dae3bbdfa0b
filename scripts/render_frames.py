"""Render reference frames of a scene as one PNG: the humanoid and objects posed on the reference, collision geometry
only (object hulls translucent, visual meshes hidden), seen from several directions around one body.

Usage:  MUJOCO_GL=egl python scripts/render_frames.py DATASET.h5 --scene SEQ --frames 40,44 --body jRightWrist
        [--views 0:-20,90:-20,180:-20,270:-20,0:-89] [--distance 0.3] [--size 320]
        [--set scene_config.FIELD=VALUE ...] -o frames.png

One row per frame, one column per view (``azimuth:elevation`` in degrees, MuJoCo's free camera looking at the body).
What a viewer cannot show from a recording: how the hand's capsules sit against the hulls the physics collides
with. On ``s110_move_kettle`` it shows the reference's right fingers crossing the outer bar of the kettle's loop
handle, inside its hulls (``reports/kettle_grasp_20261207/``). Needs an OpenGL context:
set ``MUJOCO_GL=egl`` (or ``osmesa``) on a machine without a display.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import mujoco
import numpy as np
import torch
from PIL import Image

from wristmimic.env.config import EnvConfig
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.config import to_jsonable
from wristmimic.rl.overrides import apply_overrides
from wristmimic.safe_io import atomic_output
from wristmimic.scene import SceneConfig, scene_config_from_dict


def parse_views(text: str) -> list[tuple[float, float]]:
    """``"az:el,az:el"`` -> [(az, el), ...] (degrees)."""
    try:
        views = [(float(a), float(e)) for a, e in (v.split(":") for v in text.split(","))]
    except ValueError:
        raise SystemExit(
            f"error: --views {text!r}: expected azimuth:elevation pairs in degrees, e.g. 0:-20,90:-20"
        ) from None
    return views


def render(
    dataset: Path,
    scene: str,
    frames: list[int],
    body: str,
    views: list[tuple[float, float]],
    distance: float = 0.3,
    size: int = 320,
    overrides: list[str] | None = None,
) -> np.ndarray:
    """(rows x size, columns x size, 3) uint8 image: one row per frame, one column per view."""
    cfg = apply_overrides({"scene_config": to_jsonable(SceneConfig())}, overrides or [])["scene_config"]
    env = WristMimicEnv.from_file(dataset, scene, 1, EnvConfig(), scene_config_from_dict(cfg), nthread=1)
    m = env.scene.model
    bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
    if bid < 0:
        names = ", ".join(m.body(i).name for i in range(1, m.nbody))
        raise SystemExit(f"error: scene {scene} has no body {body!r}; bodies: {names}")
    T = env.ref.num_frames
    if not frames or any(not 0 <= f < T for f in frames):
        raise SystemExit(f"error: --frames {frames}: need frames in 0..{T - 1}")
    m.vis.global_.offwidth = max(m.vis.global_.offwidth, size)
    m.vis.global_.offheight = max(m.vis.global_.offheight, size)
    d = mujoco.MjData(m)
    opt = mujoco.MjvOption()
    opt.geomgroup[:] = [1, 1, 0, 1, 0, 0]  # group 2: the objects' visual meshes
    qpos, _ = env.reference_state(torch.as_tensor(frames))
    rows = []
    with _renderer(m, size) as r:
        for q in qpos.numpy():
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
            row = []
            for az, el in views:
                cam = mujoco.MjvCamera()
                cam.lookat[:], cam.distance, cam.azimuth, cam.elevation = d.xpos[bid], distance, az, el
                r.update_scene(d, cam, opt)
                row.append(r.render())
            rows.append(np.concatenate(row, axis=1))
    env.close()
    return np.concatenate(rows, axis=0)


def _renderer(m: mujoco.MjModel, size: int) -> mujoco.Renderer:
    """An offscreen renderer, or a one-line error naming MUJOCO_GL when no OpenGL context can be made (a machine
    without a display needs ``MUJOCO_GL=egl`` or ``osmesa``; the default, GLFW, needs an X display)."""
    try:
        return mujoco.Renderer(m, size, size)
    except Exception as e:  # mujoco.FatalError from mjr_makeContext, or the GL backend's own import error
        gl = os.environ.get("MUJOCO_GL", "unset: GLFW, which needs a display")
        raise SystemExit(
            f"error: no OpenGL context for rendering (MUJOCO_GL {gl}): run with MUJOCO_GL=egl (or osmesa) "
            f"({type(e).__name__}: {str(e).splitlines()[0][:120]})"
        ) from None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--frames", required=True, help="comma-separated reference frames, e.g. 40,44")
    ap.add_argument("--body", required=True, help="MuJoCo body the cameras look at, e.g. jRightWrist or R_Wrist")
    ap.add_argument("--views", default="0:-20,90:-20,180:-20,270:-20,0:-89", help="azimuth:elevation pairs (deg)")
    ap.add_argument("--distance", type=float, default=0.3, help="camera distance from the body (m)")
    ap.add_argument("--size", type=int, default=320, help="pixels per view (square)")
    ap.add_argument("--set", action="append", default=[], help="scene_config.FIELD=VALUE override (repeatable)")
    ap.add_argument("-o", "--output", type=Path, required=True, help="PNG to write")
    args = ap.parse_args()
    if any(not s.startswith("scene_config.") for s in args.set):
        raise SystemExit("error: --set: only scene_config.FIELD overrides apply here")
    try:
        frames = [int(f) for f in args.frames.split(",")]
    except ValueError:
        raise SystemExit(f"error: --frames {args.frames!r}: expected comma-separated integers") from None
    img = render(
        args.dataset, args.scene, frames, args.body, parse_views(args.views), args.distance, args.size, args.set
    )
    with atomic_output(args.output) as tmp:
        Image.fromarray(img).save(tmp, format="PNG")
    print(f"wrote {args.output}: {len(frames)} frame(s) x {img.shape[1] // args.size} view(s)")


if __name__ == "__main__":
    main()
