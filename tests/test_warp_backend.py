"""The MuJoCo Warp backend against the CPU backend: same initial states and actions -> the same observations,
rewards and terminations within stated tolerances over a short horizon.

Runs on Warp's CPU device (CI has no GPU) and, where torch sees a GPU, on CUDA too. Tolerances, measured on
``sub2_largetable_000`` (4 worlds, 8 control steps of random actions, resets included): positions agree to
~1e-5 m, rewards to ~1e-6, terminations exactly. Warp computes in float32 and finds mesh contacts with its own
GJK/EPA, so contact forces differ most; the bounds below leave an order of magnitude of room.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

pytest.importorskip("mujoco_warp", reason="MuJoCo Warp not installed (pip install 'wristmimic[warp]')")

from wristmimic.convert.common import ConvertOptions  # noqa: E402
from wristmimic.convert.intermimic import convert_intermimic  # noqa: E402
from wristmimic.env.config import EnvConfig  # noqa: E402
from wristmimic.env.vec_env import WristMimicEnv  # noqa: E402
from wristmimic.scene import SceneConfig  # noqa: E402

from synthetic import tiny_ppo_toml, write_intermimic_folder  # noqa: E402

HORIZON = 6
POS_TOL_M = 1e-3  # body and object positions
REWARD_TOL = 1e-4
OBS_MEAN_TOL = 1e-3  # mean |difference| over the observation vector
OBS_MAX_TOL = 0.1  # largest single feature difference (velocities, contact-force-driven features)

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    tmp = tmp_path_factory.mktemp("warp")
    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=40), tmp / "im.h5", options=opts)
    return tmp / "im.h5", "sub1_box_000"


# absolute actions (the mode these tolerances were measured with): random residual actions keep the hands on the
# object, where the two simulators' contact solutions drift apart fastest
CFG = EnvConfig(action_mode="absolute")


def _pair(dataset: Path, seq: str, n: int, device: str) -> tuple[WristMimicEnv, WristMimicEnv]:
    sc = SceneConfig(solver="newton", iterations=100)  # Warp has no PGS
    cpu = WristMimicEnv.from_file(dataset, seq, n, CFG, sc, seed=3, nthread=1)
    warp = WristMimicEnv.from_file(dataset, seq, n, CFG, sc, seed=3, backend="warp", backend_options={"device": device})
    return cpu, warp


def _compare(cpu: WristMimicEnv, warp: WristMimicEnv, frames: list[int]) -> dict[str, float]:
    """Step both with the same actions from the same reference frames; assert the tolerances; return the
    worst differences seen."""
    n = cpu.num_worlds
    start = torch.tensor(frames)
    oc, _ = cpu.reset(start_frames=start)
    ow, _ = warp.reset(start_frames=start)
    assert warp.device.type == torch.device(warp.backend.device).type
    worst = {"obs_max": (oc - ow.cpu()).abs().max().item(), "pos": 0.0, "reward": 0.0}
    gen = torch.Generator().manual_seed(0)
    for _ in range(HORIZON):
        a = 0.3 * torch.randn(n, cpu.action_size, generator=gen)
        oc, rc, tc, trc, ic = cpu.step(a)
        ow, rw, tw, trw, iw = warp.step(a)
        assert torch.equal(tc, tw.cpu()), "terminations differ"
        assert torch.equal(trc, trw.cpu()), "truncations differ"
        assert torch.equal(ic["termination_reason"], iw["termination_reason"].cpu())
        sc, sw = cpu.sim_state(), warp.sim_state()
        pos = max(
            (sc.body_pos - sw.body_pos.cpu()).abs().max().item(), (sc.obj_pos - sw.obj_pos.cpu()).abs().max().item()
        )
        d = (oc - ow.cpu()).abs()
        worst = {
            "obs_max": max(worst["obs_max"], d.max().item()),
            "obs_mean": max(worst.get("obs_mean", 0.0), d.mean().item()),
            "pos": max(worst["pos"], pos),
            "reward": max(worst["reward"], (rc - rw.cpu()).abs().max().item()),
        }
        assert torch.isfinite(ow).all()
    assert worst["pos"] < POS_TOL_M, worst
    assert worst["reward"] < REWARD_TOL, worst
    assert worst["obs_mean"] < OBS_MEAN_TOL, worst
    assert worst["obs_max"] < OBS_MAX_TOL, worst
    return worst


@pytest.mark.parametrize("device", DEVICES)
def test_warp_matches_cpu_on_a_synthetic_scene(synthetic: tuple[Path, str], device: str) -> None:
    cpu, warp = _pair(*synthetic, 3, device)
    try:
        _compare(cpu, warp, [0, 5, 20])
    finally:
        cpu.close()
        warp.close()


@pytest.mark.shared_data
@pytest.mark.parametrize("device", DEVICES)
def test_warp_matches_cpu_on_a_real_scene(omomo_h5: Path, device: str) -> None:
    cpu, warp = _pair(omomo_h5, "sub2_largetable_000", 4, device)
    try:
        _compare(cpu, warp, [0, 10, 20, 40])
    finally:
        cpu.close()
        warp.close()


def test_warp_state_dict_continues_identically(synthetic: tuple[Path, str]) -> None:
    """Saving and restoring the warp environment mid-episode continues bit for bit (same device, same run)."""
    env = WristMimicEnv.from_file(*synthetic, 2, seed=1, backend="warp", backend_options={"device": "cpu"})
    try:
        env.reset()
        gen = torch.Generator().manual_seed(1)
        actions = [0.3 * torch.randn(2, env.action_size, generator=gen) for _ in range(6)]
        for a in actions[:2]:
            env.step(a)
        saved = {k: v.clone() if isinstance(v, torch.Tensor) else v for k, v in env.state_dict().items()}
        first = [env.step(a)[1] for a in actions[2:]]
        env.load_state_dict(saved)
        again = [env.step(a)[1] for a in actions[2:]]
        for x, y in zip(first, again, strict=True):
            assert torch.equal(x, y)
    finally:
        env.close()


def test_a_missing_warp_install_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from wristmimic.errors import InputError
    from wristmimic.sim import warp_backend

    monkeypatch.setitem(sys.modules, "mujoco_warp", None)  # import fails as if not installed
    with pytest.raises(InputError, match=r"wristmimic\[warp\]"):
        warp_backend.import_warp()


def test_train_resume_and_evaluate_commands_on_the_warp_backend(synthetic: tuple[Path, str], tmp_path: Path) -> None:
    """``--backend warp`` end to end on Warp's CPU device: train 2 iterations, resume to 3, evaluate; the run
    records its backend and the evaluation its settings."""
    import json

    from typer.testing import CliRunner

    from wristmimic.cli.main import app
    from wristmimic.rl import TrainSpec, preset, resume_run, start_run
    from wristmimic.rl.checkpoint import load_checkpoint

    dataset, sid = synthetic
    tiny = dict(num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(32,), critic_hidden=(32,))
    ppo = preset("cpu", **tiny, max_frames=64)
    spec = TrainSpec(dataset, sid, "wristmimic", 0, "cpu", ppo, ref_frames=20, backend="warp", device="cpu")
    run = start_run(spec, tmp_path / "run", progress=False).run_dir
    config = json.loads((run / "config.json").read_text())
    assert config["physics"] == {"backend": "warp", "device": "cpu"}
    # Warp has no PGS: a warp run of a PGS scene records the Newton it stepped with
    assert (config["scene_config"]["solver"], config["scene_config"]["iterations"]) == ("newton", 100)
    assert "warp_qpos" in load_checkpoint(run)["env"]
    r = resume_run(run, max_frames=96, progress=False)
    assert (r.status, r.iteration) == ("finished", 3)
    cli = CliRunner()
    args = ["evaluate", str(run), "-p", "quick", "-n", "5", "--num-envs", "4", "-q", "--backend", "warp"]
    res = cli.invoke(app, [*args, "--device", "cpu"])
    assert res.exit_code == 0, res.output
    summary = json.loads((run / "eval" / "quick" / "summary.json").read_text())
    assert summary["settings"]["backend"] == "warp" and summary["scenes"][0]["trials"] == 5
    bad = cli.invoke(app, ["evaluate", str(run), "-p", "quick", "-n", "5", "--backend", "gpu"])
    assert bad.exit_code == 1 and "--backend" in bad.output and "one of cpu, warp" in bad.output


def test_pipeline_trains_and_evaluates_on_the_warp_backend(synthetic: tuple[Path, str], tmp_path: Path) -> None:
    """``backend``/``device`` in the [train] and [evaluate] tables reach the run and its evaluation; an unknown
    backend is a one-line error naming the key."""
    import json

    from wristmimic.errors import InputError
    from wristmimic.pipeline import run_pipeline

    dataset, sid = synthetic
    spec = tmp_path / "warp.toml"
    body = f"""
[pipeline]
work_dir = "{tmp_path / "work"}"
[train]
dataset = "{dataset}"
scenes = ["{sid}"]
ref_frames = 12
backend = "BACKEND"
device = "cpu"
{tiny_ppo_toml(8)}
[evaluate]
protocol = "quick"
trials = 2
num_envs = 2
backend = "warp"
device = "cpu"
"""
    spec.write_text(body.replace("BACKEND", "warp"))
    ctx = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    (run,) = ctx.outputs["runs"]
    assert json.loads((run / "config.json").read_text())["physics"] == {"backend": "warp", "device": "cpu"}
    assert json.loads((run / "eval" / "quick" / "summary.json").read_text())["settings"]["backend"] == "warp"
    spec.write_text(body.replace("BACKEND", "gpu"))
    with pytest.raises(InputError, match="train.backend"):
        run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
