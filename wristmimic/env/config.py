"""Every constant of the WristMimic environment in one place (paper supplement, InterMimic defaults).

Variants for the paper's tables are built by :func:`variant_config` from a name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

ACTION_MODES = ("residual", "absolute")
"""How policy actions become PD targets (:attr:`EnvConfig.action_mode`)."""
FINGER_ACTIONS = ("absolute", "delta", "range")
"""How finger actions become PD targets (:attr:`EnvConfig.finger_action`)."""
WRIST_FRAMES = ("world", "object")
"""Where the wrist terms and the wrist reset measure a wrist's target (:attr:`EnvConfig.wrist_frame`)."""
REWARD_FORMS = ("product", "mean")
"""How the reward factors combine (:attr:`EnvConfig.reward_form`)."""

VARIANTS = ("wristmimic", "decoupled", "reward-modulation-only", "reset-only", "finger-guidance", "intermimic")


@dataclass(frozen=True)
class RewardWeights:
    """lambda of each multiplicative factor exp(-lambda * E) (paper supplement, Table 'Reward weights')."""

    p: float = 30.0
    """Body position outside the contact window."""
    r: float = 2.5
    """Body rotation outside the contact window."""
    gbp: float = 10.0
    """Body position inside the contact window (reduced from p)."""
    gbr: float = 1.0
    """Body rotation inside the contact window (reduced from r)."""
    gwp: float = 10.0
    """Wrist position, every phase."""
    gwr: float = 1.0
    """Wrist rotation, every phase."""
    fp: float = 30.0
    """Finger position (finger-guidance and intermimic variants only)."""
    fr: float = 2.5
    """Finger rotation (finger-guidance and intermimic variants only)."""
    op: float = 5.0
    """Object position."""
    orot: float = 0.1
    """Object rotation (paper 'or')."""
    ig: float = 5.0
    """Interaction graph."""
    cg_hand: float = 10.0
    """Hand contact."""
    cg_other: float = 5.0
    """Other (non-finger) body contact."""
    eg1: float = 2e-5
    """Joint energy (joint acceleration)."""
    eg2: float = 2e-5
    """Object energy (object acceleration)."""
    eg3: float = 1e-9
    """Contact energy (humanoid contact forces)."""
    near_far: float = 5.0
    """InterMimic's w = exp(-near_far * d): position error weighted near the object, rotation error far."""
    root_pos: float = 0.0
    """Root (anchor) position, squared error (m^2); 0 turns the factor off (the paper's reward has none). The
    near/far weighting leaves the root, far from the object, almost unweighted in the body terms, so without it
    drift of the whole body is felt only through the wrist terms and terminations (BeyondMimic's anchor terms).
    Off by default: 20 (with root_rot 2) gave 35.5 frames in frame-0 trials after 200k frames against 34.6."""
    root_rot: float = 0.0
    """Root (anchor) orientation, angle (rad); 0 turns the factor off."""
    feet_pos: float = 0.0
    """Feet (ankle and toe bodies), mean squared position error (m^2); 0 turns the factor off. The near/far
    weighting leaves the feet, far from a carried object, with almost no position reward and the window lowers
    their rotation lambda, so nothing asks the legs to step where the reference steps (DeepMimic's end-effector
    term)."""
    root_vel: float = 0.0
    """Root linear velocity (s^2/m^2): exp(-root_vel * |v_ref - v|^2) with v_ref the reference's central difference
    at the tracked frame (DeepMimic's and BeyondMimic's anchor velocity term). Positions and rotations say where
    the body should be but not that it should be moving: a policy that stands while the reference walks loses
    only through the position factors' slow growth and the body-error termination. 0 turns the factor off."""
    body_vel: float = 0.0
    """Body linear velocities (s^2/m^2): exp(-body_vel * mean_b |v_ref,b - v_b|^2) over every body, unweighted
    (BeyondMimic's body linear velocity term); 0 turns the factor off."""
    feet_contact: float = 0.0
    """Foot-floor contact schedule: exp(-feet_contact * E), E = the share of foot bodies (``roles["feet"]``) whose
    simulated floor contact differs from the reference's (a reference foot stands while its lowest geom is within
    2 cm of the standing height, :func:`wristmimic.env.grounding.foot_floor_contact`). Position factors leave a
    foot that drags on the floor through the reference's swing almost unpenalised until it falls behind; this
    rewards lifting it (the contact schedules of legged-robot locomotion rewards). 0 turns the factor off."""
    fingertip: float = 0.0
    """Contact guidance (1/m): exp(-fingertip * E), E = over the hands in reference contact, the mean distance of
    the hand's fingertips to the nearest object surface point (the ``ig_points`` sample). It asks the fingers to
    close on the object without any finger reference (the binary contact-hand factor is satisfied by one
    touching segment); 0 turns the factor off."""
    drive: float = 0.0
    """Carry, do not lean (1 per share of the object's weight): exp(-drive * E), E = the humanoid's contact force
    on the object against the reference object's direction of motion (the tracked frame's velocity, where it
    moves faster than 5 cm/s), over the object's weight; pushing along the motion or sideways costs nothing.
    With the object controller carrying the object, every sub2 policy leant on the table and pushed it against its
    motion (``scripts/assisted_rollout.py --loads``: 21-97 N at every gain) while the controller dragged it; the
    object factors cannot see this while the controller keeps the object on its reference. One dynamic object
    only; 0 turns the factor off."""


