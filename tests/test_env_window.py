"""Contact window bounds and phases at every boundary frame (defaults t_b 10, t_a 15, tau1 -2, tau2 12)."""

from __future__ import annotations

import pytest
import torch

from wristmimic.env.config import WindowConfig
from wristmimic.env.window import APPROACH, GRASP, OUTSIDE, STABILIZE, in_window, phase, window_bounds

CFG = WindowConfig()


def test_phase_constants() -> None:
    assert (OUTSIDE, APPROACH, GRASP, STABILIZE) == (0, 1, 2, 3)


@pytest.mark.parametrize("t_c", [0, 40, 200])
def test_phase_at_each_boundary_frame(t_c: int) -> None:
    offsets = [-11, -10, -3, -2, 12, 13, 15, 16]
    expected = [OUTSIDE, APPROACH, APPROACH, GRASP, GRASP, STABILIZE, STABILIZE, OUTSIDE]
    frame = torch.tensor([t_c + o for o in offsets])
    got = phase(frame, torch.full_like(frame, t_c), CFG)
    assert got.dtype == torch.long
    assert got.tolist() == expected


def test_every_frame_has_one_phase_and_the_counts_match_the_doc() -> None:
    t_c = 50
    frame = torch.arange(0, 120)
    ph = phase(frame, torch.full_like(frame, t_c), CFG)
    assert int((ph == APPROACH).sum()) == 8  # t_c-10 .. t_c-3
    assert int((ph == GRASP).sum()) == 15  # t_c-2 .. t_c+12
    assert int((ph == STABILIZE).sum()) == 3  # t_c+13 .. t_c+15
    assert int((ph != OUTSIDE).sum()) == CFG.t_b + CFG.t_a + 1
    assert torch.equal(ph != OUTSIDE, in_window(frame, torch.full_like(frame, t_c), CFG))


def test_no_contact_is_outside_everywhere() -> None:
    frame = torch.arange(-20, 40)
    t_c = torch.full_like(frame, -1)
    assert (phase(frame, t_c, CFG) == OUTSIDE).all()
    assert not in_window(frame, t_c, CFG).any()
    lo, hi = window_bounds(t_c, CFG)
    assert (hi < lo).all()


def test_bounds_and_per_world_t_c() -> None:
    t_c = torch.tensor([30, -1, 5])
    lo, hi = window_bounds(t_c, CFG)
    assert lo.tolist()[0::2] == [20, -5] and hi.tolist()[0::2] == [45, 20]
    frame = torch.tensor([28, 28, 28])
    assert phase(frame, t_c, CFG).tolist() == [GRASP, OUTSIDE, OUTSIDE]


def test_custom_window_config() -> None:
    cfg = WindowConfig(t_b=4, t_a=6, tau1=0, tau2=3)
    frame = torch.arange(0, 20)
    ph = phase(frame, torch.full_like(frame, 10), cfg)
    assert ph.tolist()[5:18] == [
        OUTSIDE, APPROACH, APPROACH, APPROACH, APPROACH,  # 5..9
        GRASP, GRASP, GRASP, GRASP,  # 10..13
        STABILIZE, STABILIZE, STABILIZE,  # 14..16
        OUTSIDE,  # 17
    ]  # fmt: skip
