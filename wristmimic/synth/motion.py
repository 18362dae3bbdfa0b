"""A bimanual box interaction made by inverse kinematics: stand, reach, grasp, lift, hold or turn, put down,
release, retract, rest.

The scene is laid out in the humanoid's frame: ankles on the line x = 0 (feet planted, flat, on z = 0), the
humanoid facing +x, a table whose near edge is ``table_gap`` in front of the ankles and a box resting on it.
Targets are keyframed and interpolated with minimum-jerk time scaling (``s = 10 tau^3 - 15 tau^4 + 6 tau^5``:
zero velocity and acceleration at both ends of every phase):

- the box: on the table -> lifted (``lift`` up, ``carry`` towards the body) -> optionally turned (``turn_deg``)
  about the vertical through its centre (``turn_axis`` 'z', the pelvis following ``pelvis_follow`` of it) or
  about its width axis through the two palms (``turn_axis`` 'y': the hands stay in place and roll with the
  faces they hold) -> back down onto the table (after a 90 deg turn about 'y': on its back or front face);
- the hands: rest (arms hanging, from the standing solution) -> pre-grasp, ``pregrasp_gap`` off the box's two
  side faces -> palms on the faces (``press`` into them) -> rigidly attached to the box while it is held ->
  back off the faces -> rest. Reach and retract follow a joint-space path (a quadratic Bezier through a
  posture with the hands raised in front of the table's edge, :func:`_through`): arcs like a human reach that
  clear the table; the contact phases track the box faces in task space;
- the palm faces the box, the fingers point forward and ``finger_pitch_deg`` down along the face, thumbs up;
  the fingers close onto the face (:func:`wristmimic.synth.ik.finger_closure`) as the palms arrive and open on
  release;
- both feet stay where they are; the centre of mass (humanoid + the box's weight while it is carried) stays
  over the middle of the feet.

Every frame is solved by :class:`wristmimic.synth.ik.WholeBodyIK`, warm-started from the frame before.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import matrix_to_quat, quat_to_matrix
from wristmimic.synth.humanoid import SIDES, SynthHumanoid
from wristmimic.synth.ik import FrameTargets, IKWeights, WholeBodyIK, finger_closure

FPS = 30.0
_D_VIA = np.deg2rad(-35.0)  # the half-way hand orientation: fingers pitched up from the pre-grasp direction
PHASES = ("stand", "reach", "grasp", "lift", "hold", "turn", "put_down", "release", "retract", "rest")
HELD = ("lift", "hold", "turn", "put_down")


def min_jerk(tau: np.ndarray | float) -> np.ndarray:
    """Minimum-jerk time scaling on [0, 1] (clipped outside)."""
    t = np.clip(np.asarray(tau, dtype=np.float64), 0.0, 1.0)
    return t**3 * (10.0 - 15.0 * t + 6.0 * t * t)


def _rz(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _slerp(Ra: np.ndarray, Rb: np.ndarray, s: float) -> np.ndarray:
    """Rotation between Ra (s = 0) and Rb (s = 1) along the shortest arc."""
    from wristmimic.rotations import quat_to_rotvec, rotvec_to_quat

    rel = matrix_to_quat(Ra.T @ Rb)
    return Ra @ quat_to_matrix(rotvec_to_quat(s * quat_to_rotvec(rel)))


@dataclass(frozen=True)
class MotionSpec:
    """Everything that defines one synthetic sequence (metres, degrees, frames at 30 fps)."""

    box_size: tuple[float, float, float] = (0.25, 0.30, 0.20)
    """Box extents along x (depth, away from the humanoid), y (width: between the hands) and z (height)."""
    box_density: float = 250.0
    """kg/m^3 (a packed cardboard box): 3.75 kg for the default box."""
    table_height: float = 0.75
    """Height of the table top (m)."""
    table_size: tuple[float, float] = (0.60, 1.00)
    """Table top extents along x and y; the table is a solid block from the floor to its top."""
    table_gap: float = 0.35
    """Ankle line (x = 0) to the table's near edge."""
    box_setback: float = 0.02
    """Box near face behind the table's near edge."""
    box_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Seeded jitter of the box on the table: dx, dy (m), yaw (deg)."""
    stance_half_width: float | None = None
    """Ankle distance from the midline; None: the hip joint spacing."""
    com_ahead: float = 0.045
    """Centre-of-mass target ahead of the ankle line (middle of the feet, slightly forward)."""
    lift: float = 0.15
    """How high the box is lifted (m)."""
    carry: float = 0.05
    """While lifted, the box comes this much closer to the body."""
    put_down_shift: float = 0.0
    """The box is put down this far along x from where it was picked up (< 0: nearer the humanoid)."""
    turn_deg: float = 0.0
    """Rotation of the box while lifted (the 'turn' phase, about ``turn_axis``, right-handed); 0: no turn."""
    turn_axis: str = "z"
    """'z': yaw about the box's vertical axis through its centre (with the hands on the side faces, one hand
    ends on the far face and its forearm crosses the box for turns near 90 deg); 'y': about the box's width axis
    through the two palms (the hands stay where they are and roll with their faces; 90 deg puts the box down on
    its back face (< 0: front up) or its front face (> 0: front down))."""
    pelvis_follow: float = 0.4
    """Fraction of the box's yaw (``turn_axis`` 'z') the pelvis yaw follows."""
    arm_clearance: bool = True
    """Keep the upper arms and forearms out of the box (an IK task; off along the reach's joint-space arc)."""
    clearance_margin: float | None = None
    """Wanted gap (m) of that task; None: :class:`~wristmimic.synth.ik.IKWeights`' default."""
    finger_pitch_deg: float = 20.0
    """Fingers point forward and this much down along the side faces."""
    press: float = 0.003
    """The palm sits this far into the face in the reference (a light squeeze for a PD controller)."""
    pregrasp_gap: float = 0.06
    """Palm to face distance before the grasp and after the release."""
    face_margin: float = 0.02
    """The hand stays this far inside the front and bottom edges of the face it holds."""
    grip: tuple[float, float] = (0.0, 0.0)
    """Wanted palm point on the face (box x, z from the face centre); moved as little as needed to keep the
    whole hand on the face."""
    via_height: float = 0.12
    """Half-way through a reach the palms pass this far above the table top (or the pre-grasp, if higher) ..."""
    via_ahead: float = -0.10
    """... and this far beyond the table's near edge (< 0: still in front of it)."""
    frames: dict[str, int] = field(
        default_factory=lambda: {
            "stand": 6,
            "reach": 30,
            "grasp": 12,
            "lift": 20,
            "hold": 8,
            "turn": 0,
            "put_down": 20,
            "release": 10,
            "retract": 28,
            "rest": 6,
        }
    )
    ik_iterations: int = 30
    """Gauss-Newton iterations per frame (warm-started from the frame before)."""
    path_weight: float = 1.0
    """Pull (1/rad) of every hinge towards the joint-space path in the middle of reach and retract."""
    retract_pull: float = 0.0
    """Least pull (1/rad) towards the retract's path, from its first frame: where the released hands could not
    reach their targets, it keeps the posture regularisation from snapping the arms once the hands are free."""

    def phase_list(self) -> list[tuple[str, int, int]]:
        """[(phase, first frame, frame count)] for the phases with frames, in order."""
        out, t = [], 0
        for p in PHASES:
            n = int(self.frames.get(p, 0))
            if n > 0:
                out.append((p, t, n))
                t += n
        return out

    @property
    def num_frames(self) -> int:
        return sum(int(self.frames.get(p, 0)) for p in PHASES)

    def to_dict(self) -> dict:
        return asdict(self)