@dataclass(frozen=True)
class WindowConfig:
    """Contact window [t_c - t_b, t_c + t_a] and its phases (paper: tau1 = -2, tau2 = 12)."""

    t_b: int = 10
    t_a: int = 15
    tau1: int = -2
    """Approach ends / grasping starts at t_c + tau1."""
    tau2: int = 12
    """Grasping ends / stabilisation starts at t_c + tau2."""


@dataclass(frozen=True)
class WristThresholds:
    """Wrist reset thresholds per phase (position m, rotation rad); grasping is the tight one."""

    approach_pos: float = 0.15
    approach_rot: float = 0.5
    grasp_pos: float = 0.07
    grasp_rot: float = 0.2
    stabilize_pos: float = 0.15
    stabilize_rot: float = 0.5


@dataclass(frozen=True)
class TerminationConfig:
    """Base terminations (InterMimic): fall, body error, object error, contact lost."""

    fall_height: float = 0.3
    """Root height below this (m) ends the episode."""
    body_error: float = 0.5
    """Mean key-body position error above this (m) ends the episode."""
    object_error: float = 0.5
    """Mean object surface-point error above this (m) ends the episode."""
    contact_lost_frames: int = 10
    """Reference hand in contact but no simulated hand-object contact for more than this many frames."""
    grace_frames: int = 1
    """Kinematic terminations start after this many steps of an episode."""


@dataclass(frozen=True)
class ObjectControllerConfig:
    """Training-only virtual object controller (DexMachina): a PD wrench pulls each dynamic object toward its
    reference pose of the frame being stepped to, scaled by a gain the training curriculum lowers to exactly
    zero. Gains are per unit mass / inertia, so one setting fits every object. Evaluation, ``view`` and
    ``export`` build scenes without the controller's actuators and never apply it."""

    enabled: bool = True
    """Use the controller during training (the curriculum starts at ``initial_gain``)."""
    kp: float = 100.0
    """Position stiffness (1/s^2): force = gain * m * (kp e_p + kd e_v + gravity compensation)."""
    kd: float = 20.0
    """Linear damping toward the reference velocity (1/s); critical for kp = 100."""
    kr: float = 100.0
    """Rotation stiffness (1/s^2, per unit of the mean principal inertia)."""
    dr: float = 20.0
    """Angular damping toward the reference angular velocity (1/s)."""
    initial_gain: float = 1.0
    """Gain at the start of training (1: the object follows its reference and its weight is carried)."""
    decay: float = 0.8
    """The gain is multiplied by this after every iteration whose episodes pass ``survival``."""
    survival: float = 0.5
    """Decay when the iteration's gate statistic (``gate``; by default the projected full-clip survival
    (1 - terminations / steps)^(T - 1)) is above this."""
    gate: str = "hazard"
    """What ``survival`` and ``recover`` compare against. ``hazard``: the iteration's projected full-clip survival
    (1 - terminations / steps)^(T - 1). ``completion``: the share of the iteration's ended episodes that reached
    the end of the clip (or ``max_episode_frames``) unterminated (DexMachina's "episodes reach full length"); with failure-weighted start
    frames most episodes start where the policy fails, so their termination rate per step stays high however much
    the controller helps, while completion measures whether the help carries the policy from there to the end."""
    recover: float = 0.0
    """Dial the help back (DexMachina): after every iteration whose gate statistic is below this, the gain is
    divided by ``decay`` (at most ``initial_gain``, and never above the frame cap), so over a long run the gain
    settles where the policy just completes the clip and falls to zero only as the policy takes the object over.
    Must be below ``survival``; 0: off (the gain only falls). A gain that reached exactly zero stays zero."""
    min_gain: float = 0.05
    """A gain below this becomes exactly zero."""
    zero_by_frames: int = 150_000
    """The gain is also capped by 1 - frames / zero_by_frames: exactly zero after this many training frames
    (a fixed count, not a share of the budget, so a run resumed with a larger budget continues bit for bit)."""
    weight_zero_by_frames: int = 0
    """A separate gravity ramp (ManipTrans): the weight-carrying part of the wrench (m g) keeps the gain
    max(pose gain, 1 - frames / weight_zero_by_frames), reaching exactly zero after this many frames, so the
    policy learns to hold and move the object before it learns to lift it. 0: the weight follows the pose gain."""
    spread: float = 0.0
    """Training only: each episode scales the controller's gain (pose and weight) by its own u ~ U(1 - spread, 1),
    drawn when the world resets, so at every stage of the curriculum some episodes get less help than the
    batch's gain, down to none with spread 1, and the policy meets the takeover of the object throughout
    instead of only as the gain falls. 0: every world gets the curriculum's gain."""
    horizontal: float = 1.0
    """Share of the position PD's horizontal (world x, y) force that is applied while the reference object moves
    (faster than the drive factor's 5 cm/s); at rest, and for the vertical force, the weight support and the
    torque, the controller is unchanged. 0: while the reference carries the object the controller holds its
    height, tilt and weight but leaves moving it across the floor to the humanoid, so a pushed object slides away
    instead of serving as a support it can lean on (``sub2_largetable_000``'s policies lean on the table the full
    controller drags); at rest it still holds the object in place, so a touch on the way to the grasp does not
    slide an object whose weight it carries."""
    start_hold_frames: int = 0
    """Training only: after a reset at a start frame > 0 the controller also holds that world's objects, at gain
    1 - steps / start_hold_frames (the larger of this and the curriculum's gain), so a start mid-carry, whose
    mocap grip need not hold in simulation (``s110_move_kettle``'s fingers lie inside the handle and the kettle
    falls within 5-10 frames whatever the fingers do), leaves the hands that many frames to take the object over.
    Frame-0 starts (the evaluation protocol's) never get it; 0: off."""


