"""Write ``.rrd`` recordings (rerun) of a reference sequence, alone or beside one simulated rollout.

Entity tree (``<src>`` is ``ref`` or ``sim``; names escaped with ``rr.escape_entity_path_part``)::

    /                                   ViewCoordinates RIGHT_HAND_Z_UP (static)
    /<src>/body/<body>                  Transform3D per frame (world pose of the body frame)
    /<src>/body/<body>/geom_<k>         the body's geoms as rerun primitives or meshes (static, body frame)
    /<src>/object/<id>                  Transform3D per frame (dynamic) or once (static objects, supports)
    /<src>/object/<id>/mesh             visual mesh (static, object frame)
    /<src>/object/<id>/hulls/hull_<k>   collision hulls (static; --hulls; hidden by the blueprint)
    /ref/contacts/{contact,unknown,avoid}  bodies labelled 1 / 0 / -1, as points per frame
    /sim/contacts/object                bodies touching a dynamic object in the simulation
    /episode/end                        a labelled marker where an episode that ended early ended (from the
                                        frame after its end, when ``/sim`` and its series are cleared)
    /metrics/error/object_pos/<id>      |p_sim - p_ref| of each dynamic object (m)
    /metrics/error/object_rot/<id>      rotation angle between sim and ref object (deg)
    /metrics/error/wrist_pos/{left,right}, /metrics/error/wrist_rot/{left,right}   (m, deg)
    /metrics/error/body_pos/mean        mean body position error (m)
    /metrics/reward                     the environment's reward of each step
    /metrics/contact/ref/{left,right}   reference hand contact (0/1); /metrics/contact/sim/... simulated
    /metrics/plausibility/<metric>/{ref,sim}   per-frame plausibility of both (an exported sequence's recording)
    /metrics/phase                      contact-window phase: 0 outside, 1 approach, 2 grasp, 3 stabilise
    /events                             TextLog: first contacts, phase starts, end of the episode
    /info                               TextDocument (markdown): sequence, window, policy, summary

Timelines: ``frame`` (the reference frame, a sequence) and ``time`` (frame / fps, a duration). Everything that
changes per frame is sent with ``send_columns``, once per entity; the reference's shapes and meshes are static,
the simulation's are logged at its first frame (static data cannot be cleared). Series names are at most
:data:`LEGEND_CHARS` characters (what a legend shows unclipped); the entity path says the rest.

When the simulation ends before the clip (an early termination), the frame after its last state clears
``/sim`` and the simulated series and shows ``/episode/end``; the time-series views span the whole clip.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from wristmimic.env.config import WindowConfig
from wristmimic.env.window import PHASE_NAMES
from wristmimic.format.reader import open_dataset
from wristmimic.format.validate import check_sequence
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.rotations import quat_angle, wxyz_to_xyzw
from wristmimic.safe_io import atomic_output
from wristmimic.view.blueprint import PLAUSIBILITY_VIEWS, make_blueprint
from wristmimic.view.geometry import Color, GeomShape, entity_part, geom_archetype, humanoid_geoms, mesh_archetype
from wristmimic.view.rollout import Actor, run_rollout
from wristmimic.view.tracks import ObjectTrack, ReferenceTrack, SimTrack, reference_from_dataset, reference_from_env

if TYPE_CHECKING:
    from wristmimic.env.vec_env import WristMimicEnv

APPLICATION_ID = "wristmimic"
LEGEND_CHARS = 14
"""Longest series name: longer names are clipped by the legend of a time-series view."""


@dataclass(frozen=True)
class Palette:
    """Colours (RGBA) of each source; the reference is translucent when a simulation is shown beside it."""

    sim_body: Color = (70, 130, 230, 255)
    sim_object: Color = (40, 90, 200, 255)
    ref_body: Color = (255, 140, 0, 255)
    ref_body_ghost: Color = (255, 140, 0, 90)
    ref_object: Color = (240, 160, 60, 255)
    ref_object_ghost: Color = (240, 160, 60, 90)
    static_object: Color = (160, 160, 160, 255)
    hull: Color = (110, 200, 110, 120)
    contact: Color = (40, 200, 70, 255)
    unknown: Color = (170, 170, 170, 255)
    avoid: Color = (220, 50, 50, 255)
    sim_contact: Color = (0, 220, 220, 255)
    left: Color = (40, 120, 230, 255)
    right: Color = (230, 60, 60, 255)
    ref_left: Color = (255, 140, 0, 255)
    """Series of the reference: orange tones (as its bodies); of the simulation: blue tones."""
    ref_right: Color = (180, 80, 0, 255)
    sim_left: Color = (70, 130, 230, 255)
    sim_right: Color = (0, 190, 210, 255)
    episode_end: Color = (220, 30, 30, 255)


PALETTE = Palette()


@dataclass
class RecordingSummary:
    """What was written."""

    path: Path
    ref_frames: int
    sim_frames: int
    """Recorded simulation states (0 for a reference-only recording)."""
    end_reason: str | None
    bytes: int
    errors: dict[str, float] = field(default_factory=dict)
    """Mean of every error series (entity path -> mean)."""
    trial: dict[str, float] = field(default_factory=dict)
    """The rollout's metrics as an evaluation's per-trial table has them (:func:`trial_metrics`)."""


# -- public API ----------------------------------------------------------------------------------------------
def record_reference(
    dataset: str | Path,
    sequence_id: str,
    out: str | Path,
    *,
    hulls: bool = False,
    window: WindowConfig | None = None,
    max_frames: int | None = None,
) -> RecordingSummary:
    """Record the converted data of one sequence (no simulation): humanoid bodies posed by the stored
    ``body_pos``/``body_quat``, objects and supports, contact labels, hand contact, window and phases."""
    with open_dataset(dataset) as ds:
        check_sequence(ds, sequence_id)
        ref = reference_from_dataset(ds, sequence_id, max_frames)
        hid = ds.sequence(sequence_id).humanoid_id
        skel = load_skeleton(ds.humanoid(hid).mjcf, f"{ds.path}:humanoids/{hid}")
    geoms = humanoid_geoms(skel.model, np.arange(1, skel.num_bodies + 1))
    return write_recording(out, ref, geoms, window=window or WindowConfig(), hulls=hulls)


def record_rollout(
    env: WristMimicEnv,
    actor: Actor,
    out: str | Path,
    *,
    start_frame: int = 0,
    hulls: bool = False,
    info: dict[str, str] | None = None,
    max_steps: int | None = None,
) -> RecordingSummary:
    """Run one rollout of ``actor`` in world 0 of ``env`` from ``start_frame`` until its episode ends and
    record it (``/sim``) beside the environment's reference (``/ref``) with error series (``/metrics``)."""
    ref = reference_from_env(env)
    sim = run_rollout(env, actor, start_frame, max_steps)
    sim.info.update(info or {})
    geoms = humanoid_geoms(env.scene.model, env.scene.body_ids)
    return write_recording(out, ref, geoms, sim=sim, window=env.cfg.window, hulls=hulls)