REFERENCE_HEIGHT = 1.70
"""Stature (m) at which the MotionSpec defaults are given; :func:`scaled` adapts a spec to another stature."""


def scaled(spec: MotionSpec, height: float) -> MotionSpec:
    """The spec for a humanoid of ``height``: table height, standing distance and the hand and box paths scale
    with stature (the box does not), so the task is the same for every stature."""
    k = float(height) / REFERENCE_HEIGHT
    return replace(
        spec,
        table_height=spec.table_height * k,
        table_gap=spec.table_gap * k,
        com_ahead=spec.com_ahead * k,
        via_height=spec.via_height * k,
        via_ahead=spec.via_ahead * k,
        lift=spec.lift * k,
        carry=spec.carry * k,
        put_down_shift=spec.put_down_shift * k,
    )


@dataclass
class Motion:
    """The generated reference: qpos per frame and the object poses (world)."""

    qpos: np.ndarray  # (T, nq)
    box_pos: np.ndarray  # (T, 3)
    box_quat: np.ndarray  # (T, 4) wxyz
    table_pos: np.ndarray  # (3,) centre of the table block
    closure: np.ndarray  # (T,) finger closure 0..1
    phases: list[tuple[str, int, int]]
    residuals: dict[str, np.ndarray]  # task -> (T,) error (m or rad)
    hand_targets: np.ndarray  # (T, 2, 3) palm point targets
    held: np.ndarray  # (T,) bool: the hands carry the box


