"""scripts/render_frames.py: reference frames rendered around a body, one row per frame, one column per view."""

from __future__ import annotations

import os
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wristmimic.synth.generate import generate

SCRIPT_PATH = Path(__file__).parents[1] / "scripts" / "render_frames.py"


def _gl_available() -> str | None:
    """None where an offscreen OpenGL context opens (MUJOCO_GL=egl by default), else why not."""
    code = "import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco/>'); mujoco.Renderer(m, 8, 8).render()"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    return None if r.returncode == 0 else (r.stderr.strip().splitlines() or ["no OpenGL"])[-1]


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("render") / "synth.h5", seed=0, variants=("default",))


def test_renders_one_row_per_frame_and_one_column_per_view(synth: Path, tmp_path: Path) -> None:
    why = _gl_available()
    if why:
        pytest.skip(f"no offscreen OpenGL context for MuJoCo's renderer: {why}")
    out = tmp_path / "frames.png"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    args = [str(synth), "--scene", "synth_default", "--frames", "0,60", "--body", "R_Wrist"]
    r = subprocess.run(
        [sys.executable, str(SCRIPT_PATH), *args, "--views", "0:-20,90:-89,180:0", "--size", "48", "-o", str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    from PIL import Image

    img = np.asarray(Image.open(out))
    assert img.shape == (2 * 48, 3 * 48, 3)
    assert img.std() > 5  # a picture, not a blank frame
    assert not np.array_equal(img[:48], img[48:])  # frame 60 (the box held) differs from frame 0
    bad = subprocess.run(
        [sys.executable, str(SCRIPT_PATH), *args[:-1], "nope", "-o", str(tmp_path / "bad.png")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bad.returncode != 0 and "no body 'nope'" in bad.stderr and not (tmp_path / "bad.png").exists()


def test_bad_views_are_refused_with_one_line() -> None:
    script = runpy.run_path(str(SCRIPT_PATH))
    assert script["parse_views"]("0:-20,90:5") == [(0.0, -20.0), (90.0, 5.0)]
    with pytest.raises(SystemExit, match="azimuth:elevation"):
        script["parse_views"]("0,-20")


def test_no_opengl_context_is_one_line_naming_mujoco_gl(synth: Path, tmp_path: Path) -> None:
    """Without MUJOCO_GL and without a display (GLFW cannot open a window), the script says to set MUJOCO_GL."""
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        pytest.skip("a display is present: GLFW may open a context")
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    out = tmp_path / "frames.png"
    args = [str(synth), "--scene", "synth_default", "--frames", "0", "--body", "R_Wrist", "--size", "16"]
    r = subprocess.run(
        [sys.executable, str(SCRIPT_PATH), *args, "-o", str(out)], env=env, capture_output=True, text=True, timeout=300
    )
    last = r.stderr.strip().splitlines()[-1]
    assert r.returncode != 0 and last.startswith("error: no OpenGL context") and "MUJOCO_GL=egl" in last
    assert not out.exists()
