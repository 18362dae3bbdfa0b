"""Reference starts whose fingers do not sit inside objects (``env.starts.depenetrate``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from wristmimic.env.config import EnvConfig
from wristmimic.env.depenetrate import _Probe, depenetrate_fingers, finger_chains
from wristmimic.env.vec_env import WristMimicEnv

SEQ = "sub2_largetable_000"


@pytest.fixture(scope="module")
def sub2(omomo_h5: Path) -> WristMimicEnv:
    cfg = EnvConfig()
    return WristMimicEnv.from_file(omomo_h5, SEQ, 2, replace(cfg, starts=replace(cfg.starts, depenetrate=True)))


def test_flat_omomo_thumbs_leave_the_table_and_nothing_else_moves(sub2: WristMimicEnv) -> None:
    """OMOMO's hands are flat: its thumbs lie ~4 cm inside the table top through the carry."""
    scene = sub2.scene
    chains = finger_chains(scene)
    names = [scene.skeleton.body_names[c[0]] for c in chains]
    assert len(chains) == 10 and sum("Thumb" in n for n in names) == 2
    stats = sub2.depenetration
    assert stats is not None and stats.max_before > 0.035 and stats.frames > 100
    probe = _Probe(scene, chains)
    table = sub2._ref_qpos.numpy()
    thumbs = [k for k, n in enumerate(names) if "Thumb" in n]
    depth = np.array([probe.depths(table[t])[thumbs] for t in range(table.shape[0])])
    assert (depth[45:135] <= 0.003 + 1e-9).mean() > 0.95  # both thumbs out of the table in nearly every carry frame
    assert depth.max() < 0.6 * stats.max_before  # the grasp's first frames keep some, less deep


def test_only_finger_columns_change_and_the_search_is_deterministic(sub2: WristMimicEnv) -> None:
    scene, q_env = sub2.scene, sub2._ref_qpos.numpy()
    base = q_env.copy()  # the reference's own table: its finger angles back in place
    fingers = sub2._hinge_qpos[~sub2.residual_hinges].numpy()
    base[:, fingers] = sub2.ref.joint_angles[:, ~sub2.residual_hinges].double().numpy()
    again, stats = depenetrate_fingers(scene, base, sub2.cfg.starts.depenetrate_tol)
    np.testing.assert_array_equal(again, q_env)  # deterministic, and the env used exactly this table
    changed = np.flatnonzero((again != base).any(0))
    assert len(changed) and set(changed.tolist()) <= set(fingers.tolist())
    quiet = ~(again != base).any(1)
    assert quiet[:25].all()  # before the grasp nothing penetrates: the frame-0 start is the reference's
    assert stats.chains >= 2 * 90  # both thumbs, every carry frame


def test_a_reset_starts_from_the_depenetrated_table(sub2: WristMimicEnv) -> None:
    sub2.reset(seed=0, start_frames=torch.tensor([70, 0]))
    torch.testing.assert_close(sub2.backend.qpos[0].double(), sub2._ref_qpos[70], rtol=0, atol=1e-12)
    torch.testing.assert_close(sub2.backend.qpos[1].double(), sub2._ref_qpos[0], rtol=0, atol=1e-12)
