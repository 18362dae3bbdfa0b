"""Body index sets used by rewards and terminations, built from the humanoid's stored roles
(:func:`wristmimic.humanoid.roles.compute_roles`)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch


def _idx(a: np.ndarray | list[int]) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.int64))


@dataclass(frozen=True)
class BodySets:
    """Long index tensors into the B humanoid bodies (counts given for SMPL-X / ParaHome)."""

    body: torch.Tensor
    """(nb,) tracked body joints: key bodies minus the wrists (19 / 20)."""
    wrists: torch.Tensor
    """(2,) [left wrist, right wrist]."""
    left_arm: torch.Tensor
    """(2,) left shoulder and elbow."""
    right_arm: torch.Tensor
    """(2,) right shoulder and elbow."""
    fingers: torch.Tensor
    """(nf,) finger bodies of both hands."""
    key: torch.Tensor
    """(K,) key bodies (non-finger minus root): tracked positions, IG reward, body-error termination."""
    contact_other: torch.Tensor
    """Non-finger key bodies of the 'other' contact term (= key)."""
    left_hand: torch.Tensor
    """Left wrist and its fingers."""
    right_hand: torch.Tensor
    """Right wrist and its fingers."""
    feet: torch.Tensor
    """(4,) ankle and toe bodies of both legs (empty where the roles name none)."""
    fingertips: torch.Tensor
    """(2, nt) fingertip bodies [left hand, right hand] (the leaves of the finger subtrees)."""

    @classmethod
    def from_roles(cls, roles: dict[str, np.ndarray]) -> BodySets:
        """Sets from a humanoid's roles dict (numpy int arrays of body indices)."""
        key = np.asarray(roles["key_bodies"])
        wrists = np.asarray(roles["wrists"])
        return cls(
            body=_idx(key[~np.isin(key, wrists)]),
            wrists=_idx(wrists),
            left_arm=_idx(roles["left_arm"]),
            right_arm=_idx(roles["right_arm"]),
            fingers=_idx(roles["fingers"]),
            key=_idx(key),
            contact_other=_idx(key),
            left_hand=_idx(roles["left_hand"]),
            right_hand=_idx(roles["right_hand"]),
            feet=_idx(roles.get("feet", [])),
            fingertips=_idx(np.stack([np.asarray(roles.get(f"{h}_fingertips", []), int) for h in ("left", "right")])),
        )

    def to(self, device: torch.device | str) -> BodySets:
        """The same sets on another device."""
        return BodySets(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})