@dataclass(frozen=True)
class RootAssistConfig:
    """Training-only root assist: a PD wrench on the humanoid's root (pelvis) pulling it toward the reference's
    root pose, as the virtual object controller pulls the object (a "hand of god" curriculum for locomotion;
    residual force control). Its gain falls linearly from ``initial_gain`` to exactly 0 at ``zero_by_frames``;
    evaluation and viewers never apply it (their scenes have no root motors)."""

    enabled: bool = False
    """Add six motors on the root's free joint to the training scene and drive them."""
    kp: float = 100.0
    """Position gain (1/s^2), times the humanoid's total mass: world force."""
    kd: float = 20.0
    """Linear velocity gain (1/s), times the total mass."""
    kr: float = 100.0
    """Rotation gain (1/s^2, on the local rotation vector), times ``inertia``: local torque."""
    dr: float = 20.0
    """Angular velocity gain (1/s), times ``inertia``."""
    inertia: float = 0.02
    """Radius of gyration squared (m^2) times the total mass gives the inertia the torque scales with. The wrench
    is held over the control step's substeps and the torque acts on the pelvis alone: on sub2 0.05 already
    destabilises the replay (body error in 17-24 steps), 0.02 does not."""
    initial_gain: float = 1.0
    """Gain at frame 0 of training."""
    zero_by_frames: int = 300_000
    """Training frames at which the gain reaches 0 (linear)."""
    min_gain: float = 0.05
    """Below this the gain is 0."""


@dataclass(frozen=True)
class HandAdhesionConfig:
    """Training-only contact guidance: MuJoCo adhesion actuators on every hand body (palm and finger segments)
    pull a touching hand body and what it touches together, so a hand that reaches the object while the reference
    hand touches it can hold and move it before the fingers have learnt a grip. Each body's pull is ``force`` x the
    curriculum's gain, only while that side's reference hand touches the object (at the frame being stepped to)
    and only through contacts the body already has (no pull at a distance). The gain falls linearly from
    ``initial_gain`` to exactly 0 at ``zero_by_frames``; evaluation and viewers never apply it (their scenes have no
    adhesion actuators). Issue #14's "contact guidance" lever, beside the object controller and the gravity ramp.
    Off by default: at 20 N per body to 400k frames (2026-12-07, seed 0, 600k frames) sub2 ended at 52.4 frames and
    the kettle at 49.7, 0 % each, where they end without it (``reports/contact_guidance_20261207/``)."""

    enabled: bool = False
    """Add an adhesion actuator to every hand body of the training scene and drive them."""
    force: float = 10.0
    """Pull (N) of each touching hand body at full gain."""
    initial_gain: float = 1.0
    """Gain at frame 0 of training."""
    zero_by_frames: int = 300_000
    """Training frames at which the gain reaches 0 (linear)."""
    min_gain: float = 0.05
    """Below this the gain is 0."""