def write_recording(
    out: str | Path,
    ref: ReferenceTrack,
    geoms: list[list[GeomShape]],
    *,
    sim: SimTrack | None = None,
    window: WindowConfig | None = None,
    hulls: bool = False,
    recording_id: str | None = None,
    plausibility: dict[str, dict[str, np.ndarray]] | None = None,
) -> RecordingSummary:
    """Write ``ref`` (and ``sim``) to ``out`` atomically, with the default blueprint embedded.

    ``plausibility``: ``{"ref": series, "sim": series}`` of :func:`wristmimic.plausibility.plausibility_series`,
    plotted as ``/metrics/plausibility/<metric>/<src>``."""
    window = window or WindowConfig()
    out = Path(out)
    primary = "sim" if sim is not None else "ref"
    hidden = [f"/{primary}/object/{entity_part(o.id)}/hulls" for o in ref.objects] if hulls else []
    errors: dict[str, np.ndarray] = {}
    with atomic_output(out, suffix=".rrd") as tmp:
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id or str(uuid.uuid4()))
        try:
            blueprint = make_blueprint(
                sim is not None,
                hidden,
                ref.fps,
                num_frames=ref.num_frames,
                plausibility=bool(plausibility),
                reward=sim is not None and bool(np.isfinite(sim.reward).any()),
            )
            rec.save(tmp, default_blueprint=blueprint)
            rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            _log_reference(rec, ref, geoms, window, ghost=sim is not None, hulls=hulls and primary == "ref")
            if sim is not None:
                errors = _log_simulation(rec, ref, sim, geoms, hulls)
                _log_episode_end(rec, ref, sim)
            if plausibility:
                _log_plausibility(rec, ref, sim, plausibility)
            _log_events(rec, ref, window, sim)
            text = info_markdown(ref, window, sim, errors)
            rec.log("/info", rr.TextDocument(text, media_type="text/markdown"), static=True)
            rec.flush()
        finally:
            rec.disconnect()
    return RecordingSummary(
        path=out,
        ref_frames=ref.num_frames,
        sim_frames=0 if sim is None else sim.num_frames,
        end_reason=None if sim is None else sim.end_reason,
        bytes=out.stat().st_size,
        errors={k: float(np.mean(v)) for k, v in errors.items()},
        trial={} if sim is None else trial_metrics(ref, sim),
    )


