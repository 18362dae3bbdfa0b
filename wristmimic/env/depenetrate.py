"""Reference start states whose fingers do not sit inside objects (``env.starts.depenetrate``, off by default).

Reference state initialisation copies the reference's finger angles into the start state. Where the reference
has no finger capture (OMOMO's hands are flat) or its hand and object meshes disagree, finger segments start
inside the object: on ``sub2_largetable_000`` the flat thumbs lie 3.5-4.4 cm inside the table top in every carry
frame, on ``s110_move_kettle`` fingers up to 1.4 cm inside the kettle.

Fingers get no pose targets in this method, so their start angles are free: :func:`depenetrate_fingers` moves,
frame by frame, the hinges of each finger chain (one subtree below a wrist) that penetrates a non-humanoid geom
by more than ``tol`` until it no longer does (greedy coordinate descent within the joint ranges, each round taking
the smallest hinge move that reduces the penetration, so the chain ends touching the surface rather than lifted
off it; the previous frame's offsets are kept where they still clear the object) and leaves every other column of
the state untouched. It is deterministic, so a resumed or re-evaluated run rebuilds the same table.

Measured on ``sub2_largetable_000`` (recipe of 2026-12-05, seed 0, 409,600 frames, with a first version of this
search that differed only in how it left local minima): the thumbs leave the table in
all carry frames but the grasp's first ten (up to 2.4 cm left there), a segment next to the palm keeps up to 1.8 cm;
training episodes were shorter (13.9 against 17.0 frames at 200-400k) and the mid-clip starts of the carry failed
about twice as often per step; frame-0 trials reached 55.4 frames (0 %), as without it (53-56). With zero actions
from carry frames 60 / 70 / 90 (no object controller), the reference's starts keep both hands on the table for 5-6
frames and end on ``object_error`` after 9-11; cleared starts lose hand contact after 1-4 frames and end after 8-10:
the flat fingers lodged under the table top hold it at a reference start.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wristmimic.scene import Scene

STEPS = (0.05, 0.1, 0.2, 0.4, 0.8)
"""Hinge offsets (rad) the descent tries, smallest first, both signs."""
MIN_GAIN = 5e-4
"""A move must reduce the chain's penetration by at least this much (m)."""


@dataclass
class DepenetrationStats:
    """What :func:`depenetrate_fingers` changed."""

    frames: int
    """Frames with at least one penetrating finger chain before."""
    chains: int
    """(frame, chain) pairs moved."""
    max_before: float
    """Deepest finger penetration over the clip before (m)."""
    max_after: float
    """Deepest finger penetration over the clip after (m)."""


def finger_chains(scene: Scene) -> list[list[int]]:
    """Skeleton body indices of each finger chain: the subtree of every child of either wrist."""
    skel, wrists = scene.skeleton, scene.humanoid.roles["wrists"]
    return [sorted(skel.subtree(c)) for w in np.asarray(wrists).tolist() for c in skel.children(int(w))]


class _Probe:
    """Penetration depth of finger chains against non-humanoid geoms, from one ``MjData``."""

    def __init__(self, scene: Scene, chains: list[list[int]]):
        m = self.model = scene.model
        self.data = mujoco.MjData(m)
        humanoid = np.zeros(m.nbody, dtype=bool)
        humanoid[scene.body_ids] = True
        self.chain_of_body = np.full(m.nbody, -1)
        for k, chain in enumerate(chains):
            self.chain_of_body[scene.body_ids[chain]] = k
        self.foreign = ~humanoid
        self.nchains = len(chains)

    def depths(self, qpos: np.ndarray) -> np.ndarray:
        """(chains,) deepest penetration (m, >= 0) of each chain into any non-humanoid geom at ``qpos``."""
        m, d = self.model, self.data
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        out = np.zeros(self.nchains)
        if d.ncon == 0:
            return out
        con = d.contact
        b1, b2 = m.geom_bodyid[con.geom1[: d.ncon]], m.geom_bodyid[con.geom2[: d.ncon]]
        dist = con.dist[: d.ncon]
        for a, b in ((b1, b2), (b2, b1)):
            k = self.chain_of_body[a]
            hit = (k >= 0) & self.foreign[b] & (dist < 0)
            np.maximum.at(out, k[hit], -dist[hit])
        return out