@dataclass(frozen=True)
class StartSamplingConfig:
    """Where training episodes start (besides the ``reset_frame0_prob`` share at frame 0)."""

    adaptive: bool = True
    """Start in proportion to recent failures (BeyondMimic); False: uniform over the clip (InterMimic's RSI)."""
    bin_frames: int = 10
    """Frames per bin of the failure statistics (BeyondMimic: 1 s; short clips need finer bins)."""
    alpha: float = 0.01
    """Moving-average rate of the failures per environment step."""
    uniform: float = 0.1
    """Share of starts drawn uniformly over the bins."""
    kernel: int = 3
    """A bin's weight includes the failures of this many bins from it on."""
    kernel_lambda: float = 0.8
    """Weight lambda^k of the failures k bins later."""
    bank: float = 0.0
    """Share of the starts at a frame f > 0 that restore a state the policy itself reached at f (from a frame-0
    start; :class:`wristmimic.env.starts.StateBank`) instead of the reference's, where one is banked. 0: off."""
    bank_size: int = 16
    """States kept per frame (the newest, in random slots)."""
    reference_until: int = -1
    """>= 0: reference states are trusted only up to this frame. A training start after it that does not restore
    a banked state starts instead at ``f mod (reference_until + 1)``, and reference starts up to it count as reached
    by simulation (they bank what they reach). For clips whose mocap grasp is not physically valid: on
    ``s110_move_kettle`` the reference's hooked fingers lie inside the handle's hulls from frame ~35, and a start
    there (depenetrated or not, the body held on its reference) drops the kettle within 5-10 frames whatever the
    policy does, so failure-weighted starts spend most episodes where nothing can be learnt. -1: off."""
    depenetrate: bool = False
    """Reference starts move the hinges of each finger chain that lies more than ``depenetrate_tol`` inside an
    object, wall or floor until it does not (:mod:`wristmimic.env.depenetrate`; fingers have no pose targets, so
    their start angles are free). Frame-0 starts change only where frame 0 already penetrates. Off: on
    sub2_largetable_000 it shortened training episodes and left frame-0 trials where they were (see the module)."""
    depenetrate_tol: float = 0.003
    """Penetration (m) a finger chain may keep at a reference start."""


@dataclass(frozen=True)
class FeedforwardConfig:
    """Sampling-based trajectory optimisation of open-loop PD-target offsets before training
    (:mod:`wristmimic.env.feedforward`); residual actions only."""

    enabled: bool = False
    """Optimise offsets at the start of training (saved with the run; evaluation and view reuse them). Off by
    default: on synth_default it cut the zero-action replay's root drift from 11 to 2-4 cm and lengthened its
    frame-0 survival from 40 to 51 frames (~95 s of search), but a policy trained 200k frames with it reached
    39.8 frames in frame-0 trials against 41.2 without."""
    knot_frames: int = 6
    """Frames between knots (offsets interpolate linearly)."""
    horizon_knots: int = 4
    """Knots optimised together (the rollout window)."""
    samples: int = 64
    """Worlds per cross-entropy iteration."""
    iterations: int = 4
    """Cross-entropy iterations per knot."""
    elite_frac: float = 0.125
    """Share of the cheapest samples whose mean becomes the next mean."""
    sigma: float = 0.1
    """Initial standard deviation of the knot perturbations (rad)."""
    sigma_decay: float = 0.6
    """Factor on sigma after each iteration."""
    seed: int = 0
    """Seed of the perturbations."""
    w_root: float = 100.0
    """Cost per m^2 of root position error, per frame."""
    w_root_rot: float = 1.0
    """Cost per rad of root orientation error."""
    w_wrist: float = 100.0
    """Cost per m^2 of mean wrist position error."""
    w_wrist_rot: float = 1.0
    """Cost per rad of mean wrist orientation error."""
    w_object: float = 100.0
    """Cost per m^2 of mean object position error."""
    w_object_rot: float = 1.0
    """Cost per rad of mean object orientation error."""
    w_contact: float = 0.5
    """Cost per hand without object contact where the reference hand has it."""
    w_offset: float = 0.01
    """Cost per rad^2 of the window's knot offsets (keeps them small)."""
    fall_cost: float = 10.0
    """Cost of every frame from a fall (root height or body error beyond the termination thresholds) on."""