# -- metrics -------------------------------------------------------------------------------------------------
def error_series(ref: ReferenceTrack, sim: SimTrack) -> dict[str, np.ndarray]:
    """Entity path -> (K,) error of every recorded simulation state against the reference at its frame:
    object and wrist position (m) and rotation (deg) errors, and the mean body position error (m)."""
    f = sim.frames
    out: dict[str, np.ndarray] = {}
    for j, o in enumerate(ref.dynamic_objects):
        name = entity_part(o.id)
        out[f"/metrics/error/object_pos/{name}"] = _dist(sim.obj_pos[:, j], o.pos[f])
        out[f"/metrics/error/object_rot/{name}"] = np.degrees(quat_angle(sim.obj_quat[:, j], o.quat[f]))
    for side, b in zip(("left", "right"), ref.roles["wrists"], strict=True):
        out[f"/metrics/error/wrist_pos/{side}"] = _dist(sim.body_pos[:, b], ref.body_pos[f, b])
        out[f"/metrics/error/wrist_rot/{side}"] = np.degrees(quat_angle(sim.body_quat[:, b], ref.body_quat[f, b]))
    out["/metrics/error/body_pos/mean"] = _dist(sim.body_pos, ref.body_pos[f]).mean(axis=1)
    return out


def trial_metrics(ref: ReferenceTrack, sim: SimTrack) -> dict[str, float]:
    """The rollout summarised as ``wristmimic.evaluate`` summarises a trial: means over the stepped frames
    (states 1..K-1) of the object error (mean over dynamic objects) and wrist error (mean over both wrists) in
    cm and degrees, the contact ratio (reference hand-frames touching that the simulated hand also touched,
    over all reference hand-frames after the start; 1 without reference contact) and the frames completed."""
    if sim.num_frames < 2:
        return {"frames_completed": 0.0}
    e = error_series(ref, sim)

    def mean_of(kind: str) -> float:
        rows = [v[1:] for k, v in e.items() if k.startswith(f"/metrics/error/{kind}/")]
        return float(np.mean(np.mean(rows, axis=0))) if rows else float("nan")

    f = sim.frames[1:]
    kept = int((ref.hand[f] & sim_hand_contact(ref, sim)[1:]).sum())
    total = int(ref.hand[int(sim.frames[0]) + 1 :].sum())
    return {
        "frames_completed": float(sim.num_frames - 1),
        "obj_pos_err_cm": 100.0 * mean_of("object_pos"),
        "obj_rot_err_deg": mean_of("object_rot"),
        "wrist_pos_err_cm": 100.0 * mean_of("wrist_pos"),
        "wrist_rot_err_deg": mean_of("wrist_rot"),
        "contact_ratio": kept / total if total else 1.0,
    }


def _dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1)


def sim_hand_contact(ref: ReferenceTrack, sim: SimTrack) -> np.ndarray:
    """(K, 2) bool: any body of the left / right hand touches a dynamic object in the simulation."""
    hands = [ref.roles["left_hand"], ref.roles["right_hand"]]
    return np.stack([sim.contact_obj[:, np.asarray(h, dtype=int)].any(axis=1) for h in hands], axis=1)


