"""MuJoCo scene of one canonical sequence, built with ``MjSpec``.

The humanoid comes from the MJCF stored in the canonical file, re-actuated for MuJoCo: its joint
``stiffness``/``damping`` (Isaac Gym PD gains) become position actuators (kp, kv) with the paper's gains per
body part, joint springs and damping are zeroed, armature 0.02, the MJCF's geom densities, finger ranges as
InterMimic (a humanoid with a swapped hand, :mod:`wristmimic.humanoid.hands`, keeps the ranges its MJCF carries),
and self-collision is off. Each dynamic object is a free body with one mesh geom per coacd hull and the stored
mass/inertia (from the visual mesh, not the hull sum); static objects (real or inferred supports) are fixed at
their frame-0 pose. Sensors give everything the environment observes, so a batch of worlds can be stepped by
``mujoco.rollout`` with no Python per world.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import mujoco
import numpy as np

from wristmimic.errors import InputError
from wristmimic.format.reader import Dataset, SequenceView
from wristmimic.format.records import HumanoidRecord, ObjectRecord
from wristmimic.format.validate import check_sequence
from wristmimic.humanoid.skeleton import Skeleton, load_skeleton

# collision bits: humanoid geoms never collide with each other, everything else collides with everything
HUMANOID_CONTYPE, HUMANOID_CONAFFINITY = 2, 1
WORLD_CONTYPE, WORLD_CONAFFINITY = 1, 3
# contact sensor intprm = [data field bits, reduce mode, num] (MJCF data="found force", reduce="netforce")
_DATA_FOUND, _DATA_FORCE = 1, 2
_REDUCE_NONE, _REDUCE_NETFORCE = 0, 3
FINGER_WIDE = np.deg2rad(55.625)
FINGER_NARROW = np.deg2rad(5.625)
FINGER_FLEX = np.deg2rad(90.0)


@dataclass(frozen=True)
class Gains:
    """PD gains (stiffness N m/rad, damping N m s/rad) per body part (paper supplement)."""

    legs: tuple[float, float] = (800.0, 80.0)
    torso: tuple[float, float] = (1000.0, 100.0)
    arms: tuple[float, float] = (500.0, 50.0)
    toes: tuple[float, float] = (500.0, 50.0)
    fingers: tuple[float, float] = (100.0, 10.0)


@dataclass(frozen=True)
class SceneConfig:
    """Physics settings of a scene. Timestep and substeps were chosen by ``tests/test_scene.py``: replaying
    every shared reference through the PD controller stays finite and bounded."""

    timestep: float = 1.0 / 120.0
    substeps: int = 4
    """Physics steps per 30 Hz control step."""
    integrator: str = "implicitfast"
    """Euler integrates the light fingers' actuator damping explicitly and explodes at dt >= 1/240."""
    solver: str = "newton"
    """MuJoCo constraint solver: newton, cg or pgs (``benchmarks/physics_sweep.py`` measures each). PGS with 20
    iterations trains 1.24-1.33x faster on sub2_largetable_000 and s110_move_kettle (``benchmarks/train_throughput.py
    --compare``) but fails issue #15's fidelity gate (2026-12-06, the recipe of 2026-12-05, 256 quick trials at 400k
    frames, ``reports/pgs_gate_20261206/``): 8 of 9 synthetic runs succeed as often or more (synth_high_table s0 / s1
    100 / 99.6 % against Newton's 83.6 / 77.7 %), but synth_default on the 1.55 m humanoid falls to 40.6 % against
    Newton's 100 % periodic evaluations on the same machine. So Newton stays the default; MuJoCo Warp has no PGS
    (a PGS scene on ``--backend warp`` steps with Newton, 100 iterations)."""
    iterations: int = 100
    """Solver iterations at most (MuJoCo's default; Newton stops at ``tolerance``, ~3 per step on OMOMO; PGS runs
    all of them)."""
    ls_iterations: int = 50
    """Line-search iterations at most (Newton and CG)."""
    tolerance: float = 1e-8
    """Solver tolerance (MuJoCo's default)."""
    cone: str = "pyramidal"
    """Friction cone: pyramidal (MuJoCo's default) or elliptic."""
    impratio: float = 1.0
    """Ratio of frictional to normal constraint impedance (MuJoCo's ``impratio``, default 1). MuJoCo's soft
    friction lets a held object creep under a tangential load below its friction limit; values above 1 make
    friction stiffer than the normal constraint (MuJoCo recommends them with elliptic cones)."""
    noslip_iterations: int = 0
    """MuJoCo's no-slip post-solver iterations (0: off, MuJoCo's default)."""
    refsafe: bool = True
    """MuJoCo's ``refsafe`` (its default): every contact's time constant (``solref[0]``, 0.02 s for SMPL-X's geoms)
    is raised to at least twice the timestep. At 1/120 s that binds nothing but ParaHome's 0.015 s; at 1/60 s it
    softens every contact to 0.033 s, and a squeeze grip then sags: with the body held on its reference
    (``scripts/kinematic_grip_probe.py``, synth_default, frames 40-110, both hands, the reference's fingers) the box
    lags its reference by 12.1 cm on average at 1/60 s, and by 12.1 cm at 1/120 s with the time constant set to
    0.033 s, against 6.7 cm at 1/120 s. False keeps the MJCF's time constants at any timestep (5.5 cm at 1/60 s). With
    it off, the recipe on synth_default at 1/60 s x 2 (400k frames, seed 0, 256 quick trials; 2026-12-07,
    ``reports/timestep_refsafe_20261207/``) succeeds in 10.5 % with Newton (3.1 % with it on) and 21.9 % with PGS 20
    iterations (0 % with it on), against 100 % at 1/120 s x 4: it explains part of why longer steps lose the grasp,
    not all, so the default keeps MuJoCo's."""
    armature: float = 0.02
    density: float | None = None
    """Density (kg/m^3) of every humanoid geom; None keeps the MJCF's own. PHC's and SkillMimic's humanoids weigh
    their capsules by part (pelvis 4629.6, thighs 2040.8, shins 1234.6, 1000-1100 elsewhere): sub2 of OMOMO then
    weighs 77.1 kg and ParaHome's s110 45.1 kg; a uniform 1000 (the value before 2026-12-02, which runs recorded
    then keep) made them 49.4 and 27.3 kg, so sub2 carried a table of 41 % of its own mass."""
    gains: Gains = field(default_factory=Gains)
    hand_condim: int = 4
    """Contact dimensionality of the hand geoms (palms and fingers): 4 adds torsional friction to MuJoCo's sliding
    friction (3): a soft pad's contact patch resists twisting about its normal, as PhysX's patch friction does in
    Isaac Gym. With 3, a box squeezed between two palms pivots about the line between them: on synth_default the
    recipe's policies tipped the box forward during the lift (rotation error 44-53 deg at 600k frames); with 4 and
    0.015 m (and ``weights.orot`` 1.0) the box stays level (8 deg) and 99.6 % of trials succeed after 405k frames."""
    contact_condim: int | None = 3
    """Contact dimensionality of every other colliding geom (humanoid, floor, object hulls): 3 = sliding friction.
    None keeps the source MJCF's: SkillMimic's ParaHome humanoid says condim 1 (frictionless in MuJoCo; Isaac Gym,
    which it was written for, ignores condim), so its feet slid on the floor and objects on their supports."""
    hand_torsional_friction: float = 0.015
    """Torsional friction coefficient (m) of the hand geoms when ``hand_condim`` >= 4: about mu * (2/3) r for a
    contact patch of radius r ~ 2 cm (MuJoCo's default is 0.005)."""
    hand_friction: float | None = 2.0
    """Sliding friction of the hand geoms (palms and fingers); None keeps the MJCF's (1 for SMPL-X). MuJoCo takes the
    larger of two geoms' frictions (or the higher priority's under ``support_friction``), so this sets the hands'
    grip on objects without touching the objects' friction with the floor or their supports. 2 by measurement
    (2026-12-06, ``reports/hand_friction_20261206/``): a squeeze lift then needs half the normal force, the recipe
    finds it earlier, and all thirteen synthetic recipe runs pass 80 % where two did not with the MJCF's 1."""
    object_damping: float = 0.01
    """Linear/angular damping of dynamic objects (free-joint dof damping)."""
    object_friction: float | None = None
    """Sliding friction of object geoms; None: the URDF's lateral friction, else MuJoCo's default 1."""
    support_friction: float | None = None
    """Sliding friction of a dynamic object's contacts with everything but the hands: the floor, static objects,
    non-hand body parts. None: MuJoCo's rule, the larger of the two geoms' (the floor's 1.0 for OMOMO objects).
    When set, dynamic-object hulls take MuJoCo geom priority 1 with this friction and hand geoms priority 2, so
    hand-object contacts keep the hands' friction. OMOMO's sub2 drags its large table with the far legs on the
    floor (5-9 mm above it in the reference): at 1.0 the legs hold ~150 N of the 200 N table and resist the carry
    with 40-60 N. Isaac Gym averages the two (InterMimic: object 0.6, ground 0.9 -> 0.75)."""
    object_density: float | None = None
    """Density (kg/m^3) of the dynamic objects: mass and inertia are scaled from the canonical file's (which
    records the density it used, 1000 for OMOMO and ParaHome conversions); None keeps them. InterMimic trained
    OMOMO with 200 (``omomo_train.yaml``; 1000 in ``omomo_train_new.yaml``): sub2's large table weighs 20.4 kg at
    1000 and 4.1 kg at 200."""
    finger_ranges: str = "intermimic"
    """Finger joint ranges: ``intermimic`` (:func:`finger_ranges`, written for SMPL-X's joint frames) or
    ``reference``: where the sequence's own finger angles leave a finger hinge's InterMimic range, that end moves
    to the reference's extreme plus ``finger_range_margin``; ranges the reference stays inside are unchanged.
    ParaHome's skeleton (SkillMimic's MJCF declares +-180 deg) has joint frames of its own
    (the metacarpals' rest splay, the thumb base turned up to 98 deg): InterMimic's ranges cut 20-27 % of its
    finger hinge-frames, by up to 1.9 rad, so its grips are out of reach and a reference start begins outside the
    joint limits. OMOMO and the synthetic scenes lie inside InterMimic's ranges, so both settings build the same
    scene for them. Only the limits come from the reference: finger targets still use none. Swapped hands keep
    their MJCF's."""
    finger_range_margin: float = 0.1
    """rad beyond the reference's extreme angle where ``finger_ranges=reference`` moves a range end."""
    max_hull_vertices: int = 64
    floor: bool = True
    visual_meshes: bool = True
    """Add each object's visual mesh as a non-colliding geom (group 2) for viewers."""
    object_actuators: bool = False
    """Six force/torque motors on each dynamic object's free joint (``voc_<object>_<k>``, world force, local
    torque): the training-only virtual object controller drives them. Training adds them to its own scene;
    ``config.json``, evaluation and viewers never have them."""
    root_actuators: bool = False
    """Six force/torque motors on the humanoid root's free joint (``rac_<k>``, world force, local torque) for the
    training-only root assist (``EnvConfig.root_assist``); like ``object_actuators``, training scenes only."""
    hand_adhesion: bool = False
    """An adhesion actuator on every hand body (``adh_<body>``, 1 N per unit of control, control 0-1000) for the
    training-only contact guidance (``EnvConfig.hand_adhesion``); like ``object_actuators``, training scenes only."""

    @property
    def control_dt(self) -> float:
        return self.timestep * self.substeps