@dataclass
class _Layout:
    box_rest: np.ndarray  # (3,)
    yaw0: float
    table_pos: np.ndarray
    ankles: dict[str, np.ndarray]


def layout(spec: MotionSpec, humanoid: SynthHumanoid) -> _Layout:
    """Where the table, the box and the feet are."""
    a = humanoid.anthropometry
    dx, _dy, dz = spec.box_size
    tx, _ty = spec.table_size
    near = spec.table_gap
    table_pos = np.array([near + tx / 2, 0.0, spec.table_height / 2])
    box = np.array(
        [near + spec.box_setback + dx / 2 + spec.box_offset[0], spec.box_offset[1], spec.table_height + dz / 2]
    )
    hw = spec.stance_half_width if spec.stance_half_width is not None else a.choices.hip_half_spacing * a.height
    ankles = {s: np.array([0.0, y * hw, a.m("ankle")]) for s, y in SIDES}
    return _Layout(box, float(np.deg2rad(spec.box_offset[2])), table_pos, ankles)


def hand_in_box(spec: MotionSpec, humanoid: SynthHumanoid, side: str, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Palm point and wrist rotation of one hand in the box frame, ``gap`` off the side face (< 0: into it)."""
    dx, dy, dz = spec.box_size
    s = 1.0 if side == "L" else -1.0
    b = np.deg2rad(spec.finger_pitch_deg)
    f = np.array([np.cos(b), 0.0, -np.sin(b)])  # finger direction along the face
    u = np.array([np.sin(b), 0.0, np.cos(b)])  # thumb side
    n_out = np.array([0.0, s, 0.0])  # outward normal of the face the hand is on
    R = np.stack([u, s * f, n_out], axis=1)  # wrist x (thumb side), y (fingers: +y left, -y right), z (back of hand)
    # keep the whole hand on the face: fingertips short of the front edge, the lowest finger above the bottom
    pts, rad = humanoid.hand_points[side]
    rel = (pts - humanoid.palm_point[side]) @ R.T  # hand points relative to the palm point, box axes
    x_off = min(spec.grip[0], dx / 2 - spec.face_margin - float((rel[:, 0] + rad).max()))
    z_lo = -dz / 2 + spec.face_margin - float((rel[:, 2] - rad).min())
    z_hi = dz / 2 - float((rel[:, 2] + rad).max())
    z_off = z_lo if z_lo > z_hi else float(np.clip(spec.grip[1], z_lo, z_hi))
    return np.array([x_off, s * (dy / 2 + gap), z_off]), R


class _Timeline:
    def __init__(self, spec: MotionSpec):
        self.phases = spec.phase_list()
        self.T = spec.num_frames

    def at(self, t: int) -> tuple[str, float]:
        """Phase of frame ``t`` and its progress in (0, 1] (the last frame of a phase is 1)."""
        for name, start, n in self.phases:
            if start <= t < start + n:
                return name, (t - start + 1) / n
        raise IndexError(t)


def _through(qa: np.ndarray, qv: np.ndarray, qb: np.ndarray, s: float) -> np.ndarray:
    """Joint-space quadratic Bezier from ``qa`` (s = 0) through ``qv`` (s = 1/2) to ``qb`` (s = 1); the root
    quaternion is combined the same way and renormalised (the legs and root are re-solved afterwards)."""
    c = 2.0 * qv - 0.5 * (qa + qb)
    q = (1 - s) ** 2 * qa + 2 * (1 - s) * s * c + s**2 * qb
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


def generate_motion(
    skel: Skeleton, humanoid: SynthHumanoid, spec: MotionSpec, weights: IKWeights | None = None
) -> Motion:
    """Solve the whole sequence (see the module docstring)."""
    if weights is None and spec.clearance_margin is not None:
        weights = replace(IKWeights(), clearance_margin=float(spec.clearance_margin))
    ik = WholeBodyIK(skel, humanoid, weights)
    lay = layout(spec, humanoid)
    tl = _Timeline(spec)
    T = tl.T
    box_mass = float(np.prod(spec.box_size) * spec.box_density)
    com_xy = np.array([spec.com_ahead, 0.0])
    feet_pos, feet_mat = lay.ankles, {s: np.eye(3) for s, _ in SIDES}
    if spec.turn_axis not in ("z", "y"):
        raise ValueError(f"turn_axis {spec.turn_axis!r}: 'z' or 'y'")
    turn = np.deg2rad(spec.turn_deg) if spec.frames.get("turn", 0) > 0 else 0.0
    tilt = spec.turn_axis == "y" and turn != 0.0
    yaw_end = lay.yaw0 + (0.0 if tilt else turn)
    lifted = lay.box_rest + np.array([-spec.carry, 0.0, spec.lift])
    down = lay.box_rest + np.array([spec.put_down_shift, 0.0, 0.0])
    R0 = _rz(lay.yaw0)
    if tilt:  # turn about the width axis through the palms: the palm midpoint (box frame) stays where it is
        pivot = 0.5 * sum(hand_in_box(spec, humanoid, side, 0.0)[0] for side, _ in SIDES)
        R_end = _ry(turn)
        lifted_end = lifted + R0 @ (pivot - R_end @ pivot)
        half_z = float(np.abs(R_end[2]) @ (np.asarray(spec.box_size) / 2))  # the turned box's half height
        down = np.array([lifted_end[0] + spec.put_down_shift, lifted_end[1], spec.table_height + half_z])

    def box_pose(phase: str, s: float) -> tuple[np.ndarray, float, np.ndarray]:
        """Box centre, yaw and rotation: on the table, lifted, turned, back down."""
        if not tilt or PHASES.index(phase) < PHASES.index("turn"):
            p, yaw = _box_yaw(phase, s)
            return p, yaw, _rz(yaw)
        if phase == "turn":
            Rt = _ry(s * turn)
            return lifted + R0 @ (pivot - Rt @ pivot), lay.yaw0, R0 @ Rt
        if phase == "put_down":
            return lifted_end + s * (down - lifted_end), lay.yaw0, R0 @ R_end
        return down, lay.yaw0, R0 @ R_end

    def _box_yaw(phase: str, s: float) -> tuple[np.ndarray, float]:
        """Box centre and yaw of a turn about the vertical (or none)."""
        if PHASES.index(phase) < PHASES.index("lift"):
            return lay.box_rest, lay.yaw0
        if phase == "lift":
            return lay.box_rest + s * (lifted - lay.box_rest), lay.yaw0
        if phase == "hold":
            return lifted, lay.yaw0
        if phase == "turn":
            return lifted, lay.yaw0 + s * (yaw_end - lay.yaw0)
        if phase == "put_down":
            return lifted + s * (down - lifted), yaw_end
        return down, yaw_end

    def on_box(box_p: np.ndarray, Rb: np.ndarray, gap: float) -> tuple[dict, dict]:
        """Palm targets and wrist rotations of both hands, ``gap`` off the side faces of the box."""
        pos, mat = {}, {}
        for side, _ in SIDES:
            p_l, R_l = hand_in_box(spec, humanoid, side, gap)
            pos[side], mat[side] = box_p + Rb @ p_l, Rb @ R_l
        return pos, mat

    def targets(
        hands_pos, hands_mat, box_p, yaw, load: float, twist: float = 0.0, clear: bool = True, Rb=None
    ) -> FrameTargets:
        """Targets of one frame; ``twist`` (0..1): how much of the box's turn the pelvis follows; ``clear``: keep
        the arms out of the box (off along the joint-space arcs of reach and retract, which pass over it)."""
        return FrameTargets(
            feet_pos,
            feet_mat,
            hands_pos,
            hands_mat,
            com_xy,
            held_mass=box_mass * load,
            held_pos=box_p,
            pelvis_yaw=twist * spec.pelvis_follow * (yaw - lay.yaw0),
            obstacle=(box_p, _rz(yaw) if Rb is None else Rb, np.asarray(spec.box_size, dtype=float) / 2)
            if clear and spec.arm_clearance
            else None,
        )

    # standing with arms hanging (no hand task): the rest posture, long solve from the neutral posture
    a = humanoid.anthropometry
    q_rest = ik.neutral_qpos(np.array([0.0, 0.0, (a.body["hip"] + a.choices.pelvis_above_hip) * a.height]))
    q_rest = ik.solve(q_rest, targets(None, None, lay.box_rest, lay.yaw0, 0.0), 400)
    rest = {s: ik.palm_world(s) for s, _ in SIDES}
    rest_pos, rest_mat = {s: v[0] for s, v in rest.items()}, {s: v[1] for s, v in rest.items()}

    def pose_at(box_p: np.ndarray, yaw: float, q0: np.ndarray, gap: float, load: float = 0.0) -> np.ndarray:
        """IK posture with the hands ``gap`` off the box, reached by continuation from ``q0``'s hands."""
        pos, mat = on_box(box_p, _rz(yaw), gap)
        ik.forward(q0)
        start = {s: ik.palm_world(s) for s, _ in SIDES}
        q = q0
        for k in range(1, 21):  # straight-line continuation avoids far-away local minima
            u = k / 20
            hp = {s: start[s][0] + u * (pos[s] - start[s][0]) for s in pos}
            hm = {s: _slerp(start[s][1], mat[s], u) for s in pos}
            q = ik.solve(q, targets(hp, hm, box_p, yaw, load), 40)
        return ik.solve(q, targets(pos, mat, box_p, yaw, load), 200)

    def via_pose(box_p: np.ndarray, yaw: float, Rb: np.ndarray, q0: np.ndarray) -> np.ndarray:
        """Posture half-way through a reach: hands above the table's near edge, fingers pointing forward-up."""
        pos, mat = on_box(box_p, Rb, spec.pregrasp_gap)
        ik.forward(q0)
        start = {s: ik.palm_world(s) for s, _ in SIDES}
        edge = lay.table_pos[0] - spec.table_size[0] / 2
        top = max(spec.table_height, max(p[2] for p in pos.values()))
        up = np.array([[np.cos(_D_VIA), 0, -np.sin(_D_VIA)], [0, 1, 0], [np.sin(_D_VIA), 0, np.cos(_D_VIA)]])
        vp = {
            s: np.array([edge + spec.via_ahead, 0.5 * (start[s][0][1] + pos[s][1]), top + spec.via_height]) for s in pos
        }
        vm = {s: up @ _slerp(start[s][1], mat[s], 0.7) for s in pos}  # pitched fingers-up about y
        q = q0
        for k in range(1, 21):
            u = k / 20
            hp = {s: start[s][0] + u * (vp[s] - start[s][0]) for s in pos}
            hm = {s: _slerp(start[s][1], vm[s], u) for s in pos}
            q = ik.solve(q, targets(hp, hm, box_p, yaw, 0.0, Rb=Rb), 40)
        return q

    q_pre = pose_at(lay.box_rest, lay.yaw0, q_rest, spec.pregrasp_gap)
    q_via = via_pose(lay.box_rest, lay.yaw0, _rz(lay.yaw0), q_rest)

    qs = np.zeros((T, ik.model.nq))
    box_pos, box_yaw, box_mat = np.zeros((T, 3)), np.zeros(T), np.zeros((T, 3, 3))
    closure, held = np.zeros(T), np.zeros(T, dtype=bool)
    htgt = np.full((T, 2, 3), np.nan)
    res: dict[str, np.ndarray] = {}
    q = q_rest
    q_release, q_back = q_rest, None
    for t in range(T):
        phase, tau = tl.at(t)
        s_ = float(min_jerk(tau))
        bp, yaw, Rb = box_pose(phase, s_)
        is_held = phase in HELD
        load = 0.0  # the box's weight moves to the hands early in the lift and back to the table late in put-down
        if phase == "lift":
            load = float(min_jerk(tau / 0.3))
        elif phase == "put_down":
            load = float(min_jerk((1.0 - tau) / 0.3))
        elif is_held:
            load = 1.0
        if phase in ("reach", "retract"):
            if phase == "reach":
                qa, qv, qb = q_rest, q_via, q_pre
            else:
                if q_back is None:
                    q_back = via_pose(bp, yaw, Rb, q_release)
                qa, qv, qb = q_release, q_back, q_rest
            # the hands follow the joint-space path's palms (arcs like a human reach), the posture is pulled
            # towards the path in the middle of the phase only, so both ends match the neighbouring phases
            qj = _through(qa, qv, qb, s_)
            ik.forward(qj)
            palms = {side: ik.palm_world(side) for side, _ in SIDES}
            untwist = 0.0 if phase == "reach" else 1.0 - s_  # the pelvis turns back with the retract
            hp, hm = {k: v[0] for k, v in palms.items()}, {k: v[1] for k, v in palms.items()}
            tgt = targets(hp, hm, bp, yaw, 0.0, twist=untwist, clear=phase == "retract", Rb=Rb)
            pull = 4.0 * s_ * (1.0 - s_) * spec.path_weight
            if phase == "retract" and spec.retract_pull > 0.0:
                pull = max(pull, spec.retract_pull)
            q = ik.solve(q, tgt, spec.ik_iterations, track=(qj, pull))
        else:
            if phase in ("stand", "rest"):
                hp, hm = rest_pos, rest_mat
            else:
                gap = -spec.press
                if phase == "grasp":
                    gap = spec.pregrasp_gap + s_ * (-spec.press - spec.pregrasp_gap)
                elif phase == "release":
                    gap = -spec.press + s_ * (spec.pregrasp_gap + spec.press)
                hp, hm = on_box(bp, Rb, gap)
            tgt = targets(hp, hm, bp, yaw, load, twist=0.0 if phase in ("stand", "rest") else 1.0, Rb=Rb)
            q = ik.solve(q, tgt, spec.ik_iterations)
            htgt[t] = [hp["L"], hp["R"]]
            if phase == "release":
                q_release = q
        qs[t] = q
        for k, v in ik.residuals(tgt).items():
            res.setdefault(k, np.full(T, np.nan))[t] = v
        box_pos[t], box_yaw[t], box_mat[t], held[t] = bp, yaw, Rb, is_held
        if phase == "grasp":
            closure[t] = float(min_jerk((tau - 0.3) / 0.7))
        elif phase == "release":
            closure[t] = 1.0 - float(min_jerk(tau / 0.7))
        elif is_held:
            closure[t] = 1.0
    # fingers: closure onto the face plane (the palm's contact plane in the wrist frame: -thickness + press)
    closed = finger_closure(skel, humanoid, -humanoid.palm_half_thickness + spec.press)
    for j, ang in closed.items():
        qs[:, skel.hinge_qposadr[j]] = closure[:, None] * ang[None]
    half = 0.5 * box_yaw
    box_quat = np.stack([np.cos(half), np.zeros(T), np.zeros(T), np.sin(half)], axis=-1)
    if tilt:  # a turn about the width axis: the quaternion of the full rotation (w >= 0)
        box_quat = matrix_to_quat(box_mat)
    return Motion(
        qpos=qs,
        box_pos=box_pos,
        box_quat=box_quat,
        table_pos=lay.table_pos,
        closure=closure,
        phases=tl.phases,
        residuals=res,
        hand_targets=htgt,
        held=held,
    )
