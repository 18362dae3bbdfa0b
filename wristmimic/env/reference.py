"""The reference motion of one sequence as torch tensors, with the derived quantities the environment needs.

Everything is precomputed once per scene (T frames) so that per-step work is indexing ``ref.x[frames]``.
Velocities are forward finite differences x 30 fps (last frame repeats the one before), as in InterMimic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from wristmimic.format.reader import Dataset
from wristmimic.rotations import quat_conj, quat_mul, quat_rotate, quat_to_rotvec
from wristmimic.scene import Scene


def _fdiff(x: np.ndarray, fps: float) -> np.ndarray:
    v = np.zeros_like(x)
    if len(x) > 1:
        v[:-1] = (x[1:] - x[:-1]) * fps
        v[-1] = v[-2]
    return v


def _angvel(q: np.ndarray, fps: float, local: bool) -> np.ndarray:
    """Angular velocity (rad/s) from consecutive wxyz quaternions; world frame, or body frame if ``local``."""
    w = np.zeros(q.shape[:-1] + (3,))
    if len(q) > 1:
        rel = quat_mul(quat_conj(q[:-1]), q[1:]) if local else quat_mul(q[1:], quat_conj(q[:-1]))
        w[:-1] = quat_to_rotvec(rel) * fps
        w[-1] = w[-2]
    return w


@dataclass
class Reference:
    """Reference tensors (float32 unless stated); T frames, B bodies, D = 3 J hinges, O dynamic objects."""

    num_frames: int
    fps: float
    root_pos: torch.Tensor  # (T, 3)
    root_quat: torch.Tensor  # (T, 4)
    root_linvel: torch.Tensor  # (T, 3) world
    root_angvel_local: torch.Tensor  # (T, 3) body frame (MuJoCo free-joint convention)
    joint_angles: torch.Tensor  # (T, D)
    joint_vel: torch.Tensor  # (T, D)
    body_pos: torch.Tensor  # (T, B, 3)
    body_quat: torch.Tensor  # (T, B, 4)
    body_linvel: torch.Tensor  # (T, B, 3)
    body_angvel: torch.Tensor  # (T, B, 3) world
    obj_pos: torch.Tensor  # (T, O, 3)
    obj_quat: torch.Tensor  # (T, O, 4)
    obj_linvel: torch.Tensor  # (T, O, 3)
    obj_angvel_local: torch.Tensor  # (T, O, 3)
    obj_angvel: torch.Tensor  # (T, O, 3) world
    labels: torch.Tensor  # (T, B) int8
    hand: torch.Tensor  # (T, 2) bool
    near_dist: torch.Tensor  # (T, B) distance of each body to the nearest object surface point
    near_vec: torch.Tensor  # (T, B, 3) each body minus its nearest object surface point
    points_local: torch.Tensor  # (P, 3) surface points of the dynamic objects, each in its object's frame
    points_object: torch.Tensor  # (P,) long: which dynamic object each point belongs to
    points: torch.Tensor  # (T, P, 3) the same points posed in the world
    first_contact: torch.Tensor  # (2,) long
    t_c: int  # earliest first contact frame of the grasping hands, -1 if none
    grasp_hands: torch.Tensor  # (2,) bool
    grounded_by: float | None = None
    """Metres the humanoid was lowered by (``load_reference(ground=True)``); None: as recorded."""
    foot_clearance: float = 0.0
    """Swing-foot clearance the legs were bent to (``load_reference(foot_clearance=...)``); 0: as recorded."""
    feet_lifted: int = 0
    """Foot-frames :func:`~wristmimic.env.grounding.lift_feet` changed."""
    clear_hands: bool = False
    """The arms were bent so that no palm lies inside an object (``load_reference(clear_hands=True)``)."""
    palms_cleared: int = 0
    """Frames :func:`~wristmimic.env.clearance.clear_palms` changed."""
    wrist_offsets: tuple[float, ...] = ()
    """Object-frame wrist offsets applied (``load_reference(wrist_offsets=...)``); empty: none."""

    def to(self, device: str | torch.device) -> Reference:
        return Reference(**{k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in self.__dict__.items()})


def load_reference(
    ds: Dataset,
    scene: Scene,
    ig_points: int = 1024,
    seed: int = 0,
    max_frames: int | None = None,
    ground: bool = False,
    foot_clearance: float = 0.0,
    clear_hands: bool = False,
    wrist_offsets: tuple[float, ...] = (),
) -> Reference:
    """Read the sequence of ``scene`` from ``ds`` and derive velocities, surface points and distances.
    ``max_frames`` keeps only the first frames (a short task, e.g. for tests); ``ground`` lowers the humanoid
    (root and bodies, not the objects) by its floor clearance; ``foot_clearance`` > 0 (m) then bends each leg so
    that a swinging foot clears the floor by that much and a standing one does not sink into it
    (:func:`wristmimic.env.grounding.lift_feet`); ``clear_hands`` then bends each arm so that no palm lies inside
    an object (:func:`wristmimic.env.clearance.clear_palms`); ``wrist_offsets`` (left x y z, right x y z, m in the
    first dynamic object's frame) then moves each hand while the reference hand touches the object
    (:class:`wristmimic.env.clearance.ArmOffsetMap`)."""
    seq = ds.sequence(scene.sequence_id)
    s = seq.load(None if max_frames is None else slice(0, max(int(max_frames), 2)))
    dz = 0.0
    if ground:
        from wristmimic.env.grounding import floor_clearance

        angles0 = s.joint_angles.reshape(s.num_frames, -1).astype(np.float64)
        dz = floor_clearance(scene, s.root_pos.astype(np.float64), s.root_quat.astype(np.float64), angles0)
        s.root_pos = s.root_pos - np.array([0.0, 0.0, dz], dtype=s.root_pos.dtype)
        s.body_pos = s.body_pos - np.array([0.0, 0.0, dz], dtype=s.body_pos.dtype)
    fps = float(ds.attrs.get("fps", 30.0))
    lifted = 0
    if foot_clearance > 0:
        from wristmimic.env.grounding import lift_feet

        rp, rq = s.root_pos.astype(np.float64), s.root_quat.astype(np.float64)
        old = s.joint_angles.reshape(s.num_frames, -1).astype(np.float64)
        new, lifted = lift_feet(scene, rp, rq, old, foot_clearance, fps)
        if lifted:
            _repose(s, scene, old, new)
    dyn_idx = [k for k, o in enumerate(scene.objects) if o.dynamic]
    cleared = 0
    if clear_hands:
        from wristmimic.env.clearance import clear_palms

        old = s.joint_angles.reshape(s.num_frames, -1).astype(np.float64)
        new, stats = clear_palms(
            scene,
            s.root_pos.astype(np.float64),
            s.root_quat.astype(np.float64),
            old,
            s.object_pos[:, dyn_idx].astype(np.float64),
            s.object_quat[:, dyn_idx].astype(np.float64),
        )
        cleared = stats.frames
        if cleared:
            _repose(s, scene, old, new)
    if len(wrist_offsets):
        from wristmimic.env.clearance import offset_wrists

        if not dyn_idx:
            raise ValueError(f"wrist_offsets: sequence {scene.sequence_id} has no dynamic object to offset from")
        old = s.joint_angles.reshape(s.num_frames, -1).astype(np.float64)
        new = offset_wrists(
            scene,
            s.root_pos.astype(np.float64),
            s.root_quat.astype(np.float64),
            old,
            s.object_quat[:, dyn_idx[0]].astype(np.float64),
            np.asarray(s.hand_contact, dtype=bool),
            np.asarray(wrist_offsets, dtype=np.float64).reshape(2, 3),
            fps,
        )
        _repose(s, scene, old, new)
    obj_pos = s.object_pos[:, dyn_idx].astype(np.float64)
    obj_quat = s.object_quat[:, dyn_idx].astype(np.float64)
    pts, owner = [], []
    rng = np.random.default_rng(seed)
    for j, k in enumerate(dyn_idx):
        sp = scene.objects[k].record.surface_points.astype(np.float64)
        if ig_points < len(sp):
            sp = sp[np.sort(rng.choice(len(sp), ig_points, replace=False))]
        pts.append(sp)
        owner.append(np.full(len(sp), j))
    local = np.concatenate(pts) if pts else np.zeros((0, 3))
    owner_a = np.concatenate(owner) if owner else np.zeros(0, int)
    world = (
        quat_rotate(obj_quat[:, owner_a], local[None]) + obj_pos[:, owner_a]
        if len(local)
        else np.zeros((s.num_frames, 0, 3))
    )
    body_pos = s.body_pos.astype(np.float64)
    if len(local):
        diff = [body_pos[t, :, None] - world[t, None] for t in range(s.num_frames)]  # (B, P, 3) per frame
        near_vec = np.stack([d[np.arange(len(d)), np.linalg.norm(d, axis=-1).argmin(-1)] for d in diff])
        near = np.linalg.norm(near_vec, axis=-1)
    else:
        near_vec = np.zeros(body_pos.shape)
        near = np.full(body_pos.shape[:2], np.inf)
    first = s.first_contact_frame.astype(np.int64)
    grasp = first >= 0
    t_c = int(first[grasp].min()) if grasp.any() else -1
    f32 = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    angles = s.joint_angles.reshape(s.num_frames, -1).astype(np.float64)
    dang = np.zeros_like(angles)
    dang[:-1] = np.angle(np.exp(1j * (angles[1:] - angles[:-1]))) * fps
    dang[-1] = dang[-2] if len(angles) > 1 else 0
    return Reference(
        num_frames=s.num_frames,
        fps=fps,
        root_pos=f32(s.root_pos),
        root_quat=f32(s.root_quat),
        root_linvel=f32(_fdiff(s.root_pos, fps)),
        root_angvel_local=f32(_angvel(s.root_quat.astype(np.float64), fps, local=True)),
        joint_angles=f32(angles),
        joint_vel=f32(dang),
        body_pos=f32(body_pos),
        body_quat=f32(s.body_quat),
        body_linvel=f32(_fdiff(body_pos, fps)),
        body_angvel=f32(_angvel(s.body_quat.astype(np.float64), fps, local=False)),
        obj_pos=f32(obj_pos),
        obj_quat=f32(obj_quat),
        obj_linvel=f32(_fdiff(obj_pos, fps)),
        obj_angvel_local=f32(_angvel(obj_quat, fps, local=True)),
        obj_angvel=f32(_angvel(obj_quat, fps, local=False)),
        labels=torch.as_tensor(s.contact_labels, dtype=torch.int8),
        hand=torch.as_tensor(s.hand_contact, dtype=torch.bool),
        near_dist=f32(near),
        near_vec=f32(near_vec),
        points_local=f32(local),
        points_object=torch.as_tensor(owner_a, dtype=torch.long),
        points=f32(world),
        first_contact=torch.as_tensor(first),
        t_c=t_c,
        grasp_hands=torch.as_tensor(grasp),
        grounded_by=dz if ground else None,
        foot_clearance=float(foot_clearance) if foot_clearance > 0 else 0.0,
        feet_lifted=int(lifted),
        clear_hands=bool(clear_hands),
        palms_cleared=int(cleared),
        wrist_offsets=tuple(float(v) for v in wrist_offsets),
    )


def _repose(s, scene: Scene, old: np.ndarray, new: np.ndarray) -> None:
    """Give the loaded sequence ``s`` the hinge angles ``new`` (T, J*3) instead of ``old``: each body's recorded
    position and orientation moves by the change MuJoCo's forward kinematics gives (root kept)."""
    from wristmimic.env.grounding import forward_bodies

    rp, rq = s.root_pos.astype(np.float64), s.root_quat.astype(np.float64)
    p0, q0 = forward_bodies(scene, rp, rq, old)
    p1, q1 = forward_bodies(scene, rp, rq, new)
    s.body_pos = (s.body_pos + (p1 - p0)).astype(s.body_pos.dtype)
    s.body_quat = quat_mul(quat_mul(q1, quat_conj(q0)), s.body_quat.astype(np.float64)).astype(s.body_quat.dtype)
    s.joint_angles = new.reshape(s.joint_angles.shape).astype(s.joint_angles.dtype)