@dataclass(frozen=True)
class EnvConfig:
    """The WristMimic environment. Defaults = the paper's method (variant 'wristmimic')."""

    variant: str = "wristmimic"
    goal_horizons: tuple[int, ...] = (1, 16)
    """Future reference frames in the goal observation (InterMimic: t+1 and t+16)."""
    window_modulation: bool = True
    """Inside the contact window: arm weights 0, wrist terms kept, body weights reduced (gbp, gbr)."""
    wrist_resets: bool = True
    """Phase-specific wrist thresholds inside the contact window."""
    wrist_terms: bool = True
    """Separate wrist position/rotation reward factors (gwp, gwr); else wrists count as body joints."""
    wrist_frame: str = "world"
    """Where the wrist reward factors and the wrist reset measure a wrist's target. ``world``: the reference's wrist
    pose (the paper). ``object``: in frames where the reference's hand touches an object, the reference wrist pose
    relative to the reference object, carried by the simulated object (``env/vec_env.py``,
    :meth:`~wristmimic.env.vec_env.WristMimicEnv.wrist_targets`), so a hand is asked to stay where it grips the
    object wherever the object is, not to leave it when the object lags its reference. Observations, the other
    terms and the evaluation's errors keep the world reference."""
    reward_form: str = "product"
    """How the reward factors exp(-lambda E) combine. ``product``: their product (the paper, InterMimic), so one
    factor near 0 zeroes the step's reward. ``mean``: their mean (DeepMimic's and BeyondMimic's weighted sum, equal
    weights), which keeps partial credit for the terms still tracked."""
    finger_targets: bool = False
    """Finger pose targets in the goal observation and finger pose rewards."""
    weights: RewardWeights = field(default_factory=RewardWeights)
    window: WindowConfig = field(default_factory=WindowConfig)
    wrist: WristThresholds = field(default_factory=WristThresholds)
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    ig_points: int = 128
    """Object surface points (a seeded subset of the 1,024 stored) for the interaction graph, nearest-point
    features and object error. InterMimic uses all 1,024; on CPU the all-pairs graph then costs as much as
    the physics (benchmarks/env_step.py), 128 keeps the environment >= 80 % inside MuJoCo."""
    math_threads: int = 1
    """torch threads for observation/reward math inside ``step``; 1 avoids OpenMP contention with the
    physics threads on small machines (restored afterwards)."""
    contact_force_threshold: float = 0.1
    """A body counts as in contact when its net contact force exceeds this (N)."""
    max_episode_frames: int = 300
    """Training episodes are truncated after this many frames (InterMimic rolloutLength 300)."""
    reset_frame0_prob: float = 0.1
    """Reference state initialisation: probability of starting at frame 0 (else from ``starts``)."""
    starts: StartSamplingConfig = field(default_factory=StartSamplingConfig)
    """Start frames of training episodes that do not start at frame 0."""
    object_controller: ObjectControllerConfig = field(default_factory=ObjectControllerConfig)
    """Training-only object curriculum (virtual object controller)."""
    root_assist: RootAssistConfig = field(default_factory=RootAssistConfig)
    """Training-only root assist (off)."""
    hand_adhesion: HandAdhesionConfig = field(default_factory=HandAdhesionConfig)
    """Training-only contact guidance: adhesion of the hand bodies to what they touch (off)."""
    feedforward: FeedforwardConfig = field(default_factory=FeedforwardConfig)
    """Open-loop PD-target offsets optimised before training (residual actions only)."""
    action_mode: str = "residual"
    """``residual``: body and wrist hinges target the reference angle of the frame being stepped to plus
    ``residual_scale * a``; finger hinges stay absolute (no finger reference: the method's premise, and a
    swapped hand has none). ``absolute``: every hinge targets offset + scale * a (InterMimic / paper parity)."""
    velocity_feedforward: bool = True
    """Residual hinges target q_ref + (kv / kp) q_ref_dot: the position actuator's damping then pulls toward the
    reference velocity instead of zero (no lag on moving joints)."""
    gravity_feedforward: bool = False
    """Residual upper-body hinges (not legs, not fingers) also target + tau_g(q_ref) / kp, the gravity load at the
    reference pose over the hinge's stiffness (:mod:`wristmimic.env.gravity`): PD alone sags under gravity."""
    carry_feedforward: bool = False
    """Residual arm and torso hinges also target J^T (m g / n) / kp in reference frames where an object is off its
    supports and n hands touch it: the torques that hold up its weight at each hand (:mod:`wristmimic.env.carry`);
    PD alone sags under a carried load."""
    grip_squeeze: float = 0.0
    """N; > 0: in the reference's antipodal two-handed holds (both hands on the object from opposite sides), each
    arm's residual hinges also target J^T (F n) / kp, pressing the wrist with F newtons toward the object
    (:mod:`wristmimic.env.squeeze`): PD tracking of palms that lie on the faces presses with no force, so nothing
    carries the object until the policy discovers the squeeze. 0: off."""
    ground_reference: bool = False
    """Lower the humanoid's reference (root and bodies, not the objects) by its floor clearance, so its feet
    stand on the simulated floor (:mod:`wristmimic.env.grounding`; sub2_largetable_000: 2.0 cm)."""
    foot_clearance: float = 0.0
    """m; > 0 bends each leg of the reference (after ``ground_reference``) so that a swinging foot's lowest point
    clears the floor by this much and a standing foot's does not sink into it (:func:`wristmimic.env.grounding.
    lift_feet`). sub2_largetable_000 shuffles back with its swing toe 0-7 mm above the floor, and a standing toe
    up to 1.5 cm inside it: simulated, the toe drags (76-114 N of friction over 16 frames of the first step)."""
    clear_hands: bool = False
    """Bend each arm of the reference (after ``foot_clearance``) so that no palm lies more than 2 mm inside an
    object, support or wall, the wrist keeping its reference orientation (:mod:`wristmimic.env.clearance`).
    sub2_largetable_000's palms lie up to 19 mm inside the table top through the carry (111 frames move, by up
    to 17 mm); tracking them means pushing the table away. Fingers are left as recorded."""
    wrist_offsets: tuple[float, ...] = ()
    """m; six numbers (left x, y, z, right x, y, z) or none (off): each hand of the reference (after
    ``clear_hands``) moved by that offset in the reference object's frame while the reference hand touches the
    object, ramped in and out over 10 frames, through its arm's hinges (the damped pseudo-inverse of the wrist's
    6-D Jacobian at the reference pose, so the hand keeps its orientation to first order; a first-order map: on
    sub2 the wrists move within 5-24 % of a 2-3 cm offset; :class:`wristmimic.env.clearance.ArmOffsetMap`).
    The offsets come from ``scripts/kinematic_grip_probe.py --wrist-offset``: a wrist path that, with the body on
    the reference and the right finger closure, carries the object, where the mocap one does not."""
    finger_grip: tuple[float, ...] = ()
    """rad; one PD-target angle per finger hinge (in action order, left hand then right as the actuators come) or
    none (off): while the reference hand touches the object (ramped in over the first 10 frames of each contact
    and out over its last 10), that hand's finger actions are centred on this grip instead of the mid-range hand,
    so a = 0 holds it. The grip is a synthesised one, not a finger reference: ``scripts/kinematic_grip_probe.py``
    writes it (``finger_grip`` in its JSON) from a search over finger targets that carry the object with the body
    on the reference (the issue's sampling-based warm start, here as an action prior). Absolute or range finger
    actions only. (Ramped in over the 10 frames before contact, as ``wrist_offsets`` is, the curled fingers met
    sub2's table top on the way down: every trial ended on ``wrist`` at 33 frames.)"""
    finger_grip_from: int = 0
    """Reference frame before which ``finger_grip`` is off (ramped in over the 10 frames from it, also inside a
    contact): the probe's ``--start``, from which the grip it found holds (there, its hands already on the object)."""
    residual_scale: float = 0.5
    """rad per unit action of a body or wrist hinge in ``residual`` mode (before clipping to the joint range)."""
    action_scale: float = 1.0
    """Absolute targets (every hinge in ``absolute`` mode, fingers in ``residual`` mode) are
    offset + action_scale * scale * a with InterMimic's mid-range offset and half-range scale."""
    finger_action: str = "absolute"
    """How finger actions become PD targets (neither uses a finger reference). ``absolute``: offset +
    action_scale * scale * a, as above (a = 0 is the mid-range hand). ``delta``: each finger hinge keeps a held
    target, moved by ``finger_delta_scale * a`` every control step and clipped to its range; a reset sets it to
    the start state's angle, so a = 0 holds the current grip (DexMachina-style relative finger control). The
    held target minus the finger angle is then part of the observation (``finger_hold``). ``range``: like
    ``absolute``, but every finger hinge maps [-1, 1] onto exactly its joint range (mid-range offset, half-range
    scale), where ``absolute`` keeps InterMimic's rule for hinges whose range is off-centre (offset 0, scale pi:
    the flexing last segments, [-5.6, 90] deg, then see 3.4x the exploration noise of the others, 0.31 rad at
    sigma 0.1, and saturate for two thirds of the action interval)."""
    finger_delta_scale: float = 0.1
    """rad per unit action per control step of a ``delta`` finger target (a full 1.6 rad closure in 16 steps)."""
    finger_synergy: float = 0.0
    """rad; > 0 adds one action per hand (the last two: left, right) that moves every finger hinge's PD target by
    ``finger_synergy * g * c``: a one-dimensional grasp synergy whose positive direction curls the fingers toward
    the palm, with closure coefficients ``c`` from the humanoid's geometry, not from a reference
    (:mod:`wristmimic.env.synergy`). Not with ``finger_action=delta``. 0: off."""