@dataclass
class SceneObject:
    """An object of the scene and where it lives in the model."""

    id: str
    record: ObjectRecord
    dynamic: bool
    body_id: int
    qposadr: int = -1
    dofadr: int = -1


@dataclass
class Scene:
    """A compiled scene and the index maps the environment needs."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    config: SceneConfig
    sequence_id: str
    humanoid: HumanoidRecord
    skeleton: Skeleton
    body_ids: np.ndarray  # (B,) model body id of each humanoid body
    hinge_qposadr: np.ndarray  # (J, 3)
    hinge_dofadr: np.ndarray  # (J, 3)
    actuator_ids: np.ndarray  # (J, 3) actuator of each hinge (ctrl index)
    ctrl_range: np.ndarray  # (J*3, 2)
    objects: list[SceneObject]
    sensors: dict[str, slice]  # name -> slice of sensordata
    gains: np.ndarray  # (J*3, 2) kp, kv per hinge

    @property
    def dynamic_objects(self) -> list[SceneObject]:
        return [o for o in self.objects if o.dynamic]

    @cached_property
    def nstate(self) -> int:
        return mujoco.mj_stateSize(self.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)

    def to_xml(self) -> str:
        """The scene as MJCF text (meshes inline), for inspection."""
        return self.spec.to_xml()


def gain_groups(skel: Skeleton, roles: dict[str, np.ndarray]) -> dict[str, list[int]]:
    """Body indices per gain group, from the tree: fingers, toes (foot leaves), legs (ancestors of the feet),
    torso (ancestors of the head's parent, root excluded), arms (every other non-root body)."""
    fingers = set(roles["fingers"].tolist())
    feet = set(roles["feet"].tolist())
    toes = {b for b in feet if not skel.children(b)}
    legs: set[int] = set()
    for f in feet - toes:
        b = f
        while b > 0:
            legs.add(b)
            b = int(skel.parents[b])
    head = int(roles["head"][0])
    torso: set[int] = set()
    b = int(skel.parents[int(skel.parents[head])])  # skip the neck
    while b > 0:
        torso.add(b)
        b = int(skel.parents[b])
    arms = set(range(1, skel.num_bodies)) - fingers - toes - legs - torso
    return {
        k: sorted(v) for k, v in {"fingers": fingers, "toes": toes, "legs": legs, "torso": torso, "arms": arms}.items()
    }


def finger_ranges(skel: Skeleton, roles: dict[str, np.ndarray]) -> dict[int, np.ndarray]:
    """InterMimic finger joint ranges (rad, (3, 2) per finger body), by position along each finger chain.

    Segment 1 and 2: x +-55.625 deg, y/z +-5.625; segment 3: x [-90, 5.625] (left) / [-5.625, 90] (right),
    y/z +-5.625. Thumb: segment 1 xyz +-55.625, segment 2 +-5.625. A chain of four (ParaHome: CMC, MCP, PIP,
    DIP) starts with a metacarpal kept near-rigid (+-5.625) and continues as segments 1..3.
    """
    wide, narrow = FINGER_WIDE, FINGER_NARROW
    out: dict[int, np.ndarray] = {}
    for side, sign in (("left", -1.0), ("right", 1.0)):
        wrist = int(roles["wrists"][0 if side == "left" else 1])
        for start in skel.children(wrist):
            chain = [start]
            while skel.children(chain[-1]):
                chain.append(skel.children(chain[-1])[0])
            name = skel.body_names[start]
            thumb = "Thumb" in name or "First" in name
            if len(chain) == 4 or (thumb and len(chain) == 3 and "CMC" in name):
                out[chain[0]] = np.array([[-narrow, narrow]] * 3)
                chain = chain[1:] if len(chain) == 4 else chain
            for k, b in enumerate(chain, start=1):
                if k >= 3:
                    flex = [-FINGER_FLEX, narrow] if sign < 0 else [-narrow, FINGER_FLEX]
                    out[b] = np.array([flex, [-narrow, narrow], [-narrow, narrow]])
                elif thumb and k == 1:
                    out[b] = np.array([[-wide, wide]] * 3)
                elif thumb:
                    out[b] = np.array([[-narrow, narrow]] * 3)
                else:
                    out[b] = np.array([[-wide, wide], [-narrow, narrow], [-narrow, narrow]])
    return out


SUPPORT_PRIORITY = 1
"""MuJoCo geom priority of dynamic-object hulls under ``support_friction`` (hands one above): the higher-priority
geom's friction governs a contact; equal priorities take the larger of the two."""


LEGACY_SCENE_DEFAULTS: dict = {
    "solver": "newton",
    "iterations": 100,
    "hand_condim": 3,
    "hand_torsional_friction": 0.005,
    "contact_condim": None,
    "density": 1000.0,
    "hand_friction": None,
}
"""What a run's recorded ``scene_config`` meant when it predates a field (sliding friction only on the hands, MuJoCo's
Newton solver)."""


def scene_config_from_dict(data: dict) -> SceneConfig:
    """A :class:`SceneConfig` from a run's recorded ``scene_config``; fields it predates keep their old values."""
    from wristmimic.rl.config import from_jsonable

    return from_jsonable(SceneConfig, {**LEGACY_SCENE_DEFAULTS, **data})


def _strip_source_extras(spec: mujoco.MjSpec) -> None:
    """Drop the source's actuators, world geoms (floor) and sensors: the scene adds its own."""
    for a in list(spec.actuators):
        spec.delete(a)
    for s in list(spec.sensors):
        spec.delete(s)
    for g in list(spec.worldbody.geoms):
        spec.delete(g)


def _humanoid(
    spec: mujoco.MjSpec,
    skel: Skeleton,
    roles: dict[str, np.ndarray],
    cfg: SceneConfig,
    own_ranges: bool = False,
    envelope: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Re-actuate the humanoid in ``spec``; returns (J*3, 2) gains in hinge order. Finger ranges are InterMimic's
    (:func:`finger_ranges`), unless ``own_ranges`` (a swapped hand carries its ranges in the MJCF); with
    ``envelope`` ((J, 3) lowest and highest reference angles) an end the reference passes moves to it plus
    ``cfg.finger_range_margin``."""
    groups = gain_groups(skel, roles)
    gain_of = {b: getattr(cfg.gains, g) for g, bodies in groups.items() for b in bodies}
    franges = {} if own_ranges else finger_ranges(skel, roles)
    if envelope is not None:  # widen only the ends the reference passes, to its extreme plus the margin
        row = {int(b): j for j, b in enumerate(skel.joint_bodies)}
        (amin, amax), margin = envelope, cfg.finger_range_margin
        for b, r in franges.items():
            lo, hi = amin[row[b]], amax[row[b]]
            franges[b] = np.stack(
                [np.where(lo < r[:, 0], lo - margin, r[:, 0]), np.where(hi > r[:, 1], hi + margin, r[:, 1])], 1
            )
    gains = []
    for j, b in enumerate(skel.joint_bodies):
        body = spec.body(skel.body_names[b])
        kp, kv = gain_of[int(b)]
        hinges = [jt for jt in body.joints if jt.type == mujoco.mjtJoint.mjJNT_HINGE]
        for k, jt in enumerate(hinges):
            jt.stiffness = np.zeros_like(np.asarray(jt.stiffness))
            jt.damping = np.zeros_like(np.asarray(jt.damping))
            jt.armature = cfg.armature
            rng = franges[int(b)][k] if int(b) in franges else skel.joint_range[j, k]
            jt.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            jt.range = np.rad2deg(rng) if spec.compiler.degree else rng  # spec ranges use the MJCF angle unit
            act = spec.add_actuator(name=f"pd_{jt.name}", target=jt.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=kp, kv=kv)
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = rng
            gains.append((kp, kv))
    hands = {skel.body_names[b] for side in ("left_hand", "right_hand") for b in roles.get(side, [])}
    for body in spec.bodies:
        for g in body.geoms:
            if cfg.density is not None:
                g.density = cfg.density
            g.contype, g.conaffinity = HUMANOID_CONTYPE, HUMANOID_CONAFFINITY
            if cfg.contact_condim is not None:
                g.condim = cfg.contact_condim
            if body.name in hands and cfg.hand_friction is not None:
                g.friction = [float(cfg.hand_friction), float(g.friction[1]), float(g.friction[2])]
            if body.name in hands and cfg.hand_condim != 3:
                g.condim = cfg.hand_condim
                g.friction = [float(g.friction[0]), cfg.hand_torsional_friction, float(g.friction[2])]
            if body.name in hands and cfg.support_friction is not None:
                g.priority = SUPPORT_PRIORITY + 1
    return np.asarray(gains, dtype=np.float64)


def _add_object(
    spec: mujoco.MjSpec, oid: str, rec: ObjectRecord, dynamic: bool, pos: np.ndarray, quat: np.ndarray, cfg: SceneConfig
) -> None:
    body = spec.worldbody.add_body(name=f"obj_{oid}", pos=pos, quat=quat)
    friction = cfg.object_friction if cfg.object_friction is not None else rec.urdf.get("lateral_friction")
    supported = dynamic and cfg.support_friction is not None
    if supported:
        friction = cfg.support_friction
    if dynamic:
        fj = body.add_freejoint(name=f"obj_{oid}")
        fj.damping = [cfg.object_damping, 0.0, 0.0]
        body.explicitinertial = True
        scale = 1.0 if cfg.object_density is None else float(cfg.object_density) / float(rec.density)
        body.mass = float(rec.mass) * scale
        body.ipos = np.asarray(rec.com, float)
        body.fullinertia = scale * np.asarray(rec.inertia, float)[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
    for k, (v, f) in enumerate(rec.hulls()):
        mesh = spec.add_mesh(
            name=f"{oid}_hull{k}",
            uservert=np.asarray(v, np.float32).ravel(),
            userface=np.asarray(f, np.int32).ravel(),
            maxhullvert=cfg.max_hull_vertices,
            inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX,
        )
        g = body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            name=f"{oid}_hull{k}",
            density=0.0,
            contype=WORLD_CONTYPE,
            conaffinity=WORLD_CONAFFINITY,
            group=3,
            rgba=[0.4, 0.6, 0.9, 0.3],
        )
        if friction is not None:
            g.friction = [float(friction), 0.005, 0.0001]
        if supported:
            g.priority = SUPPORT_PRIORITY
        if cfg.contact_condim is not None:
            g.condim = cfg.contact_condim
    if cfg.visual_meshes and not rec.inferred:
        mesh = spec.add_mesh(
            name=f"{oid}_visual",
            uservert=np.asarray(rec.vertices, np.float32).ravel(),
            userface=np.asarray(rec.faces, np.int32).ravel(),
            inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL,
        )
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            name=f"{oid}_visual",
            density=0.0,
            contype=0,
            conaffinity=0,
            group=2,
            rgba=[0.8, 0.7, 0.5, 1.0],
        )


SOLVERS, CONES = ("newton", "cg", "pgs"), ("pyramidal", "elliptic")
FINGER_RANGES = ("intermimic", "reference")
"""Values of :attr:`SceneConfig.finger_ranges`."""


def _set_solver(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    if cfg.solver not in SOLVERS or cfg.cone not in CONES:
        raise InputError(
            None, "scene_config", f"solver {cfg.solver!r}, cone {cfg.cone!r}", f"solver in {SOLVERS}, cone in {CONES}"
        )
    if cfg.iterations < 1 or cfg.ls_iterations < 1 or not cfg.tolerance >= 0.0:
        raise InputError(None, "scene_config", "iterations and ls_iterations >= 1, tolerance >= 0")
    if not (np.isfinite(cfg.impratio) and cfg.impratio >= 1.0) or cfg.noslip_iterations < 0:
        raise InputError(
            None,
            "scene_config",
            f"impratio {cfg.impratio!r}, noslip_iterations {cfg.noslip_iterations!r}",
            "a finite impratio >= 1 and noslip_iterations >= 0",
        )
    for name in ("density", "object_density"):
        v = getattr(cfg, name)
        if v is not None and not (np.isfinite(v) and v > 0):
            raise InputError(
                None, f"scene_config.{name}", f"invalid value {v!r}", "None or a finite number > 0 (kg/m^3)"
            )
    if cfg.finger_ranges not in FINGER_RANGES or not (
        np.isfinite(cfg.finger_range_margin) and cfg.finger_range_margin >= 0
    ):
        raise InputError(
            None,
            "scene_config.finger_ranges",
            f"{cfg.finger_ranges!r} with margin {cfg.finger_range_margin!r}",
            f"one of {', '.join(FINGER_RANGES)} and a finite margin >= 0 (rad)",
        )
    for name in ("object_friction", "support_friction", "hand_friction"):
        v = getattr(cfg, name)
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise InputError(None, f"scene_config.{name}", f"invalid value {v!r}", "None or a finite number >= 0")
    spec.option.solver = getattr(mujoco.mjtSolver, f"mjSOL_{cfg.solver.upper()}")
    spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{cfg.cone.upper()}")
    spec.option.iterations, spec.option.ls_iterations = int(cfg.iterations), int(cfg.ls_iterations)
    spec.option.tolerance = float(cfg.tolerance)
    spec.option.impratio = float(cfg.impratio)
    spec.option.noslip_iterations = int(cfg.noslip_iterations)
    if not isinstance(cfg.refsafe, bool):
        raise InputError(None, "scene_config.refsafe", f"invalid value {cfg.refsafe!r}", "true or false")
    if not cfg.refsafe:
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_REFSAFE)


def build_scene(ds: Dataset, sequence_id: str, config: SceneConfig | None = None) -> Scene:
    """Build the MuJoCo scene of ``sequence_id`` from an open canonical file."""
    cfg = config or SceneConfig()
    check_sequence(ds, sequence_id)  # the data gate: InputError naming file and key for the first problem
    seq: SequenceView = ds.sequence(sequence_id)
    hum = ds.humanoid(seq.humanoid_id)
    skel = load_skeleton(hum.mjcf, f"{ds.path}:humanoids/{seq.humanoid_id}")
    spec = mujoco.MjSpec.from_string(hum.mjcf)
    spec.modelname = f"wristmimic_{sequence_id}"
    _strip_source_extras(spec)
    spec.option.timestep = cfg.timestep
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{cfg.integrator.upper()}")
    _set_solver(spec, cfg)
    envelope = None
    if cfg.finger_ranges == "reference":
        a = seq.array("joint_angles")
        envelope = (a.min(0), a.max(0))
    gains = _humanoid(spec, skel, hum.roles, cfg, own_ranges=bool(hum.hand), envelope=envelope)
    if cfg.floor:
        floor = spec.worldbody.add_geom(
            name="floor",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[50, 50, 0.1],
            contype=WORLD_CONTYPE,
            conaffinity=WORLD_CONAFFINITY,
            rgba=[0.8, 0.9, 0.8, 1],
        )
        if cfg.contact_condim is not None:
            floor.condim = cfg.contact_condim
    obj_pos = seq.array("object_pos", slice(0, 1))[0]
    obj_quat = seq.array("object_quat", slice(0, 1))[0]
    records = {oid: ds.object(oid) for oid in seq.object_ids}
    dyn = [oid for oid in seq.object_ids if not records[oid].static]
    for k, oid in enumerate(seq.object_ids):
        _add_object(spec, oid, records[oid], oid in dyn, obj_pos[k], obj_quat[k], cfg)
    _add_sensors(spec, skel, dyn)
    if cfg.object_actuators:
        for oid in dyn:
            for k in range(6):
                act = spec.add_actuator(name=f"voc_{oid}_{k}", target=f"obj_{oid}")
                act.trntype = mujoco.mjtTrn.mjTRN_JOINT
                act.gear = [float(i == k) for i in range(6)]
                act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    if cfg.root_actuators:
        free = [j.name for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_FREE and not j.name.startswith("obj_")]
        if not free:
            raise InputError(ds.path, f"sequences/{sequence_id}", "root_actuators: the humanoid has no free root joint")
        for k in range(6):
            act = spec.add_actuator(name=f"rac_{k}", target=free[0])
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.gear = [float(i == k) for i in range(6)]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    if cfg.hand_adhesion:
        for b in sorted({int(b) for side in ("left_hand", "right_hand") for b in hum.roles.get(side, [])}):
            act = spec.add_actuator(name=f"adh_{skel.body_names[b]}", target=skel.body_names[b])
            act.trntype = mujoco.mjtTrn.mjTRN_BODY
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = [0.0, 1000.0]  # before set_to_adhesion: it refuses a negative range (an MJCF default's)
            act.set_to_adhesion(1.0)
    spec.add_numeric(name="wristmimic_control_substeps", data=[float(cfg.substeps)])
    spec.add_text(name="wristmimic_sequence", data=sequence_id)
    try:
        model = spec.compile()
    except Exception as exc:  # noqa: BLE001 - MuJoCo raises ValueError with the compiler's message
        raise InputError(ds.path, f"sequences/{sequence_id}", f"scene does not compile: {str(exc)[:200]}") from None
    return _index(spec, model, cfg, sequence_id, hum, skel, records, dyn, gains)


def _add_sensors(spec: mujoco.MjSpec, skel: Skeleton, dyn: list[str]) -> None:
    frames = [*skel.body_names, *(f"obj_{o}" for o in dyn)]
    kinds = (
        ("pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
        ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT),
        ("linvel", mujoco.mjtSensor.mjSENS_FRAMELINVEL),
        ("angvel", mujoco.mjtSensor.mjSENS_FRAMEANGVEL),
    )
    for kind, st in kinds:
        for name in frames:
            # XBODY = the body frame (BODY would be its inertial frame)
            spec.add_sensor(name=f"{kind}:{name}", type=st, objtype=mujoco.mjtObj.mjOBJ_XBODY, objname=name)
    for name in skel.body_names:
        s = spec.add_sensor(
            name=f"contact:{name}", type=mujoco.mjtSensor.mjSENS_CONTACT, objtype=mujoco.mjtObj.mjOBJ_BODY, objname=name
        )
        s.intprm = [_DATA_FOUND | _DATA_FORCE, _REDUCE_NETFORCE, 1]
        for o in dyn:
            s = spec.add_sensor(
                name=f"touch:{name}:{o}",
                type=mujoco.mjtSensor.mjSENS_CONTACT,
                objtype=mujoco.mjtObj.mjOBJ_BODY,
                objname=name,
                reftype=mujoco.mjtObj.mjOBJ_BODY,
                refname=f"obj_{o}",
            )
            s.intprm = [_DATA_FOUND, _REDUCE_NONE, 1]


def _index(
    spec: mujoco.MjSpec,
    model: mujoco.MjModel,
    cfg: SceneConfig,
    sid: str,
    hum: HumanoidRecord,
    skel: Skeleton,
    records: dict[str, ObjectRecord],
    dyn: list[str],
    gains: np.ndarray,
) -> Scene:
    name2id = lambda t, n: mujoco.mj_name2id(model, t, n)  # noqa: E731
    body_ids = np.array([name2id(mujoco.mjtObj.mjOBJ_BODY, n) for n in skel.body_names])
    jnames = [[f"{skel.body_names[b]}_{a}" for a in "xyz"] for b in skel.joint_bodies]
    jids = np.array([[name2id(mujoco.mjtObj.mjOBJ_JOINT, n) for n in row] for row in jnames])
    hinge_ids = np.array(
        [
            [j for j in np.flatnonzero(model.jnt_bodyid == bid) if model.jnt_type[j] == 3]
            for bid in body_ids[skel.joint_bodies]
        ]
    )
    if (jids < 0).any():
        jids = hinge_ids
    act = np.array(
        [
            [
                name2id(mujoco.mjtObj.mjOBJ_ACTUATOR, f"pd_{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}")
                for j in row
            ]
            for row in jids
        ]
    )
    objects = []
    for oid, rec in records.items():
        bid = name2id(mujoco.mjtObj.mjOBJ_BODY, f"obj_{oid}")
        o = SceneObject(oid, rec, oid in dyn, bid)
        if o.dynamic:
            j = model.body_jntadr[bid]
            o.qposadr, o.dofadr = int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j])
        objects.append(o)
    sensors = {}
    for i in range(model.nsensor):
        a = int(model.sensor_adr[i])
        sensors[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SENSOR, i)] = slice(a, a + int(model.sensor_dim[i]))
    return Scene(
        spec=spec,
        model=model,
        config=cfg,
        sequence_id=sid,
        humanoid=hum,
        skeleton=skel,
        body_ids=body_ids,
        hinge_qposadr=model.jnt_qposadr[jids],
        hinge_dofadr=model.jnt_dofadr[jids],
        actuator_ids=act,
        ctrl_range=model.actuator_ctrlrange[act.ravel()].copy(),
        objects=objects,
        sensors=sensors,
        gains=gains,
    )


def export_scene_xml(ds_path: str | Path, sequence_id: str, out: str | Path, config: SceneConfig | None = None) -> Path:
    """Write the scene of one sequence as MJCF (atomic)."""
    from wristmimic.format.reader import open_dataset
    from wristmimic.safe_io import atomic_output

    with open_dataset(ds_path) as ds:
        scene = build_scene(ds, sequence_id, config)
    with atomic_output(out) as tmp:
        tmp.write_text(scene.to_xml())
    return Path(out)