# -- logging -------------------------------------------------------------------------------------------------
def _times(frames: np.ndarray, fps: float) -> list[rr.TimeColumn]:
    frames = np.asarray(frames, dtype=np.int64)
    return [rr.TimeColumn("frame", sequence=frames), rr.TimeColumn("time", duration=frames / float(fps))]


def _log_at(rec: rr.RecordingStream, path: str, archetype: rr.AsComponents, at: int | None, fps: float) -> None:
    """Log ``archetype`` statically (``at`` None) or at frame ``at`` (then a later ``Clear`` can remove it)."""
    if at is None:
        rec.log(path, archetype, static=True)
        return
    rec.set_time("frame", sequence=int(at))
    rec.set_time("time", duration=int(at) / float(fps))
    rec.log(path, archetype)
    rec.reset_time()


def _send_pose(rec: rr.RecordingStream, path: str, frames: np.ndarray, fps: float, pos: np.ndarray, quat: np.ndarray):
    rec.send_columns(
        path,
        indexes=_times(frames, fps),
        columns=rr.Transform3D.columns(
            translation=np.asarray(pos, np.float32), quaternion=wxyz_to_xyzw(np.asarray(quat, np.float32))
        ),
    )


def _log_humanoid(
    rec: rr.RecordingStream,
    src: str,
    ref: ReferenceTrack,
    geoms: list[list[GeomShape]],
    frames: np.ndarray,
    pos: np.ndarray,
    quat: np.ndarray,
    color: Color,
    fill: str,
    at: int | None = None,
) -> None:
    """Geoms of every body (static, or at frame ``at``) and the bodies' poses per frame."""
    for b, name in enumerate(ref.body_names):
        path = f"/{src}/body/{entity_part(name)}"
        for k, g in enumerate(geoms[b]):
            _log_at(rec, f"{path}/geom_{k}", geom_archetype(g, color, fill), at, ref.fps)
        _send_pose(rec, path, frames, ref.fps, pos[:, b], quat[:, b])


def _log_reference(
    rec: rr.RecordingStream,
    ref: ReferenceTrack,
    geoms: list[list[GeomShape]],
    window: WindowConfig,
    ghost: bool,
    hulls: bool,
) -> None:
    """``/ref``: bodies and objects (translucent when ``ghost``), contact labels, hand contact and phases."""
    frames = np.arange(ref.num_frames)
    body = PALETTE.ref_body_ghost if ghost else PALETTE.ref_body
    fill = "transparentfillmajorwireframe" if ghost else "solid"
    _log_humanoid(rec, "ref", ref, geoms, frames, ref.body_pos, ref.body_quat, body, fill)
    for o in ref.objects:
        color = (PALETTE.ref_object_ghost if ghost else PALETTE.ref_object) if o.dynamic else PALETTE.static_object
        _log_object(rec, "ref", o, frames if o.dynamic else None, o.pos, o.quat, color, ref.fps, hulls)
    _log_ref_contacts(rec, ref)
    _log_reference_series(rec, ref, window)


def _log_simulation(
    rec: rr.RecordingStream, ref: ReferenceTrack, sim: SimTrack, geoms: list[list[GeomShape]], hulls: bool
) -> dict[str, np.ndarray]:
    """``/sim`` (bodies, objects, contacts) and the ``/metrics`` series of the rollout; returns the errors."""
    at = int(sim.frames[0])
    _log_humanoid(rec, "sim", ref, geoms, sim.frames, sim.body_pos, sim.body_quat, PALETTE.sim_body, "solid", at)
    _log_sim_objects(rec, ref, sim, hulls)
    _log_points(
        rec, "/sim/contacts/object", sim.frames, ref.fps, sim.body_pos, sim.contact_obj, 0.025, PALETTE.sim_contact
    )
    errors = error_series(ref, sim)
    _log_sim_series(rec, ref, sim, errors)
    return errors


