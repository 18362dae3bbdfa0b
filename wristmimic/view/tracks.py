"""The data a recording shows, as plain numpy: the reference of one sequence and one simulated rollout.

Shapes: T reference frames, K recorded simulation states, B humanoid bodies, O dynamic objects.
Quaternions are wxyz.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch

from wristmimic.env import window as W
from wristmimic.env.config import WindowConfig
from wristmimic.format.reader import Dataset
from wristmimic.format.records import ObjectRecord

if TYPE_CHECKING:
    from wristmimic.env.vec_env import WristMimicEnv


@dataclass
class ObjectTrack:
    """One object of the scene and its reference pose."""

    id: str
    record: ObjectRecord
    dynamic: bool
    pos: np.ndarray  # (T, 3), or (1, 3) for a static object
    quat: np.ndarray  # (T, 4) wxyz, or (1, 4)


@dataclass
class ReferenceTrack:
    """The reference motion of one sequence (the converted data)."""

    sequence_id: str
    fps: float
    body_names: list[str]
    roles: dict[str, np.ndarray]
    body_pos: np.ndarray  # (T, B, 3)
    body_quat: np.ndarray  # (T, B, 4)
    objects: list[ObjectTrack]
    labels: np.ndarray  # (T, B) int8: 1 contact, 0 unknown, -1 must not touch
    hand: np.ndarray  # (T, 2) bool, left and right hand in contact
    first_contact: np.ndarray  # (2,) first contact frame per hand, -1 if none
    info: dict[str, str] = field(default_factory=dict)
    """Free text shown in the recording's info panel (dataset, humanoid, subject, text, ...)."""

    @property
    def num_frames(self) -> int:
        return int(self.body_pos.shape[0])

    @property
    def t_c(self) -> int:
        """Earliest first contact frame of the grasping hands, -1 if none (as the environment defines it)."""
        grasp = self.first_contact >= 0
        return int(self.first_contact[grasp].min()) if grasp.any() else -1

    @property
    def dynamic_objects(self) -> list[ObjectTrack]:
        return [o for o in self.objects if o.dynamic]

    def phases(self, cfg: WindowConfig) -> np.ndarray:
        """(T,) phase id of every frame (``wristmimic.env.window``: 0 outside, 1 approach, 2 grasp,
        3 stabilise)."""
        frames = torch.arange(self.num_frames)
        return W.phase(frames, torch.full_like(frames, self.t_c), cfg).numpy()


@dataclass
class SimTrack:
    """One simulated rollout of a single world, recorded until its episode ended."""

    frames: np.ndarray  # (K,) reference frame of each recorded state
    body_pos: np.ndarray  # (K, B, 3)
    body_quat: np.ndarray  # (K, B, 4)
    obj_pos: np.ndarray  # (K, O, 3) dynamic objects, in scene order
    obj_quat: np.ndarray  # (K, O, 4)
    contact_obj: np.ndarray  # (K, B) bool: body touches a dynamic object
    reward: np.ndarray  # (K,) reward of the step that led to each state (NaN for the start state)
    end_reason: str
    """``truncated`` (reached the end of the reference or the episode limit), ``terminated: <reason>`` or
    ``stopped`` (the step limit of the recording)."""
    info: dict[str, str] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])


def reference_from_dataset(ds: Dataset, sequence_id: str, max_frames: int | None = None) -> ReferenceTrack:
    """The stored reference of ``sequence_id`` (its first ``max_frames`` frames if given)."""
    seq = ds.sequence(sequence_id)
    frames = None if max_frames is None else slice(0, max(int(max_frames), 1))
    s = seq.load(frames)
    hum = ds.humanoid(seq.humanoid_id)
    objects = []
    for k, oid in enumerate(seq.object_ids):
        rec = ds.object(oid)
        sl = slice(0, 1) if rec.static else slice(None)
        objects.append(ObjectTrack(oid, rec, not rec.static, s.object_pos[sl, k], s.object_quat[sl, k]))
    info = {
        "dataset": str(ds.path),
        "humanoid": f"{seq.humanoid_id} ({hum.family}, {hum.num_bodies} bodies)",
        "subject": seq.subject,
        "source": seq.dataset,
        "text": seq.text,
        "stored contact window": str(s.contact_window.tolist()),
    }
    return ReferenceTrack(
        sequence_id=sequence_id,
        fps=float(ds.attrs.get("fps", 30.0)),
        body_names=list(hum.body_names),
        roles={k: np.asarray(v) for k, v in hum.roles.items()},
        body_pos=s.body_pos.astype(np.float32),
        body_quat=s.body_quat.astype(np.float32),
        objects=objects,
        labels=s.contact_labels.astype(np.int8),
        hand=s.hand_contact.astype(bool),
        first_contact=s.first_contact_frame.astype(np.int64),
        info={k: v for k, v in info.items() if v},
    )


def reference_from_env(env: WristMimicEnv) -> ReferenceTrack:
    """The reference an environment imitates (``env.ref``; static objects at their pose in the scene)."""
    r, sc = env.ref, env.scene
    objects, j = [], 0
    for o in sc.objects:
        if o.dynamic:
            pos, quat = r.obj_pos[:, j].numpy(), r.obj_quat[:, j].numpy()
            j += 1
        else:
            pos, quat = sc.model.body_pos[o.body_id][None], sc.model.body_quat[o.body_id][None]
        objects.append(ObjectTrack(o.id, o.record, o.dynamic, np.asarray(pos), np.asarray(quat)))
    hum = sc.humanoid
    return ReferenceTrack(
        sequence_id=sc.sequence_id,
        fps=float(r.fps),
        body_names=list(sc.skeleton.body_names),
        roles={k: np.asarray(v) for k, v in hum.roles.items()},
        body_pos=r.body_pos.numpy(),
        body_quat=r.body_quat.numpy(),
        objects=objects,
        labels=r.labels.numpy().astype(np.int8),
        hand=r.hand.numpy().astype(bool),
        first_contact=r.first_contact.numpy().astype(np.int64),
        info={"humanoid": f"{hum.name} ({hum.family}, {hum.num_bodies} bodies)"},
    )
