"""The batched WristMimic environment: N worlds of one scene, Gymnasium-style vector API, torch tensors out.

>>> env = WristMimicEnv.from_file("datasets/omomo.h5", "sub2_largetable_000", num_worlds=64, seed=0)
>>> obs, info = env.reset()
>>> obs, reward, terminated, truncated, info = env.step(torch.zeros(64, env.action_size))

Worlds that end (terminated or truncated) are reset automatically at the end of ``step``; the returned
observation is then the first observation of the new episode (``info["time_outs"]`` tells PPO where to
bootstrap). No Python loop runs over worlds or bodies: physics goes through the backend in one call,
observation/reward math is batched torch on the backend's device (the CPU, or the GPU with the ``warp``
backend), and nothing on the step path waits for the host except on the CPU backend.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import torch

from wristmimic.env import window as W
from wristmimic.env.bodies import BodySets
from wristmimic.env.carry import carry_offsets
from wristmimic.env.clearance import contact_ramp
from wristmimic.env.config import EnvConfig, check_env_config
from wristmimic.env.depenetrate import DepenetrationStats, depenetrate_fingers
from wristmimic.env.gravity import gravity_offsets
from wristmimic.env.grounding import foot_floor_contact
from wristmimic.env.observations import (
    GoalRef,
    RefFrame,
    SimState,
    ig_feature,
    nearest_vectors,
    observation_parts,
    point_sq_dists,
)
from wristmimic.env.reference import Reference, load_reference
from wristmimic.env.rewards import CONSTANTS as REWARD_CONSTANTS
from wristmimic.env.rewards import DRIVE_MIN_SPEED, RewardInputs, compute_reward, ig_weights, sq_dists
from wristmimic.env.squeeze import squeeze_offsets
from wristmimic.env.starts import AdaptiveStarts, StateBank
from wristmimic.env.synergy import HANDS as SYNERGY_HANDS
from wristmimic.env.synergy import closure_coefficients
from wristmimic.env.terminations import REASONS, ContactLostCounter, TerminationInputs, check_terminations
from wristmimic.env.torch_math import quat_angle, quat_conj, quat_mul, quat_rotate, quat_to_matrix, quat_to_rotvec
from wristmimic.errors import InputError
from wristmimic.format.reader import open_dataset
from wristmimic.scene import Scene, SceneConfig, build_scene
from wristmimic.sim.backend import PhysicsBackend, make_backend
from wristmimic.threads import torch_threads

_FLOAT32_TINY = torch.finfo(torch.float32).tiny
"""The smallest normal float32: observation entries below it are set to 0."""
_IG_TABLE_MAX = 1 << 24
"""Most elements of the per-frame reference IG weight table (T, K, P) kept in memory (64 MiB float32)."""


@dataclass
class _SensorIndex:
    """Column indices into sensordata for each batched quantity."""

    body_pos: np.ndarray
    body_quat: np.ndarray
    body_linvel: np.ndarray
    body_angvel: np.ndarray
    obj_pos: np.ndarray
    obj_quat: np.ndarray
    obj_linvel: np.ndarray
    obj_angvel: np.ndarray
    contact: np.ndarray  # (B, 4) found, fx, fy, fz
    touch: np.ndarray  # (B, O)


def _strided(cols: np.ndarray) -> tuple[int, int, int] | None:
    """(start, row stride, column stride) when the (R, C) column indices are start + r rs + c cs, else None."""
    if cols.size == 0:
        return None
    r, c = cols.shape
    start = int(cols[0, 0])
    rs = int(cols[1, 0]) - start if r > 1 else 0
    cs = int(cols[0, 1]) - start if c > 1 else 1
    regular = np.array_equal(cols, start + rs * np.arange(r)[:, None] + cs * np.arange(c)[None])
    return (start, rs, cs) if regular and rs >= 0 and cs > 0 else None


def _sensor_index(scene: Scene) -> _SensorIndex:
    names = scene.skeleton.body_names
    dyn = [f"obj_{o.id}" for o in scene.dynamic_objects]

    def cols(kind: str, objs: list[str]) -> np.ndarray:
        rows = [np.arange(scene.sensors[f"{kind}:{n}"].start, scene.sensors[f"{kind}:{n}"].stop) for n in objs]
        return np.stack(rows) if rows else np.zeros((0, {"quat": 4}.get(kind, 3)), int)

    touch = np.array(
        [[scene.sensors[f"touch:{n}:{o.id}"].start for o in scene.dynamic_objects] for n in names], dtype=int
    ).reshape(len(names), len(dyn))
    return _SensorIndex(
        cols("pos", names),
        cols("quat", names),
        cols("linvel", names),
        cols("angvel", names),
        cols("pos", dyn),
        cols("quat", dyn),
        cols("linvel", dyn),
        cols("angvel", dyn),
        cols("contact", names),
        touch,
    )


class WristMimicEnv:
    """Vectorised WristMimic environment over ``num_worlds`` copies of one sequence's scene."""

    def __init__(
        self,
        scene: Scene,
        reference: Reference,
        num_worlds: int,
        config: EnvConfig | None = None,
        seed: int = 0,
        backend: PhysicsBackend | str = "cpu",
        nthread: int | None = None,
        backend_options: dict | None = None,
    ):
        self.scene, self.cfg = scene, config or EnvConfig()
        check_env_config(self.cfg)
        if self.cfg.ground_reference and reference.grounded_by is None:
            raise ValueError("ground_reference needs a reference loaded with load_reference(ground=True)")
        if self.cfg.foot_clearance != reference.foot_clearance:
            raise ValueError(
                f"foot_clearance {self.cfg.foot_clearance} needs a reference loaded with that foot_clearance"
                f" (this one: {reference.foot_clearance})"
            )
        if self.cfg.clear_hands != reference.clear_hands:
            raise ValueError(
                f"clear_hands {self.cfg.clear_hands} needs a reference loaded with that clear_hands"
                f" (this one: {reference.clear_hands})"
            )
        if tuple(self.cfg.wrist_offsets) != tuple(reference.wrist_offsets):
            raise ValueError(
                f"wrist_offsets {list(self.cfg.wrist_offsets)} need a reference loaded with those offsets"
                f" (this one: {list(reference.wrist_offsets)})"
            )
        self.num_worlds = int(num_worlds)
        self.seed = int(seed)
        if isinstance(backend, str):
            backend = make_backend(backend, scene.model, self.num_worlds, nthread, **(backend_options or {}))
        self.backend = backend
        dev = self.device = backend.device
        self.ref = reference.to(dev)
        self.sets = BodySets.from_roles(scene.humanoid.roles).to(dev)
        self._idx = _sensor_index(scene)
        self._tidx = {k: torch.as_tensor(v, dtype=torch.long, device=dev) for k, v in self._idx.__dict__.items()}
        self._hinge_dof = torch.as_tensor(scene.hinge_dofadr.reshape(-1), dtype=torch.long, device=dev)
        self._gen = torch.Generator(device=dev).manual_seed(self.seed)
        N = self.num_worlds
        self.frame = torch.zeros(N, dtype=torch.long, device=dev)
        self.start = torch.zeros(N, dtype=torch.long, device=dev)
        self.steps = torch.zeros(N, dtype=torch.long, device=dev)
        self.lost = ContactLostCounter(N, dev)
        self.starts = AdaptiveStarts(self.cfg.starts, reference.num_frames, dev) if self.cfg.starts.adaptive else None
        self.bank: StateBank | None = None
        """States the policy reached, restored by some mid-clip starts (``StartSamplingConfig.bank`` > 0)."""
        if self.cfg.starts.bank > 0:
            m0 = scene.model
            self.bank = StateBank(reference.num_frames, self.cfg.starts.bank_size, m0.nq, m0.nv, dev)
        self._lineage = torch.zeros(N, dtype=torch.bool, device=dev)
        self.start_counts = torch.zeros(2, dtype=torch.long, device=dev)
        """Sampled starts after frame 0 and those restored from the bank, since construction (when the bank is on)."""
        """(N,) the world's state descends by simulation from a frame-0 start (what the bank records)."""
        roles = scene.humanoid.roles

        def idx(a: object) -> torch.Tensor:
            return torch.as_tensor(np.asarray(a), dtype=torch.long, device=dev)

        fingers, key, non_finger = idx(roles["fingers"]), idx(roles["key_bodies"]), idx(roles["non_finger"])
        self.tracked = torch.cat([key, fingers]) if self.cfg.finger_targets else key
        self.rotated = torch.cat([non_finger, fingers]) if self.cfg.finger_targets else non_finger
        if self.cfg.finger_targets and scene.humanoid.hand:
            raise InputError(
                None,
                f"variant {self.cfg.variant}",
                f"needs finger pose targets, but humanoid {scene.humanoid.name} has a swapped hand "
                f"({scene.humanoid.hand}) whose finger reference is only its rest pose",
                "a variant without finger targets (wristmimic, decoupled, reward-modulation-only, reset-only)",
            )
        self.goal_contact = key
        self.all_bodies = torch.arange(scene.skeleton.num_bodies, device=dev)
        self.hands = (idx(roles["left_hand"]), idx(roles["right_hand"]))
        # action -> PD target (InterMimic): mid-range offset and half-range scale; wide joints centred at 0
        lo, hi = scene.ctrl_range[:, 0], scene.ctrl_range[:, 1]
        offset, scale = (lo + hi) / 2, (hi - lo) / 2
        finger_joint = np.isin(scene.skeleton.joint_bodies, np.asarray(roles["fingers"]))
        wide = np.abs(offset) > 0.1
        if self.cfg.finger_action == "range":  # finger actions span exactly each finger hinge's range
            wide &= ~np.repeat(finger_joint, 3)
        offset[wide], scale[wide] = 0.0, np.pi

        def f32(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(a, dtype=torch.float32, device=dev)

        self._offset, self._scale = f32(offset), f32(scale * self.cfg.action_scale)
        self._lo, self._hi = f32(lo), f32(hi)
        # residual mode: body and wrist hinges around the reference of the next frame, fingers absolute
        self.residual_hinges = torch.as_tensor(
            np.repeat(~finger_joint, 3) & (self.cfg.action_mode == "residual"), device=dev
        )
        """(J*3,) bool: hinges whose PD target is reference + residual_scale * a (none in absolute mode)."""
        self.finger_actions = torch.as_tensor(np.repeat(finger_joint, 3), device=dev)
        """(J*3,) bool: action dimensions of finger hinges."""
        self.delta_hinges = torch.as_tensor(
            np.repeat(finger_joint, 3) & (self.cfg.finger_action == "delta"), device=dev
        )
        """(J*3,) bool: finger hinges with a held target moved by finger_delta_scale * a (``finger_action``)."""
        self._delta_cols = self.delta_hinges.nonzero().flatten()
        self._held = torch.zeros(N, len(self.delta_hinges), device=dev)
        """(N, J*3) held PD targets of the ``delta`` finger hinges (other columns unused)."""
        self._ff_time = f32(scene.gains[:, 1] / scene.gains[:, 0] * float(self.cfg.velocity_feedforward))
        self._ctrl = torch.zeros(N, scene.model.nu, device=dev)
        self._act_cols = idx(scene.actuator_ids.reshape(-1))
        self._prev_joint_vel = torch.zeros(N, len(self._act_cols), device=dev)
        self._prev_obj_vel = torch.zeros(N, len(scene.dynamic_objects), 6, device=dev)
        # reference state -> qpos / qvel columns (free joints of the root and the dynamic objects, hinges)
        self._qpos0 = torch.as_tensor(scene.model.qpos0, dtype=torch.float64, device=dev)
        self._hinge_qpos = idx(scene.hinge_qposadr.reshape(-1))
        self._obj_qpos = idx([o.qposadr for o in scene.dynamic_objects])
        self._obj_dof = idx([o.dofadr for o in scene.dynamic_objects])
        k3, k4 = torch.arange(3, device=dev), torch.arange(4, device=dev)
        self._obj_pos_q, self._obj_quat_q = self._obj_qpos[:, None] + k3, self._obj_qpos[:, None] + 3 + k4
        """(O, 3) / (O, 4) qpos columns of each dynamic object's position / quaternion."""
        self._obj_lin_v, self._obj_ang_v = self._obj_dof[:, None] + k3, self._obj_dof[:, None] + 3 + k3
        """(O, 3) qvel columns of each dynamic object's linear (world) / angular (local) velocity."""
        self.num_hinges = len(self._act_cols)
        """Actuated hinges (3 per joint), the first ``num_hinges`` action dimensions (in ``scene.actuator_ids``
        order)."""
        self._synergy: torch.Tensor | None = None
        """(2, num_hinges) PD-target change per unit of the left / right grasp-synergy action (``finger_synergy``)."""
        if self.cfg.finger_synergy > 0.0:
            self._synergy = f32(closure_coefficients(scene) * self.cfg.finger_synergy)
        self.action_size = self.num_hinges + (0 if self._synergy is None else len(SYNERGY_HANDS))
        """Policy actions: one per hinge, then one grasp-synergy action per hand when ``finger_synergy`` > 0."""
        # virtual object controller (training only): motors on the objects' free joints, if the scene has them
        m = scene.model
        voc = [
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"voc_{o.id}_{k}") for k in range(6)]
            for o in scene.dynamic_objects
        ]
        self.has_object_controller = bool(voc) and min(min(r) for r in voc) >= 0
        self._voc_cols = idx(voc if self.has_object_controller else np.zeros((0, 6), int))
        bids = [o.body_id for o in scene.dynamic_objects]
        self._obj_mass = f32(m.body_mass[bids])[:, None] if bids else torch.zeros(0, 1, device=dev)
        self._obj_weight = self._obj_mass[:, 0] * float(np.linalg.norm(m.opt.gravity))
        self._obj_inertia = f32(m.body_inertia[bids].mean(-1))[:, None] if bids else torch.zeros(0, 1, device=dev)
        self._gravity = f32(-m.opt.gravity)
        h = self.cfg.object_controller.horizontal  # the controller's horizontal share (world x, y; z stays)
        self._horizontal_share = torch.tensor([h, h, 1.0], dtype=torch.float32, device=dev)
        # root assist (training only): motors on the humanoid root's free joint, if the scene has them
        rac = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"rac_{k}") for k in range(6)]
        self.has_root_assist = min(rac) >= 0
        self._rac_cols = idx(rac if self.has_root_assist else [])
        root_body = int(m.jnt_bodyid[m.actuator_trnid[rac[0], 0]]) if self.has_root_assist else 0
        self._root_mass = float(m.body_subtreemass[root_body])  # the whole humanoid
        # contact guidance (training only): adhesion actuators on the hand bodies, if the scene has them
        adh = [
            i for i in range(m.nu) if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or "").startswith("adh_")
        ]
        self.has_hand_adhesion = bool(adh)
        self._adh_cols = idx(adh)
        sides = [np.atleast_1d(scene.humanoid.roles.get(f"{h}_hand", [])) for h in ("left", "right")]
        hand_of = {int(scene.body_ids[b]): k for k, bs in enumerate(sides) for b in bs}
        self._adh_side = torch.tensor([hand_of[int(m.actuator_trnid[i, 0])] for i in adh], dtype=torch.long, device=dev)
        """(n_adh,) 0 / 1: the hand (left / right) of each adhesion actuator's body."""
        self.feedforward = torch.zeros(reference.num_frames, self.num_hinges, device=dev)
        """(T, D) open-loop offsets added to the residual hinges' targets (:mod:`wristmimic.env.feedforward`);
        zero unless a run's optimised offsets are loaded."""
        self.gravity_feedforward = torch.zeros(reference.num_frames, self.num_hinges, device=dev)
        """(T, D) gravity-holding offsets of the residual hinges' targets (``EnvConfig.gravity_feedforward``)."""
        if self.cfg.gravity_feedforward and self.cfg.action_mode == "residual":
            r = reference
            g = gravity_offsets(
                scene, *(x.detach().cpu().double().numpy() for x in (r.root_pos, r.root_quat, r.joint_angles))
            )
            self.gravity_feedforward = f32(g)
        self.squeeze_feedforward = torch.zeros(reference.num_frames, self.num_hinges, device=dev)
        """(T, D) offsets of the arms' residual hinges that press both hands into an object held between them
        (``EnvConfig.grip_squeeze``, :mod:`wristmimic.env.squeeze`)."""
        self.carry_feedforward = torch.zeros(reference.num_frames, self.num_hinges, device=dev)
        """(T, D) offsets of the arm and torso residual hinges that hold up a carried object's weight
        (``EnvConfig.carry_feedforward``, :mod:`wristmimic.env.carry`)."""
        self.eval_info = True
        """Put the evaluation errors (``info["eval"]``) in every step's info; training turns it off (unused there)."""
        self.object_gain = 0.0
        """Gain of the virtual object controller (0: off). Set by the training curriculum; needs a scene built
        with ``SceneConfig(object_actuators=True)``."""
        self.object_weight_gain: float | None = None
        """Gain of the controller's weight support (``ObjectControllerConfig.weight_zero_by_frames``); None: the
        same as :attr:`object_gain`."""
        self.object_scale = torch.ones(N, device=dev)
        """(N,) each world's share of the controller's gain for its current episode
        (``ObjectControllerConfig.spread``; ones when off)."""
        self.object_start_hold = 0
        """Frames after a reset at a start frame > 0 during which the object controller holds that world's objects
        (``ObjectControllerConfig.start_hold_frames``; 0: off). Set by training only."""
        self.root_gain = 0.0
        """Gain of the root assist (0: off; ``EnvConfig.root_assist``). Set by training; needs a scene built with
        ``SceneConfig(root_actuators=True)``."""
        self.adhesion_gain = 0.0
        """Gain of the hands' adhesion (0: off; ``EnvConfig.hand_adhesion``). Set by training; needs a scene built
        with ``SceneConfig(hand_adhesion=True)``."""
        self.on_step: Callable[[SimState, torch.Tensor], None] | None = None
        """Called in :meth:`step` with the state just reached (before any auto-reset) and the actions (a recorder:
        ``wristmimic.evaluate.export``); ``steps`` is then the frame reached, ``_ctrl`` the PD targets applied."""
        self._obs_layout: dict[str, slice] = {}
        self.observation_size = 0
        self._setup_step_constants()

    def _setup_step_constants(self) -> None:
        """Tables and index tensors the step reads every call, made once: sensordata views, the objects'
        surface points by object, per-frame reference tables (goal observation, reference state, IG weights)."""
        dev, r, N, T = self.device, self.ref, self.num_worlds, self.ref.num_frames
        self._sd_views = {k: _strided(v) for k, v in self._idx.__dict__.items()}
        self._sd_shapes = {k: v.shape for k, v in self._idx.__dict__.items()}
        hinge = self._hinge_dof.cpu().numpy()
        self._hinge_slice = (
            slice(int(hinge[0]), int(hinge[-1]) + 1) if len(hinge) and bool((np.diff(hinge) == 1).all()) else None
        )
        # surface points as (O, Pmax, 3) blocks in their objects' frames; keep: the rows of the P points
        owner, O = r.points_object.cpu(), len(self.scene.dynamic_objects)
        counts = torch.bincount(owner, minlength=O) if len(owner) else torch.zeros(O, dtype=torch.long)
        pmax = int(counts.max()) if O else 0
        order = torch.argsort(owner, stable=True)
        rank = torch.empty_like(owner)
        rank[order] = torch.arange(len(owner)) - (torch.cumsum(counts, 0) - counts)[owner[order]]
        rows = owner * pmax + rank
        local = torch.zeros(O * pmax, 3)
        local[rows] = r.points_local.cpu()
        self._pts_local = local.view(O, pmax, 3).to(dev)
        self._pts_rows = None if torch.equal(rows, torch.arange(O * pmax)) else rows.to(dev)
        # hands as one (2, L) index (the shorter list padded with its own first body: 'any' is unchanged)
        L = max(len(h) for h in self.hands)
        self._hand_idx = torch.stack([torch.cat([h, h[:1].expand(L - len(h))]) for h in self.hands])
        # window phase of every frame in [lo, hi]: all frames below lo and above hi are outside the window
        wc = self.cfg.window
        self._phase_lo = min(0, r.t_c - wc.t_b - 1)
        frames = torch.arange(self._phase_lo, max(T, r.t_c + wc.t_a + 1) + 1, device=dev)
        self._phase_table = W.phase(frames, torch.full_like(frames, r.t_c), wc)
        self._grasp = r.grasp_hands[None].expand(N, 2)
        # goal observation: the reference at a frame, tracked / rotated / contact bodies, one row per frame
        gc = self.goal_contact
        goal = [
            r.body_pos[:, self.tracked].flatten(1),
            r.body_quat[:, self.rotated].flatten(1),
            r.obj_pos.flatten(1),
            r.obj_quat.flatten(1),
            ig_feature(r.near_vec[:, self.tracked]).flatten(1),
            r.labels[:, gc].to(torch.float32),
            r.hand.to(torch.float32),
        ]
        self._goal_table = torch.cat(goal, 1)
        self._goal_widths = [g.shape[1] for g in goal]
        self._horizons = torch.as_tensor(self.cfg.goal_horizons, dtype=torch.long, device=dev)
        # reference state (qpos, qvel) of every frame
        self._ref_qpos, self._ref_qvel = self._reference_state_table()
        if self.cfg.action_mode == "residual" and (self.cfg.grip_squeeze > 0.0 or self.cfg.carry_feedforward):
            qpos, hand = self._ref_qpos.detach().cpu().numpy(), r.hand.detach().cpu().numpy()
            if self.cfg.grip_squeeze > 0.0:
                sq = squeeze_offsets(self.scene, self.cfg.grip_squeeze, qpos, hand)
                self.squeeze_feedforward = torch.as_tensor(sq, dtype=torch.float32, device=self.device)
            if self.cfg.carry_feedforward:
                carry = carry_offsets(self.scene, qpos, r.labels.detach().cpu().numpy(), hand)
                self.carry_feedforward = torch.as_tensor(carry, dtype=torch.float32, device=self.device)
        self._held_offsets = self.gravity_feedforward + self.squeeze_feedforward + self.carry_feedforward
        self._grip_center = self._finger_grip_table() if self.cfg.finger_grip else None
        """(T, num_hinges) centre of the absolute targets per frame: the mid-range offset, moved to ``finger_grip``
        on a touching hand's fingers (None: off)."""
        # bodies -> points distances are computed with the key bodies first: the IG reward reads (N, K, P) as a view
        key, P, B = self.sets.key, r.points.shape[1], self.scene.skeleton.num_bodies
        rest = torch.ones(B, dtype=torch.bool, device=dev)
        rest[key] = False
        self._sq_rows = torch.cat([key, torch.arange(B, device=dev)[rest]])
        self._sq_unperm = torch.argsort(self._sq_rows)
        # reference interaction-graph weights of every frame, (T, K, P), if that table is not too large
        self._ref_ig_w: torch.Tensor | None = None
        if P and T * len(key) * P <= _IG_TABLE_MAX:
            rows_t = [
                ig_weights(
                    sq_dists(r.body_pos[a : a + 256, key], r.points[a : a + 256]), REWARD_CONSTANTS.ig_min_sq_dist
                )
                for a in range(0, T, 256)
            ]
            self._ref_ig_w = torch.cat(rows_t)
        if self.cfg.weights.drive > 0 and len(self.scene.dynamic_objects) != 1:
            raise ValueError(
                f"weights.drive > 0 needs exactly one dynamic object; scene {self.scene.sequence_id} has"
                f" {len(self.scene.dynamic_objects)}"
            )
        # the reference's foot-floor contact schedule, for the feet_contact factor
        self._ref_feet_contact: torch.Tensor | None = None
        if self.cfg.weights.feet_contact > 0:
            if not self.sets.feet.numel():
                raise ValueError("weights.feet_contact > 0 needs a humanoid whose roles name its feet")
            table = foot_floor_contact(
                self.scene,
                r.root_pos.double().numpy(),
                r.root_quat.double().numpy(),
                r.joint_angles.double().numpy(),
                self.sets.feet.cpu().numpy(),
            )
            self._ref_feet_contact = torch.from_numpy(table).to(dev)
        # reference body velocities for the velocity factors: central differences (p[f+1] - p[f-1]) fps / 2, the
        # velocity at the frame itself (the stored forward difference is the one a reset starts from)
        self._ref_vel: torch.Tensor | None = None
        if self.cfg.weights.root_vel > 0 or self.cfg.weights.body_vel > 0:
            v = r.body_linvel
            self._ref_vel = torch.cat([v[:1], 0.5 * (v[:-1] + v[1:])]) if T > 1 else v.clone()

    # -- construction --------------------------------------------------------------------------------------
    @classmethod
    def from_file(
        cls,
        dataset: str | Path,
        sequence_id: str,
        num_worlds: int,
        config: EnvConfig | None = None,
        scene_config: SceneConfig | None = None,
        seed: int = 0,
        nthread: int | None = None,
        max_frames: int | None = None,
        backend: str = "cpu",
        backend_options: dict | None = None,
    ) -> WristMimicEnv:
        """Build the scene and reference of ``sequence_id`` from a canonical file (``max_frames``: keep only the
        first frames of the reference) on physics ``backend`` (``cpu`` or ``warp``)."""
        cfg = config or EnvConfig()
        with open_dataset(dataset) as ds:
            scene = build_scene(ds, sequence_id, scene_config)
            ref = load_reference(
                ds,
                scene,
                cfg.ig_points,
                0,
                max_frames,
                ground=cfg.ground_reference,
                foot_clearance=cfg.foot_clearance,
                clear_hands=cfg.clear_hands,
                wrist_offsets=tuple(cfg.wrist_offsets),
            )  # point subset: seed 0
        return cls(scene, ref, num_worlds, cfg, seed, backend, nthread, backend_options)

    @property
    def obs_layout(self) -> dict[str, slice]:
        """Name -> slice of the observation vector (``state``, ``goal<k>/<piece>``)."""
        return self._obs_layout

    # -- reset ---------------------------------------------------------------------------------------------
    def reset(self, seed: int | None = None, start_frames: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
        """Reset every world (reference state initialisation, or ``start_frames``)."""
        if seed is not None:
            self._gen.manual_seed(int(seed))
        every = torch.ones(self.num_worlds, dtype=torch.bool, device=self.device)
        self._reset_worlds(every, None if start_frames is None else start_frames.to(self.device))
        return self._observe(), {}

    def sample_start_frames(self, n: int) -> torch.Tensor:
        """Frame 0 with probability ``reset_frame0_prob``, else failure-weighted (``starts.adaptive``) or uniform
        over [0, T - 2]."""
        T = self.ref.num_frames
        if self.starts is not None:
            uniform = self.starts.sample(n, self._gen)
        else:
            uniform = torch.randint(0, max(T - 1, 1), (n,), generator=self._gen, device=self.device)
        zero = torch.rand(n, generator=self._gen, device=self.device) < self.cfg.reset_frame0_prob
        return torch.where(zero, torch.zeros_like(uniform), uniform)

    def _reference_state_table(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(T, nq), (T, nv) float64: the reference state of every frame (humanoid and dynamic objects)."""
        r, T, nv = self.ref, self.ref.num_frames, self.scene.model.nv
        qpos = self._qpos0.expand(T, -1).clone()
        qvel = torch.zeros(T, nv, dtype=torch.float64, device=self.device)
        qpos[:, 0:3], qpos[:, 3:7] = r.root_pos.double(), r.root_quat.double()
        qpos[:, self._hinge_qpos] = r.joint_angles.double()
        qvel[:, 0:3], qvel[:, 3:6] = r.root_linvel.double(), r.root_angvel_local.double()
        qvel[:, self._hinge_dof] = r.joint_vel.double()
        if len(self._obj_qpos):
            qpos[:, self._obj_pos_q.flatten()] = r.obj_pos.double().flatten(1)
            qpos[:, self._obj_quat_q.flatten()] = r.obj_quat.double().flatten(1)
            qvel[:, self._obj_lin_v.flatten()] = r.obj_linvel.double().flatten(1)
            qvel[:, self._obj_ang_v.flatten()] = r.obj_angvel_local.double().flatten(1)
        self.depenetration: DepenetrationStats | None = None
        if self.cfg.starts.depenetrate:
            table, self.depenetration = depenetrate_fingers(
                self.scene, qpos.cpu().numpy(), self.cfg.starts.depenetrate_tol
            )
            qpos = torch.from_numpy(table).to(qpos.device)
        return qpos, qvel

    def reference_state(self, frames: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(qpos, qvel) float64 of the reference at ``frames`` (N,): humanoid and dynamic objects."""
        f = frames.to(torch.long)
        return self._ref_qpos[f], self._ref_qvel[f]

    def _reset_worlds(self, mask: torch.Tensor, frames: torch.Tensor | None = None) -> None:
        """Reference state initialisation of the worlds where ``mask`` (N,) is true, at ``frames`` (N,) or
        sampled start frames. Works on the whole batch with masks: no host synchronisation."""
        f = self.sample_start_frames(self.num_worlds) if frames is None else frames.to(torch.long)
        use = None
        if self.bank is not None and frames is None:  # sampled (training) starts only
            have, bq, bv = self.bank.draw(f, self._gen)
            u = torch.rand(self.num_worlds, generator=self._gen, device=self.device)
            use = have & (f > 0) & (u < self.cfg.starts.bank)
            self.start_counts += torch.stack([(mask & (f > 0)).sum(), (mask & use).sum()])
        until = self.cfg.starts.reference_until
        if until >= 0 and frames is None:  # late reference starts fold back into the trusted frames
            late = f > until if use is None else (f > until) & ~use
            f = torch.where(late, f % (until + 1), f)
        qpos, qvel = self.reference_state(f)
        lineage = f == 0 if until < 0 else f <= until
        if use is not None:
            qpos, qvel = torch.where(use[:, None], bq, qpos), torch.where(use[:, None], bv, qvel)
            lineage |= use
        self._lineage = torch.where(mask, lineage, self._lineage)
        spread = self.cfg.object_controller.spread
        if spread > 0.0 and self.cfg.object_controller.enabled:  # draws only then: other runs keep their streams
            u = 1.0 - spread * torch.rand(self.num_worlds, generator=self._gen, device=self.device)
            self.object_scale = torch.where(mask, u, self.object_scale)
        self.backend.reset(mask, qpos, qvel)
        if self._delta_cols.numel():  # a reset holds the start state's finger angles
            start = qpos[:, self._hinge_qpos].to(torch.float32)
            self._held = torch.where(mask[:, None], start.clamp(self._lo, self._hi), self._held)
        r, col = self.ref, mask[:, None]
        self.frame = torch.where(mask, f, self.frame)
        self.start = torch.where(mask, f, self.start)
        self.steps = self.steps.masked_fill(mask, 0)
        self.lost.counts = self.lost.counts.masked_fill(col, 0)
        self._prev_joint_vel = torch.where(col, r.joint_vel[f], self._prev_joint_vel)
        obj_vel = torch.cat([r.obj_linvel[f], r.obj_angvel[f]], -1)
        self._prev_obj_vel = torch.where(col[..., None], obj_vel, self._prev_obj_vel)

    # -- state ---------------------------------------------------------------------------------------------
    def _sensors(self, sd: torch.Tensor, name: str) -> torch.Tensor:
        """(N, R, C) columns ``name`` of float32 sensordata ``sd``: a strided view where they are regular."""
        spec, (rows, cols) = self._sd_views[name], self._sd_shapes[name]
        if spec is None:
            return sd[:, self._tidx[name]]
        start, rs, cs = spec
        return sd.as_strided((sd.shape[0], rows, cols), (sd.stride(0), rs, cs), sd.storage_offset() + start)

    def sim_state(self) -> SimState:
        """The simulated state of every world, from the backend's sensors (a fresh copy: later steps do not
        change it)."""
        sd = self.backend.sensordata  # one float32 copy, then views into it
        sd = sd.to(torch.float32, memory_format=torch.contiguous_format, copy=True)
        contact = self._sensors(sd, "contact")
        force = contact[..., 1:]
        obj_pos, obj_quat = self._sensors(sd, "obj_pos"), self._sensors(sd, "obj_quat")
        # surface points: each object's rotation matrix applied to its block of local points
        pts = torch.matmul(self._pts_local, quat_to_matrix(obj_quat).transpose(-1, -2)) + obj_pos[:, :, None]
        pts = pts.flatten(1, 2)
        points = pts if self._pts_rows is None else pts.index_select(1, self._pts_rows)
        qvel = self.backend.qvel
        qvel = qvel[:, self._hinge_slice] if self._hinge_slice is not None else qvel[:, self._hinge_dof]
        return SimState(
            body_pos=self._sensors(sd, "body_pos"),
            body_quat=self._sensors(sd, "body_quat"),
            body_linvel=self._sensors(sd, "body_linvel"),
            body_angvel=self._sensors(sd, "body_angvel"),
            obj_pos=obj_pos,
            obj_quat=obj_quat,
            obj_linvel=self._sensors(sd, "obj_linvel"),
            obj_angvel=self._sensors(sd, "obj_angvel"),
            contact=(contact[..., 0] > 0)
            & (torch.linalg.vector_norm(force, dim=-1) > self.cfg.contact_force_threshold),
            contact_force=force,
            contact_obj=(self._sensors(sd, "touch") > 0).any(-1),
            joint_vel=qvel.to(torch.float32, copy=True),
            points=points,
        )

    def ref_frame(self, frames: torch.Tensor) -> RefFrame:
        """The reference at ``frames`` (N,), clamped to the sequence."""
        r = self.ref
        f = frames.clamp(0, r.num_frames - 1)
        return RefFrame(
            r.body_pos.index_select(0, f),
            r.body_quat.index_select(0, f),
            r.obj_pos.index_select(0, f),
            r.obj_quat.index_select(0, f),
            r.points.index_select(0, f),
            r.labels.index_select(0, f),
            r.hand.index_select(0, f),
            r.near_vec.index_select(0, f),
        )

    # -- observations --------------------------------------------------------------------------------------
    def _goal_ref(self) -> GoalRef:
        """The reference at every goal horizon's frame, one gather from the per-frame goal table."""
        H, N, T = len(self._horizons), self.num_worlds, self.ref.num_frames
        f = (self.frame[None] + self._horizons[:, None]).clamp(0, T - 1).flatten()
        g = self._goal_table.index_select(0, f).view(H, N, -1).split(self._goal_widths, -1)
        return GoalRef(
            body_pos=g[0].unflatten(-1, (-1, 3)),
            body_quat=g[1].unflatten(-1, (-1, 4)),
            obj_pos=g[2].unflatten(-1, (-1, 3)),
            obj_quat=g[3].unflatten(-1, (-1, 4)),
            ig=g[4].unflatten(-1, (-1, 3)),
            labels=g[5],
            hand=g[6],
        )

    def _point_sq_dists(self, s: SimState, worlds: torch.Tensor | None = None) -> torch.Tensor | None:
        """(N, B, P) squared distances bodies -> object surface points, rows in the order key bodies first
        (``_sq_rows``), of every world or of ``worlds`` (n,) only; None without points."""
        if not s.points.shape[1]:
            return None
        pos, pts = s.body_pos, s.points
        if worlds is not None:
            pos, pts = pos.index_select(0, worlds), pts.index_select(0, worlds)
        return point_sq_dists(pos.index_select(1, self._sq_rows), pts)

    def _observe(self, s: SimState | None = None, sq: torch.Tensor | None = None) -> torch.Tensor:
        """Observation of every world; ``sq``: :meth:`_point_sq_dists` of ``s`` if already computed."""
        s = s or self.sim_state()
        sq = self._point_sq_dists(s) if sq is None else sq
        pos = s.body_pos.index_select(1, self._sq_rows)  # the rows of sq
        near = nearest_vectors(pos, s.points, sq).index_select(1, self._sq_unperm)
        parts = observation_parts(
            s,
            near,
            self._sim_hand(s),
            self._goal_ref(),
            self.cfg.goal_horizons,
            self.tracked,
            self.rotated,
            self.goal_contact,
            None,  # the state's contact markers: every body
        )
        if self._delta_cols.numel():
            q = self.backend.qpos.index_select(1, self._hinge_qpos.index_select(0, self._delta_cols))
            parts["finger_hold"] = [self._held.index_select(1, self._delta_cols) - q.to(torch.float32)]
        if not self._obs_layout:
            a = 0
            for name, v in parts.items():
                w = sum(p.shape[1] for p in v)
                self._obs_layout[name] = slice(a, a + w)
                a += w
            self.observation_size = a
        obs = torch.cat([p for v in parts.values() for p in v], dim=1)
        # denormal floats (|x| < 1.2e-38) make every matmul that reads them ~25x slower on x86: the interaction graph
        # exp(-5 d) of an object more than ~17 m away is one (measured: the CPU recipe's first actor layer on sub2
        # with its table parked 20 m away, 13.0 ms per batch of 32 against 0.49 ms flushed; training 216 against 680
        # frames/s), as are rounding residues of the goal rotations; they are exactly 0 here
        return obs.masked_fill_(obs.abs() < _FLOAT32_TINY, 0.0)

    # -- step ----------------------------------------------------------------------------------------------
    def action_to_ctrl(self, action: torch.Tensor, frames: torch.Tensor | None = None) -> torch.Tensor:
        """Actions in [-1, 1] -> PD targets (rad) of the ``num_hinges`` hinges, clipped to the joint ranges.
        Residual hinges add ``residual_scale * a`` to the reference angle at ``frames`` (default: the frame being
        stepped to); the grasp-synergy actions (``finger_synergy``) add their closure to the finger targets."""
        a = action.clamp(-1.0, 1.0)
        grasp = a[:, self.num_hinges :]
        a = a[:, : self.num_hinges]
        f = (self.frame + 1 if frames is None else frames).clamp(0, self.ref.num_frames - 1)
        centre = self._offset if self._grip_center is None else self._grip_center[f]
        target = centre + self._scale * a
        if self.cfg.action_mode == "residual":
            ref = self.ref.joint_angles[f] + self._ff_time * self.ref.joint_vel[f] + self.feedforward[f]
            ref = ref + self._held_offsets[f]
            residual = ref + self.cfg.residual_scale * a
            target = torch.where(self.residual_hinges, residual, target)
        if self._delta_cols.numel():
            target = torch.where(self.delta_hinges, self._held + self.cfg.finger_delta_scale * a, target)
        if self._synergy is not None:
            target = target + grasp @ self._synergy
        return torch.maximum(torch.minimum(target, self._hi), self._lo)

    def _finger_grip_table(self) -> torch.Tensor:
        """(T, num_hinges): the absolute targets' centre per frame, ``finger_grip`` on each hand's finger hinges
        weighted by that hand's reference contact, ramped over the first and last 10 frames of each contact (inside
        it: the hand reaches the object with the mid-range fingers and closes them once there)."""
        fingers = self.finger_actions.cpu().numpy()
        grip = np.asarray(self.cfg.finger_grip, dtype=np.float64)
        if len(grip) != int(fingers.sum()):
            raise ValueError(
                f"finger_grip has {len(grip)} angles; humanoid {self.scene.humanoid.name} has {int(fingers.sum())}"
                " finger hinges"
            )
        skel, roles = self.scene.skeleton, self.scene.humanoid.roles
        hinge_bodies = np.repeat(skel.joint_bodies, 3)
        weight = 1.0 - contact_ramp(~self.ref.hand.detach().cpu().numpy().astype(bool), 10)  # (T, 2): left, right
        if self.cfg.finger_grip_from > 0:  # off before finger_grip_from, then a 10-frame ramp
            since = np.arange(self.ref.num_frames) - self.cfg.finger_grip_from + 1
            weight *= np.clip(since / 10, 0.0, 1.0)[:, None]
        offset = self._offset.detach().cpu().numpy().astype(np.float64)
        target = np.zeros(self.num_hinges)
        target[fingers] = grip
        centre = np.repeat(offset[None], self.ref.num_frames, axis=0)
        for h, side in enumerate(("left", "right")):  # two hands
            cols = fingers & np.isin(hinge_bodies, np.asarray(roles[f"{side}_hand"]))
            centre[:, cols] += weight[:, h : h + 1] * (target[cols] - offset[cols])
        return torch.as_tensor(centre, dtype=torch.float32, device=self.device)

    def step(self, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict]:
        """Advance every world one 30 Hz control step."""
        with torch_threads(self.cfg.math_threads):
            return self._step(action)

    def _step(self, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict]:
        self.prepare_step(action)
        self.backend.step(self._ctrl, self.scene.config.substeps)
        return self.finish_step(action)

    def prepare_step(self, action: torch.Tensor) -> torch.Tensor:
        """The first part of :meth:`step`: actions -> the (N, nu) controls to hold for this step (returned; the
        environment's own buffer). A caller that runs the physics itself (e.g. asynchronously, overlapping another
        batch's math) then calls ``backend.step(ctrl, scene.config.substeps)`` and :meth:`finish_step`."""
        ctrl = self.action_to_ctrl(action.detach().to(self.device, torch.float32))
        self._ctrl[:, self._act_cols] = ctrl
        if self._delta_cols.numel():
            self._held = torch.where(self.delta_hinges, ctrl, self._held)
        hold = self.start_hold_gain()
        if self.object_gain > 0.0 or (self.object_weight_gain or 0.0) > 0.0 or hold is not None:
            self._ctrl[:, self._voc_cols.flatten()] = self.object_wrench(hold).flatten(1)
        if self.root_gain > 0.0:
            self._ctrl[:, self._rac_cols] = self.root_wrench()
        if self.adhesion_gain > 0.0 or self._adh_cols.numel():
            self._ctrl[:, self._adh_cols] = self.adhesion_ctrl()
        return self._ctrl

    def finish_step(self, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict]:
        """The rest of :meth:`step` once the physics has advanced: observations, rewards, terminations and
        resets, as :meth:`step` returns them (``action``: the one given to :meth:`prepare_step`)."""
        self.frame += 1
        self.steps += 1
        s = self.sim_state()
        if self.on_step is not None:
            self.on_step(s, action)
        sq = self._point_sq_dists(s)  # shared by the reward's interaction graph and the observation
        rf = self.ref_frame(self.frame)
        hand = self._sim_hand(s)  # shared by reward, terminations and the evaluation errors
        _, phase = self._window()
        wrists = self.wrist_targets(s, rf) if self.cfg.wrist_frame == "object" else None
        reward, terms = self._reward(s, rf, hand, phase, sq, wrists)
        terminated, reason = self._terminations(s, rf, hand, phase, wrists)
        if self.starts is not None:
            self.starts.record(self.frame, terminated)
        if self.bank is not None:
            self.bank.record(self.frame, self._lineage & ~terminated, self.backend.qpos, self.backend.qvel, self._gen)
        T = self.ref.num_frames
        truncated = ((self.frame >= T - 1) | (self.steps >= self.cfg.max_episode_frames)) & ~terminated
        done = terminated | truncated
        info = {
            "terms": terms,
            "termination_reason": reason,
            "time_outs": truncated,
            "episode_frames": self.steps.clone(),
            "episode_start": self.start.clone(),
            "frame": self.frame.clone(),
        }
        if self.eval_info:
            info["eval"] = self._eval_errors(s, rf, hand)
        self._prev_joint_vel = s.joint_vel
        self._prev_obj_vel = torch.cat([s.obj_linvel, s.obj_angvel], -1)
        if self.device.type != "cpu" or bool(done.any()):  # on a GPU: always, masked (no host round trip)
            self._reset_worlds(done)
            s = self.sim_state()
            if sq is not None and self.device.type == "cpu":  # only the reset worlds' distances changed
                ids = done.nonzero().flatten()
                sq[ids] = self._point_sq_dists(s, ids)
            else:
                sq = self._point_sq_dists(s)
        return self._observe(s, sq), reward, terminated, truncated, info

    def start_hold_gain(self) -> torch.Tensor | None:
        """(N,) the object controller's gain that :attr:`object_start_hold` gives each world this step: 1 -
        steps / object_start_hold after a reset at a frame > 0, else 0; None when off."""
        if self.object_start_hold <= 0:
            return None
        hold = (1.0 - self.steps.to(torch.float32) / self.object_start_hold).clamp(min=0.0)
        return hold * (self.start > 0)

    def object_wrench(self, hold: torch.Tensor | None = None) -> torch.Tensor:
        """(N, O, 6) virtual object controller: world force and local torque pulling each dynamic object toward
        its reference at the frame being stepped to, times :attr:`object_gain` x each world's :attr:`object_scale`
        (gravity compensated); ``hold`` (N,): per-world gains that raise it (:meth:`start_hold_gain`)."""
        if not self.has_object_controller:
            raise RuntimeError("object_gain > 0 needs a scene built with SceneConfig(object_actuators=True)")
        c, r = self.cfg.object_controller, self.ref
        f = (self.frame + 1).clamp(0, r.num_frames - 1)
        qpos, qvel = self.backend.qpos.to(torch.float32), self.backend.qvel.to(torch.float32)
        pos, quat = qpos[:, self._obj_pos_q], qpos[:, self._obj_quat_q]
        lin, ang = qvel[:, self._obj_lin_v], qvel[:, self._obj_ang_v]
        pd = c.kp * (r.obj_pos[f] - pos) + c.kd * (r.obj_linvel[f] - lin)
        if c.horizontal != 1.0:  # only while the reference object moves: at rest it is held in place
            moving = r.obj_linvel[f].norm(dim=-1, keepdim=True) > DRIVE_MIN_SPEED
            pd = torch.where(moving, pd * self._horizontal_share, pd)
        rot = quat_to_rotvec(quat_mul(quat_conj(quat), r.obj_quat[f]))  # local frame
        alpha = c.kr * rot + c.dr * (r.obj_angvel_local[f] - ang)
        # per world: the episode's share of the curriculum's gain (ones without spread), raised by any start hold
        gain = self.object_gain * self.object_scale
        weight = None if self.object_weight_gain is None else self.object_weight_gain * self.object_scale
        if hold is not None:
            gain, weight = torch.maximum(hold, gain), None if weight is None else torch.maximum(hold, weight)
        gain, weight = gain[:, None, None], None if weight is None else weight[:, None, None]
        if weight is None:
            return gain * torch.cat([self._obj_mass * (pd + self._gravity), self._obj_inertia * alpha], -1)
        acc = gain * pd + weight * self._gravity
        return torch.cat([self._obj_mass * acc, gain * self._obj_inertia * alpha], -1)

    def root_wrench(self) -> torch.Tensor:
        """(N, 6) root assist: world force and local torque pulling the humanoid's root toward the reference root
        pose and velocity of the frame being stepped to, times :attr:`root_gain` (no gravity support)."""
        if not self.has_root_assist:
            raise RuntimeError("root_gain > 0 needs a scene built with SceneConfig(root_actuators=True)")
        c = self.cfg.root_assist
        f = (self.frame + 1).clamp(0, self.ref.num_frames - 1)
        rq, rv = self._ref_qpos[f].to(torch.float32), self._ref_qvel[f].to(torch.float32)
        qpos, qvel = self.backend.qpos[:, :7].to(torch.float32), self.backend.qvel[:, :6].to(torch.float32)
        acc = c.kp * (rq[:, :3] - qpos[:, :3]) + c.kd * (rv[:, :3] - qvel[:, :3])
        rot = quat_to_rotvec(quat_mul(quat_conj(qpos[:, 3:7]), rq[:, 3:7]))  # local frame
        alpha = c.kr * rot + c.dr * (rv[:, 3:6] - qvel[:, 3:6])
        m = self.root_gain * self._root_mass
        return torch.cat([m * acc, (m * c.inertia) * alpha], -1)

    def adhesion_ctrl(self) -> torch.Tensor:
        """(N, n_adh) pull (N) of each hand body's adhesion actuator this step: ``hand_adhesion.force`` x
        :attr:`adhesion_gain` where that side's reference hand touches the object at the frame being stepped to,
        else 0."""
        if self.adhesion_gain > 0.0 and not self.has_hand_adhesion:
            raise RuntimeError("adhesion_gain > 0 needs a scene built with SceneConfig(hand_adhesion=True)")
        f = (self.frame + 1).clamp(0, self.ref.num_frames - 1)
        touch = self.ref.hand[f].to(torch.float32)[:, self._adh_side]  # (N, n_adh)
        return (self.cfg.hand_adhesion.force * self.adhesion_gain) * touch

    def _sim_hand(self, s: SimState) -> torch.Tensor:
        """(N, 2) bool: any body of the left / right hand touches a dynamic object."""
        return s.contact_obj[:, self._hand_idx].any(-1)

    def _eval_errors(self, s: SimState, rf: RefFrame, hand: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-world tracking errors of this step, from the state before any auto-reset (for evaluation):
        ``obj_pos`` (m) and ``obj_rot`` (rad) mean over dynamic objects, ``wrist_pos`` (m) and ``wrist_rot``
        (rad) mean over both wrists, all (N,); ``sim_hand`` and ``ref_hand`` (N, 2) bool hand-object contact."""
        w = self.sets.wrists
        return {
            "obj_pos": torch.linalg.vector_norm(s.obj_pos - rf.obj_pos, dim=-1).mean(-1),
            "obj_rot": quat_angle(rf.obj_quat, s.obj_quat).mean(-1),
            "wrist_pos": torch.linalg.vector_norm(s.body_pos[:, w] - rf.body_pos[:, w], dim=-1).mean(-1),
            "wrist_rot": quat_angle(rf.body_quat[:, w], s.body_quat[:, w]).mean(-1),
            "sim_hand": hand,
            "ref_hand": rf.hand,
        }

    def _window(self) -> tuple[torch.Tensor, torch.Tensor]:
        ph = self._phase_table[(self.frame - self._phase_lo).clamp(0, len(self._phase_table) - 1)]
        return ph != W.OUTSIDE, ph

    def _reward(
        self,
        s: SimState,
        rf: RefFrame,
        sim_hand: torch.Tensor,
        phase: torch.Tensor,
        sq: torch.Tensor | None = None,
        wrists: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Reward and its terms; ``sq``: :meth:`_point_sq_dists` of ``s`` and ``wrists``: :meth:`wrist_targets`
        (``wrist_frame=object``), if already computed."""
        in_window = phase != W.OUTSIDE
        f = self.frame.clamp(0, self.ref.num_frames - 1)
        key = self.sets.key
        ref_pos, ref_quat = rf.body_pos, rf.body_quat
        if self.cfg.wrist_frame == "object":  # the wrist factors' targets only (the interaction graph keeps rf's)
            wp, wq = self.wrist_targets(s, rf) if wrists is None else wrists
            ref_pos = ref_pos.index_copy(1, self.sets.wrists, wp)
            ref_quat = ref_quat.index_copy(1, self.sets.wrists, wq)
        x = RewardInputs(
            body_pos=s.body_pos,
            body_quat=s.body_quat,
            ref_body_pos=ref_pos,
            ref_body_quat=ref_quat,
            ref_near_dist=self.ref.near_dist.index_select(0, f),
            obj_pos=s.obj_pos,
            obj_quat=s.obj_quat,
            ref_obj_pos=rf.obj_pos,
            ref_obj_quat=rf.obj_quat,
            ig_pos=s.body_pos.index_select(1, key),
            ref_ig_pos=rf.body_pos.index_select(1, key),
            points=s.points,
            ref_points=rf.points,
            contact_obj=s.contact_obj,
            ref_labels=rf.labels,
            ref_hand=rf.hand,
            sim_hand=sim_hand,
            joint_vel=s.joint_vel,
            prev_joint_vel=self._prev_joint_vel,
            obj_vel=torch.cat([s.obj_linvel, s.obj_angvel], -1),
            prev_obj_vel=self._prev_obj_vel,
            contact_force=s.contact_force,
            in_window=in_window,
            grasp_hands=self._grasp,
            step=self.steps,
            dt=self.scene.config.control_dt,
            ig_sq_dists=None if sq is None else sq[:, : len(key)],
            ref_ig_weights=None if self._ref_ig_w is None else self._ref_ig_w.index_select(0, f),
            body_linvel=None if self._ref_vel is None else s.body_linvel,
            feet_contact=None if self._ref_feet_contact is None else s.contact.index_select(1, self.sets.feet),
            ref_feet_contact=None if self._ref_feet_contact is None else self._ref_feet_contact.index_select(0, f),
            ref_body_linvel=None if self._ref_vel is None else self._ref_vel.index_select(0, f),
            tip_sq_dists=self._tip_sq_dists(s, sq) if self.cfg.weights.fingertip > 0 else None,
            ref_obj_linvel=self.ref.obj_linvel.index_select(0, f) if self.cfg.weights.drive > 0 else None,
            obj_weight=self._obj_weight,
        )
        return compute_reward(x, self.sets, self.cfg)

    def wrist_targets(self, s: SimState, rf: RefFrame) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 2, 3), (N, 2, 4) wrist targets in the object frame (``wrist_frame=object``): for a hand the reference
        shows touching an object this frame, its reference wrist pose relative to the reference pose of the first
        dynamic object, carried by that object's simulated pose; the reference wrist pose otherwise."""
        w = self.sets.wrists
        pos, quat = rf.body_pos.index_select(1, w), rf.body_quat.index_select(1, w)
        if s.obj_pos.shape[1] == 0:
            return pos, quat
        ref_q, sim_q = rf.obj_quat[:, :1], s.obj_quat[:, :1]  # (N, 1, 4)
        to_sim = quat_mul(sim_q, quat_conj(ref_q))  # (N, 1, 4): reference object frame -> simulated object frame
        goal_pos = quat_rotate(to_sim.expand_as(quat), pos - rf.obj_pos[:, :1]) + s.obj_pos[:, :1]
        goal_quat = quat_mul(to_sim.expand_as(quat), quat)
        use = rf.hand[..., None]
        return torch.where(use, goal_pos, pos), torch.where(use, goal_quat, quat)

    def _tip_sq_dists(self, s: SimState, sq: torch.Tensor | None) -> torch.Tensor:
        """(N, 2, nt) squared distance of each hand's fingertips to their nearest object surface point."""
        tips = self.sets.fingertips
        if sq is None:
            sq = self._point_sq_dists(s)
        if sq is None:  # no dynamic object: nothing to close on
            return torch.zeros(s.body_pos.shape[0], *tips.shape, device=self.device)
        rows = self._sq_unperm.index_select(0, tips.flatten())
        return sq.index_select(1, rows).amin(-1).view(-1, *tips.shape)

    def _terminations(
        self,
        s: SimState,
        rf: RefFrame,
        sim_hand: torch.Tensor,
        ph: torch.Tensor,
        wrists: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        lost = self.lost.update(rf.hand, sim_hand)
        w = self.sets.wrists
        ref_wp, ref_wq = rf.body_pos.index_select(1, w), rf.body_quat.index_select(1, w)
        if self.cfg.wrist_frame == "object":
            ref_wp, ref_wq = self.wrist_targets(s, rf) if wrists is None else wrists
        x = TerminationInputs(
            root_height=s.body_pos[:, 0, 2],
            body_pos=s.body_pos,
            ref_body_pos=rf.body_pos,
            obj_points=s.points,
            ref_obj_points=rf.points,
            contact_lost=lost,
            wrist_pos=s.body_pos.index_select(1, w),
            ref_wrist_pos=ref_wp,
            wrist_quat=s.body_quat.index_select(1, w),
            ref_wrist_quat=ref_wq,
            phase=ph,
            grasp_hands=self._grasp,
            step=self.steps,
        )
        return check_terminations(x, self.sets, self.cfg)

    # -- checkpointing -------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, object]:
        """Everything needed to continue bit-for-bit: physics state of every world, episode bookkeeping and
        the generator of start frames."""
        return {
            **self.backend.state_dict(),
            "frame": self.frame.clone(),
            "start": self.start.clone(),
            "steps": self.steps.clone(),
            "contact_lost": self.lost.counts.clone(),
            "prev_joint_vel": self._prev_joint_vel.clone(),
            "prev_obj_vel": self._prev_obj_vel.clone(),
            "generator": self._gen.get_state(),
            "start_failures": None if self.starts is None else self.starts.failures.clone(),
            "lineage": self._lineage.clone(),
            "finger_hold": self._held.clone(),
            "object_scale": self.object_scale.clone(),
            **({} if self.bank is None else self.bank.state_dict()),
            "sequence_id": self.scene.sequence_id,
            "num_worlds": self.num_worlds,
        }

    def load_state_dict(self, state: dict[str, object]) -> None:
        """Restore :meth:`state_dict` (same scene and number of worlds)."""
        if state["sequence_id"] != self.scene.sequence_id or state["num_worlds"] != self.num_worlds:
            raise ValueError(
                f"checkpoint is for {state['sequence_id']} x {state['num_worlds']} worlds, this environment is "
                f"{self.scene.sequence_id} x {self.num_worlds}"
            )
        self.backend.load_state_dict(state)  # type: ignore[arg-type]
        self.frame[:] = state["frame"]  # type: ignore[index]
        self.start[:] = state["start"]  # type: ignore[index]
        self.steps[:] = state["steps"]  # type: ignore[index]
        self.lost.counts[:] = state["contact_lost"]  # type: ignore[index]
        self._prev_joint_vel[:] = state["prev_joint_vel"]  # type: ignore[index]
        self._prev_obj_vel[:] = state["prev_obj_vel"]  # type: ignore[index]
        self._gen.set_state(state["generator"].cpu())  # type: ignore[union-attr]
        if self.starts is not None and state.get("start_failures") is not None:
            self.starts.failures[:] = state["start_failures"]  # type: ignore[index]
        if state.get("lineage") is not None:
            self._lineage[:] = state["lineage"]  # type: ignore[index]
        if state.get("finger_hold") is not None:
            self._held[:] = state["finger_hold"]  # type: ignore[index]
        if state.get("object_scale") is not None:
            self.object_scale[:] = state["object_scale"]  # type: ignore[index]
        if self.bank is not None:
            self.bank.load_state_dict(state)  # type: ignore[arg-type]

    def observe(self) -> torch.Tensor:
        """The current observation of every world (e.g. after :meth:`load_state_dict`)."""
        return self._observe()

    @staticmethod
    def reason_name(code: int) -> str:
        return REASONS.get(int(code), str(code))

    def close(self) -> None:
        self.backend.close()