LEGACY_ENV_DEFAULTS: dict = {
    "action_mode": "absolute",
    "velocity_feedforward": False,
    "gravity_feedforward": False,
    "ground_reference": False,
    "object_controller": {"enabled": False},
    "starts": {"adaptive": False, "bank": 0.0},
    "weights": {"root_pos": 0.0, "root_rot": 0.0},
    "feedforward": {"enabled": False},
}
"""What a run's recorded ``env`` meant when it predates a field: absolute actions, no object curriculum, uniform
starts, no root factors (merged one level deep: a recorded table keeps its own fields)."""


def overlay(base: dict, over: dict) -> dict:
    """``base`` with ``over``'s entries on top, nested tables merged one level deep."""
    out = dict(base)
    for key, value in over.items():
        both = isinstance(value, dict) and isinstance(base.get(key), dict)
        out[key] = {**base[key], **value} if both else value
    return out


def env_config_from_dict(data: dict) -> EnvConfig:
    """An :class:`EnvConfig` from a run's recorded ``env``; fields it predates keep their old behaviour."""
    from wristmimic.rl.config import from_jsonable

    return from_jsonable(EnvConfig, overlay(LEGACY_ENV_DEFAULTS, data))


def check_env_config(cfg: EnvConfig) -> None:
    """Refuse values no environment can run with (one-line ``ValueError``)."""
    if cfg.action_mode not in ACTION_MODES:
        raise ValueError(f"unknown action_mode {cfg.action_mode!r}; expected one of {', '.join(ACTION_MODES)}")
    if not cfg.residual_scale > 0 or not cfg.action_scale > 0:
        raise ValueError("residual_scale and action_scale must be > 0")
    if cfg.finger_action not in FINGER_ACTIONS:
        raise ValueError(f"unknown finger_action {cfg.finger_action!r}; expected one of {', '.join(FINGER_ACTIONS)}")
    if not cfg.finger_delta_scale > 0:
        raise ValueError(f"finger_delta_scale must be > 0, got {cfg.finger_delta_scale}")
    if cfg.wrist_frame not in WRIST_FRAMES:
        raise ValueError(f"unknown wrist_frame {cfg.wrist_frame!r}; expected one of {', '.join(WRIST_FRAMES)}")
    if cfg.reward_form not in REWARD_FORMS:
        raise ValueError(f"unknown reward_form {cfg.reward_form!r}; expected one of {', '.join(REWARD_FORMS)}")
    if not 0.0 <= cfg.finger_synergy <= math.pi:
        raise ValueError(f"finger_synergy must be in [0, pi] rad, got {cfg.finger_synergy}")
    if cfg.finger_synergy > 0 and cfg.finger_action == "delta":
        raise ValueError("finger_synergy works with absolute or range finger actions, not finger_action=delta")
    if not 0.0 <= cfg.grip_squeeze < math.inf:
        raise ValueError(f"grip_squeeze must be a finite force >= 0 N, got {cfg.grip_squeeze}")
    if not isinstance(cfg.clear_hands, bool):
        raise ValueError(f"clear_hands must be true or false, got {cfg.clear_hands!r}")
    if len(cfg.wrist_offsets) not in (0, 6) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= 0.2 for v in cfg.wrist_offsets
    ):
        raise ValueError(
            f"wrist_offsets must be empty or six numbers within +-0.2 m (left x y z, right x y z), got"
            f" {list(cfg.wrist_offsets)!r}"
        )
    if not all(isinstance(v, int | float) and not isinstance(v, bool) and abs(v) <= math.pi for v in cfg.finger_grip):
        raise ValueError(f"finger_grip must be empty or angles within +-pi rad, got {list(cfg.finger_grip)!r}")
    if isinstance(cfg.finger_grip_from, bool) or not isinstance(cfg.finger_grip_from, int) or cfg.finger_grip_from < 0:
        raise ValueError(f"finger_grip_from must be a frame >= 0, got {cfg.finger_grip_from!r}")
    if cfg.finger_grip and cfg.finger_action == "delta":
        raise ValueError("finger_grip works with absolute or range finger actions, not finger_action=delta")
    if not 0.0 <= cfg.weights.drive < math.inf:
        raise ValueError(f"weights.drive must be a finite weight >= 0, got {cfg.weights.drive}")
    if not 0.0 <= cfg.foot_clearance <= 0.1:
        raise ValueError(f"foot_clearance must be in [0, 0.1] m, got {cfg.foot_clearance}")
    st = cfg.starts
    if st.bin_frames < 1 or st.kernel < 1 or not 0 < st.alpha <= 1 or not 0 <= st.uniform <= 1:
        raise ValueError("starts: bin_frames and kernel >= 1, alpha in (0, 1], uniform in [0, 1]")
    if not 0 <= st.bank <= 1 or st.bank_size < 1:
        raise ValueError("starts: bank in [0, 1], bank_size >= 1")
    if not st.reference_until >= -1:
        raise ValueError("starts: reference_until >= -1 (frames; -1: off)")
    if not st.depenetrate_tol >= 0:
        raise ValueError("starts: depenetrate_tol >= 0 (m)")
    oc = cfg.object_controller
    if not 0.0 <= oc.spread <= 1.0:
        raise ValueError("object_controller.spread must be in [0, 1]")
    if oc.gate not in ("hazard", "completion"):
        raise ValueError(f"object_controller.gate must be 'hazard' or 'completion', got {oc.gate!r}")
    if not 0.0 <= oc.recover < oc.survival:
        raise ValueError(f"object_controller.recover must be in [0, survival = {oc.survival}), got {oc.recover}")
    if not 0.0 <= oc.horizontal <= 1.0:
        raise ValueError(f"object_controller.horizontal must be in [0, 1], got {oc.horizontal}")
    if not 0.0 < oc.decay <= 1.0:
        raise ValueError(f"object_controller.decay must be in (0, 1], got {oc.decay}")
    if oc.start_hold_frames < 0 or (oc.start_hold_frames > 0 and not oc.enabled):
        raise ValueError("object_controller.start_hold_frames must be >= 0 and needs the controller enabled")
    ra = cfg.root_assist
    if ra.enabled and (ra.zero_by_frames < 1 or not ra.initial_gain >= 0 or not ra.inertia > 0):
        raise ValueError("root_assist: zero_by_frames >= 1, initial_gain >= 0, inertia > 0")
    ha = cfg.hand_adhesion
    if ha.enabled and (ha.zero_by_frames < 1 or not ha.initial_gain >= 0 or not 0 <= ha.force <= 1000):
        raise ValueError(
            f"hand_adhesion: zero_by_frames >= 1, initial_gain >= 0 and force in [0, 1000] N, got"
            f" {ha.zero_by_frames}, {ha.initial_gain}, {ha.force}"
        )


def variant_config(name: str, **overrides: object) -> EnvConfig:
    """The paper's variants by name; ``overrides`` replace fields (e.g. ``wrist=WristThresholds(...)``)."""
    flags = {
        "wristmimic": dict(window_modulation=True, wrist_resets=True, wrist_terms=True, finger_targets=False),
        "decoupled": dict(window_modulation=False, wrist_resets=False, wrist_terms=False, finger_targets=False),
        "reward-modulation-only": dict(
            window_modulation=True, wrist_resets=False, wrist_terms=True, finger_targets=False
        ),
        "reset-only": dict(window_modulation=False, wrist_resets=True, wrist_terms=True, finger_targets=False),
        "finger-guidance": dict(window_modulation=True, wrist_resets=True, wrist_terms=True, finger_targets=True),
        "intermimic": dict(window_modulation=False, wrist_resets=False, wrist_terms=False, finger_targets=True),
    }
    if name not in flags:
        raise ValueError(f"unknown variant {name!r}; expected one of {', '.join(VARIANTS)}")
    return replace(EnvConfig(variant=name, **flags[name]), **overrides)  # type: ignore[arg-type]