def _log_object(
    rec: rr.RecordingStream,
    src: str,
    o: ObjectTrack,
    frames: np.ndarray | None,
    pos: np.ndarray,
    quat: np.ndarray,
    color: Color,
    fps: float,
    hulls: bool,
    at: int | None = None,
) -> None:
    """An object's meshes (static, or at frame ``at``) and pose: per frame, or once when ``frames`` is None."""
    path = f"/{src}/object/{entity_part(o.id)}"
    if len(o.record.vertices) and len(o.record.faces):
        _log_at(rec, f"{path}/mesh", mesh_archetype(o.record.vertices, o.record.faces, color), at, fps)
    if hulls:
        for k, (v, f) in enumerate(o.record.hulls()):
            _log_at(rec, f"{path}/hulls/hull_{k}", mesh_archetype(v, f, PALETTE.hull), at, fps)
    if frames is None:
        q = wxyz_to_xyzw(np.asarray(quat[0], np.float64))
        _log_at(rec, path, rr.Transform3D(translation=pos[0], quaternion=rr.Quaternion(xyzw=q)), at, fps)
    else:
        _send_pose(rec, path, frames, fps, pos, quat)


def _log_sim_objects(rec: rr.RecordingStream, ref: ReferenceTrack, sim: SimTrack, hulls: bool) -> None:
    j = 0
    for o in ref.objects:
        if o.dynamic:
            pos, quat, frames, color = sim.obj_pos[:, j], sim.obj_quat[:, j], sim.frames, PALETTE.sim_object
            j += 1
        else:
            pos, quat, frames, color = o.pos, o.quat, None, PALETTE.static_object
        _log_object(rec, "sim", o, frames, pos, quat, color, ref.fps, hulls, at=int(sim.frames[0]))


def _log_points(
    rec: rr.RecordingStream,
    path: str,
    frames: np.ndarray,
    fps: float,
    pos: np.ndarray,
    mask: np.ndarray,
    radius: float,
    color: Color,
) -> None:
    """Points at ``pos[t, b]`` where ``mask[t, b]``: one row per frame, colour and radius static."""
    rec.log(path, rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)
    positions = np.asarray(pos, np.float32)[mask]
    rec.send_columns(
        path, indexes=_times(frames, fps), columns=rr.Points3D.columns(positions=positions).partition(mask.sum(1))
    )


def _log_ref_contacts(rec: rr.RecordingStream, ref: ReferenceTrack) -> None:
    frames = np.arange(ref.num_frames)
    for name, label, radius, color in (
        ("contact", 1, 0.025, PALETTE.contact),
        ("unknown", 0, 0.01, PALETTE.unknown),
        ("avoid", -1, 0.01, PALETTE.avoid),
    ):
        _log_points(rec, f"/ref/contacts/{name}", frames, ref.fps, ref.body_pos, ref.labels == label, radius, color)


def short_name(name: str) -> str:
    """``name`` cut to :data:`LEGEND_CHARS` characters (the end replaced by "~")."""
    return name if len(name) <= LEGEND_CHARS else name[: LEGEND_CHARS - 1] + "~"


def _log_series(
    rec: rr.RecordingStream,
    path: str,
    frames: np.ndarray,
    fps: float,
    values: np.ndarray,
    name: str,
    color: Color,
    width: float | None = None,
) -> None:
    """A named, coloured line (its legend name at most :data:`LEGEND_CHARS` long); non-finite values left out."""
    style = rr.SeriesLines(names=[short_name(name)], colors=[color], widths=None if width is None else [width])
    rec.log(path, style, static=True)
    values = np.asarray(values, float)
    ok = np.isfinite(values)
    if ok.any():
        rec.send_columns(
            path, indexes=_times(np.asarray(frames)[ok], fps), columns=rr.Scalars.columns(scalars=values[ok])
        )


def _log_reference_series(rec: rr.RecordingStream, ref: ReferenceTrack, window: WindowConfig) -> None:
    frames = np.arange(ref.num_frames)
    for k, (side, color) in enumerate((("left", PALETTE.ref_left), ("right", PALETTE.ref_right))):
        path = f"/metrics/contact/ref/{side}"
        _log_series(rec, path, frames, ref.fps, ref.hand[:, k], f"ref {side[0].upper()}", color, width=3.0)
    _log_series(rec, "/metrics/phase", frames, ref.fps, ref.phases(window), "phase", (120, 120, 120, 255))