def _descend(
    probe: _Probe,
    q: np.ndarray,
    k: int,
    cols: np.ndarray,
    rng: np.ndarray,
    warm: np.ndarray,
    tol: float,
    max_rounds: int,
) -> np.ndarray:
    """Offsets of chain ``k``'s hinges ``cols`` (ranges ``rng`` (n, 2)) that bring its penetration at ``q`` to at
    most ``tol``, or as low as greedy coordinate descent gets it; ``q`` ends at the result."""
    ref, lo, hi = q[cols].copy(), rng[:, 0], rng[:, 1]

    def cost(delta: np.ndarray) -> float:
        q[cols] = np.clip(ref + delta, lo, hi)
        return float(probe.depths(q)[k])

    def descend(best: np.ndarray) -> tuple[np.ndarray, float]:
        depth = cost(best)
        for _ in range(max_rounds):
            if depth <= tol:
                break
            found = None
            for step in STEPS:  # the smallest move that helps: the chain ends touching, not lifted off
                for i in range(len(cols)):
                    for sign in (1.0, -1.0):
                        trial = best.copy()
                        trial[i] = np.clip(ref[i] + trial[i] + sign * step, lo[i], hi[i]) - ref[i]
                        if trial[i] == best[i]:  # at the joint's limit already
                            continue
                        d = cost(trial)
                        if d < depth - MIN_GAIN and (found is None or d < found[1]):
                            found = (trial, d, best)
                if found is not None:
                    break
            if found is None:
                break
            best, depth = found[0], found[1]
            move = best - found[2]
            while depth > tol:  # keep going while the same move keeps helping
                trial = np.clip(ref + best + move, lo, hi) - ref
                d = cost(trial)
                if d >= depth - MIN_GAIN:
                    break
                best, depth = trial, d
        return best, depth

    if warm.any() and cost(warm) <= tol:  # the previous frame's offsets still clear the object
        best = warm
    else:
        best, depth = descend(np.zeros(len(cols)))
        if depth > tol and warm.any():  # from the previous frame's offsets, where starting from zero got stuck
            w_best, w_depth = descend(warm.copy())
            if w_depth < depth:
                best = w_best
    q[cols] = np.clip(ref + best, lo, hi)
    return q[cols] - ref


def depenetrate_fingers(
    scene: Scene, qpos: np.ndarray, tol: float = 0.003, max_rounds: int = 12
) -> tuple[np.ndarray, DepenetrationStats]:
    """A copy of the reference state table ``qpos`` (T, nq) whose finger chains penetrate no object, wall or
    floor by more than ``tol`` (m) where a move of their hinges within range can achieve it; with statistics."""
    chains = finger_chains(scene)
    probe = _Probe(scene, chains)
    m = scene.model
    body_hinges = {int(b): i for i, b in enumerate(scene.skeleton.joint_bodies)}
    cols = [
        np.concatenate([scene.hinge_qposadr[body_hinges[b]] for b in chain if b in body_hinges]) for chain in chains
    ]
    jnt_of_qpos = {int(m.jnt_qposadr[j]): j for j in range(m.njnt)}
    ranges = [np.array([m.jnt_range[jnt_of_qpos[int(c)]] for c in cc]) for cc in cols]
    out = np.array(qpos, dtype=np.float64, copy=True)
    warm = [np.zeros(len(c)) for c in cols]
    frames = moved = 0
    max_before = max_after = 0.0
    for t in range(out.shape[0]):
        q = out[t]
        depth = probe.depths(q)
        max_before = max(max_before, float(depth.max(initial=0.0)))
        bad = set(np.flatnonzero(depth > tol).tolist())
        frames += bool(bad)
        for k in range(len(chains)):
            if k in bad:
                warm[k] = _descend(probe, q, k, cols[k], ranges[k], warm[k], tol, max_rounds)
                moved += 1
            else:
                warm[k] = np.zeros(len(cols[k]))
        max_after = max(max_after, float(probe.depths(q).max(initial=0.0)))
    return out, DepenetrationStats(frames, moved, max_before, max_after)
