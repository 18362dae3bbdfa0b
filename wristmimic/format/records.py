"""In-memory records of what the canonical file holds: humanoids, objects, sequences."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class HumanoidRecord:
    """A humanoid: its MJCF text, body tree and roles (role -> body indices)."""

    name: str
    family: str
    mjcf: str
    body_names: list[str]
    parents: np.ndarray  # (B,) int32
    joint_bodies: np.ndarray  # (J,) int32
    roles: dict[str, np.ndarray]
    source_file: str = ""
    hand: str = ""
    """Name of a hand swapped in by ``wristmimic humanoid swap-hands`` (empty: the source's own hands)."""
    hand_source: str = ""
    """Where the swapped hand's geometry came from."""
    hand_ranges: str = ""
    """Finger range mode of the swapped hand (``intermimic``, ``free``, ``hand``)."""

    @property
    def num_bodies(self) -> int:
        return len(self.body_names)


@dataclass
class ObjectRecord:
    """An object: meshes, collision hulls, mass properties and surface samples (object frame)."""

    name: str
    static: bool
    inferred: bool
    vertices: np.ndarray  # (V, 3)
    faces: np.ndarray  # (F, 3)
    hull_vertices: np.ndarray  # (Nv, 3)
    hull_faces: np.ndarray  # (Nf, 3) local to each hull
    hull_vertex_offsets: np.ndarray  # (H+1,)
    hull_face_offsets: np.ndarray  # (H+1,)
    hull_meta: dict[str, Any]  # method, params, coacd_version, cache_key
    mass: float
    com: np.ndarray  # (3,)
    inertia: np.ndarray  # (3, 3)
    mass_method: str
    density: float
    watertight: bool
    surface_points: np.ndarray  # (P, 3)
    surface_seed: int
    mesh_sha256: str
    urdf: dict[str, Any] = field(default_factory=dict)
    source_file: str = ""
    extra: dict[str, Any] = field(default_factory=dict)  # e.g. inferred-support provenance

    @property
    def num_hulls(self) -> int:
        return len(self.hull_vertex_offsets) - 1

    def hulls(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """[(vertices, faces)] per hull."""
        vo, fo = self.hull_vertex_offsets, self.hull_face_offsets
        return [
            (self.hull_vertices[vo[k] : vo[k + 1]], self.hull_faces[fo[k] : fo[k + 1]]) for k in range(self.num_hulls)
        ]


@dataclass
class SequenceRecord:
    """One reference sequence: per-frame kinematics, object poses and contacts (see schema)."""

    humanoid_id: str
    object_ids: list[str]
    subject: str
    dataset: str
    root_pos: np.ndarray
    root_quat: np.ndarray
    joint_quat: np.ndarray
    joint_angles: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray
    source_body_pos: np.ndarray
    source_body_pos_valid: np.ndarray
    object_pos: np.ndarray
    object_quat: np.ndarray
    contact_labels: np.ndarray
    contact_geometric: np.ndarray
    contact_distance: np.ndarray
    hand_contact: np.ndarray
    object_contact: np.ndarray
    first_contact_frame: np.ndarray
    contact_window: np.ndarray
    contact_meta: dict[str, Any]
    text: str = ""
    split: str = ""
    source_file: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    optional: dict[str, np.ndarray] = field(default_factory=dict)
    """Arrays of ``schema.OPTIONAL_SEQUENCE_ARRAYS`` the sequence has (``sim/actions``, ...), by schema name."""

    @property
    def num_frames(self) -> int:
        return int(self.root_pos.shape[0])

    def arrays(self) -> dict[str, np.ndarray]:
        """Schema array name -> array (the optional ones it has last)."""
        return {
            "root_pos": self.root_pos,
            "root_quat": self.root_quat,
            "joint_quat": self.joint_quat,
            "joint_angles": self.joint_angles,
            "body_pos": self.body_pos,
            "body_quat": self.body_quat,
            "source_body_pos": self.source_body_pos,
            "source_body_pos_valid": self.source_body_pos_valid,
            "object_pos": self.object_pos,
            "object_quat": self.object_quat,
            "contacts/labels": self.contact_labels,
            "contacts/geometric": self.contact_geometric,
            "contacts/distance": self.contact_distance,
            "contacts/hand": self.hand_contact,
            "contacts/object": self.object_contact,
            "contacts/first_contact_frame": self.first_contact_frame,
            "contacts/window": self.contact_window,
            **self.optional,
        }