def _log_sim_series(rec: rr.RecordingStream, ref: ReferenceTrack, sim: SimTrack, errors: dict[str, np.ndarray]):
    palette = [PALETTE.sim_object, (200, 120, 0, 255), (120, 60, 180, 255), (0, 150, 120, 255)]
    used: dict[str, int] = {}
    for path, values in errors.items():
        kind, leaf = path.split("/")[3], path.rsplit("/", 1)[-1]
        if leaf in ("left", "right"):
            color = PALETTE.left if leaf == "left" else PALETTE.right
            name = f"wrist {leaf[0].upper()}"  # the view says position or rotation; the path says the rest
        else:
            color = palette[used.get(kind, 0) % len(palette)]
            used[kind] = used.get(kind, 0) + 1
            name = "body mean" if kind == "body_pos" else leaf
        _log_series(rec, path, sim.frames, ref.fps, values, name, color)
    hand = sim_hand_contact(ref, sim)
    for k, (side, color) in enumerate((("left", PALETTE.sim_left), ("right", PALETTE.sim_right))):
        path = f"/metrics/contact/sim/{side}"
        _log_series(rec, path, sim.frames, ref.fps, hand[:, k], f"sim {side[0].upper()}", color, width=1.5)
    if np.isfinite(sim.reward).any():
        _log_series(rec, "/metrics/reward", sim.frames, ref.fps, sim.reward, "reward", (90, 90, 90, 255))


SIM_SERIES = ["/metrics/error", "/metrics/contact/sim", "/metrics/reward"]
"""Series of the simulation, cleared with ``/sim`` after an early end."""


def _log_episode_end(rec: rr.RecordingStream, ref: ReferenceTrack, sim: SimTrack) -> None:
    """When the simulation ended before the clip: at the next frame, clear ``/sim`` and its series and mark where
    (and why) the episode ended with a labelled point at its last root position (``/episode/end``)."""
    last = int(sim.frames[-1])
    if last >= ref.num_frames - 1:
        return
    rec.set_time("frame", sequence=last + 1)
    rec.set_time("time", duration=(last + 1) / float(ref.fps))
    rec.log("/sim", rr.Clear(recursive=True))
    for path in SIM_SERIES:
        rec.log(path, rr.Clear(recursive=True))
    label = f"episode ended at frame {last}: {sim.end_reason}"
    marker = rr.Points3D(
        [sim.body_pos[-1, 0]], radii=[0.05], colors=[PALETTE.episode_end], labels=[label], show_labels=True
    )
    rec.log("/episode/end", marker)
    rec.reset_time()


PLAUSIBILITY_NAMES = {
    "hand_object_depth_m": "hand pen",
    "body_floor_depth_m": "floor pen",
    "object_support_depth_m": "supp pen",
    "hand_gap_m": "hand gap",
    "foot_height_m": "foot z",
    "foot_skate_speed_m_s": "skate",
    "object_float": "floating",
    "body_jerk_m_s3": "body jerk",
    "object_jerk_m_s3": "obj jerk",
}
"""Legend names of :func:`wristmimic.plausibility.plausibility_series`' metrics (the path keeps the full name)."""


def plausibility_color(metric: str, src: str) -> Color:
    """The colour of a plausibility series: by the metric's place in its view (:data:`PLAUSIBILITY_VIEWS`) and
    the source, as the contact series are coloured: the first metric of a view orange (``ref``) / blue (``sim``),
    the second brown / cyan; grey for a metric no view shows or another source."""
    place = next((ms.index(metric) for ms in PLAUSIBILITY_VIEWS.values() if metric in ms), None)
    colors = {
        "ref": (PALETTE.ref_left, PALETTE.ref_right),
        "sim": (PALETTE.sim_left, PALETTE.sim_right),
    }
    if place is None or src not in colors:
        return PALETTE.unknown
    return colors[src][place % 2]


