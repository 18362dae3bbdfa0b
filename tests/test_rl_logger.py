"""Training statistics: success counts only episodes that started at frame 0 and reached the last frame."""

from __future__ import annotations

import math

import torch

from wristmimic.rl.logger import EpisodeStats


def _info(frame: list[int], start: list[int], time_out: list[bool]) -> dict:
    n = len(frame)
    return {
        "time_outs": torch.tensor(time_out),
        "frame": torch.tensor(frame),
        "episode_start": torch.tensor(start),
        "episode_frames": torch.tensor(frame) - torch.tensor(start),
        "termination_reason": torch.zeros(n, dtype=torch.long),
        "terms": {"reward/x": torch.ones(n)},
    }


def test_success_needs_a_frame_0_start_and_the_last_frame_unterminated() -> None:
    st = EpisodeStats(num_frames=100)
    # world 0: from 0 to the end (success); 1: late start to the end (not counted); 2: from 0, terminated;
    # 3: from 0, cut by the episode cap before the end (a time-out that is no success); 4: still running
    terminated = torch.tensor([False, False, True, False, False])
    st.record(
        torch.ones(5), terminated, _info([99, 99, 40, 60, 10], [0, 50, 0, 0, 0], [True, True, False, True, False])
    )
    row = st.flush()
    assert row["episodes"] == 4 and row["episodes_from_zero"] == 3
    assert row["success_rate"] == 1 / 3
    assert (st.episodes_total, st.successes_total) == (3, 1)
    st.record(torch.ones(1), torch.tensor([False]), _info([99], [70], [True]))
    assert math.isnan(st.flush()["success_rate"])  # no frame-0 episode ended
