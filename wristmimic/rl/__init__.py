"""PPO training of per-scene WristMimic policies: storage, networks, PPO, runner, checkpoints, policy loading.

>>> from wristmimic.rl import TrainSpec, start_run, load_policy
"""

from wristmimic.rl.config import PRESETS, PPOConfig, preset
from wristmimic.rl.policy import Policy, load_policy
from wristmimic.rl.train import TrainResult, TrainSpec, default_run_dir, resume_run, start_run

__all__ = [
    "PRESETS",
    "PPOConfig",
    "Policy",
    "TrainResult",
    "TrainSpec",
    "default_run_dir",
    "load_policy",
    "preset",
    "resume_run",
    "start_run",
]