def _log_plausibility(
    rec: rr.RecordingStream, ref: ReferenceTrack, sim: SimTrack | None, series: dict[str, dict[str, np.ndarray]]
) -> None:
    """``/metrics/plausibility/<metric>/<src>`` per frame, coloured by :func:`plausibility_color` (reference warm,
    simulation cool, the two metrics of a view apart)."""
    start = 0 if sim is None else int(sim.frames[0])
    for src, metrics in series.items():
        for metric, values in metrics.items():
            frames = np.arange(len(values)) + (start if src == "sim" else 0)
            name = f"{PLAUSIBILITY_NAMES.get(metric, metric)} {src}"
            path = f"/metrics/plausibility/{metric}/{src}"
            _log_series(rec, path, frames, ref.fps, values, name, plausibility_color(metric, src))


def _log_events(rec: rr.RecordingStream, ref: ReferenceTrack, window: WindowConfig, sim: SimTrack | None) -> None:
    events: list[tuple[int, str, str]] = []
    for side, f in zip(("left", "right"), ref.first_contact, strict=True):
        if f >= 0:
            events.append((int(f), f"first contact of the {side} hand (reference)", "INFO"))
    ph = ref.phases(window)
    for f in range(ref.num_frames):
        if ph[f] != (ph[f - 1] if f else 0):
            events.append((f, f"phase: {PHASE_NAMES[int(ph[f])]}", "INFO"))
    if sim is not None:
        level = "WARN" if sim.end_reason.startswith("terminated") else "INFO"
        events.append((int(sim.frames[-1]), f"episode ended ({sim.end_reason})", level))
    if not events:
        return
    events.sort(key=lambda e: e[0])
    frames = np.array([e[0] for e in events])
    rec.send_columns(
        "/events",
        indexes=_times(frames, ref.fps),
        columns=rr.TextLog.columns(text=[e[1] for e in events], level=[e[2] for e in events]),
    )


def _phase_ranges(ph: np.ndarray) -> list[tuple[str, int, int]]:
    """(phase name, first frame, last frame) of each run of equal phase inside the window."""
    out: list[tuple[str, int, int]] = []
    for f, p in enumerate(ph):
        if p == 0:
            continue
        if out and out[-1][0] == PHASE_NAMES[int(p)] and out[-1][2] == f - 1:
            out[-1] = (out[-1][0], out[-1][1], f)
        else:
            out.append((PHASE_NAMES[int(p)], f, f))
    return out


def info_markdown(
    ref: ReferenceTrack, window: WindowConfig, sim: SimTrack | None, errors: dict[str, np.ndarray]
) -> str:
    """The text of the ``/info`` panel."""
    kinds = {True: "dynamic", False: "static"}
    objs = ", ".join(f"`{o.id}` ({'inferred support' if o.record.inferred else kinds[o.dynamic]})" for o in ref.objects)
    lines = [f"# {ref.sequence_id}", "", f"- frames: {ref.num_frames} at {ref.fps:g} fps", f"- objects: {objs or '-'}"]
    lines += [f"- {k}: {v}" for k, v in ref.info.items()]
    t_c = ref.t_c
    lines += ["", "## Contact window", ""]
    fc = ", ".join(f"{s} {int(f)}" for s, f in zip(("left", "right"), ref.first_contact, strict=True))
    lines.append(f"- first contact frame per hand: {fc} (-1: none); t_c = {t_c}")
    if t_c >= 0:
        lines.append(f"- window: [{t_c - window.t_b}, {t_c + window.t_a}] (t_c - {window.t_b} .. t_c + {window.t_a})")
        lines += [f"- {name}: frames {a}..{b}" for name, a, b in _phase_ranges(ref.phases(window))]
    else:
        lines.append("- no contact in this sequence: no window")
    if sim is not None:
        lines += ["", "## Simulation", ""]
        lines += [f"- {k}: {v}" for k, v in sim.info.items()]
        lines.append(f"- recorded frames {int(sim.frames[0])}..{int(sim.frames[-1])}, {sim.end_reason}")
        lines += ["", "| error | mean | max |", "|---|---|---|"]
        for path, v in errors.items():
            lines.append(f"| {path.removeprefix('/metrics/error/')} | {np.mean(v):.4g} | {np.max(v):.4g} |")
        trial = trial_metrics(ref, sim)
        lines += ["", "As an evaluation table has it: " + ", ".join(f"{k} {v:.4g}" for k, v in trial.items())]
    return "\n".join(lines) + "\n"
