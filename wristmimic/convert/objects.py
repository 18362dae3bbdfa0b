"""Objects of an HOI dataset: URDF properties, the OBJ mesh, mass properties and surface samples.

Two folder layouts are supported:

- OMOMO / InterMimic: ``objects/<name>.urdf`` + ``objects/<name>/<name>.obj``; the URDF names the mesh
  relative to the *parent* of ``objects`` (``filename="objects/<name>/<name>.obj"``).
- SkillMimic ParaHome: ``objects/<name>.urdf`` + ``objects/<name>.obj``; the URDF names the mesh relative
  to its own folder (``filename="<name>.obj"``).

An OBJ without a URDF is accepted. Vertices are kept exactly as in the OBJ (object-local frame, metres, no
re-centring, no merging or reordering); only a URDF mesh ``scale`` other than 1 is applied.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import re
import sys
import warnings
import xml.etree.ElementTree as ET
import xml.parsers.expat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from wristmimic.errors import InputError

MASS_METHODS = ("visual_mesh", "visual_mesh_repaired", "visual_mesh_open", "convex_hull")
_REL_TOL = 1e-9
_FRICTION_TAGS = ("lateral_friction", "rolling_friction", "spinning_friction")
_DTD = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


@dataclass
class ObjectAsset:
    """One object: mesh in its local frame, URDF properties, mass properties and surface samples."""

    name: str
    vertices: np.ndarray  # float64 (V,3), object-local frame, metres, as in the OBJ (URDF scale applied)
    faces: np.ndarray  # int32 (F,3)
    mesh_path: Path
    urdf_path: Path | None
    mesh_sha256: str  # sha256 of the mesh FILE bytes
    urdf: dict  # numeric URDF properties, see read_urdf
    density: float  # kg/m^3 used for mass
    mass: float  # kg
    com: np.ndarray  # (3,) object-local
    inertia: np.ndarray  # (3,3) about the COM, object-local axes
    mass_method: str  # one of MASS_METHODS, see mass_properties
    watertight: bool  # of the visual mesh as loaded
    surface_points: np.ndarray  # float32 (n_surface, 3), object-local
    surface_seed: int


# --------------------------------------------------------------------------- URDF


def _float(path: Path, key: str, text: str | None) -> float:
    try:
        value = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(path, key, f"not a number: {text!r}", "a finite number") from None
    if not np.isfinite(value):
        raise InputError(path, key, f"not finite: {text!r}", "a finite number")
    return value


def _floats(path: Path, key: str, text: str | None, n: int) -> list[float]:
    parts = (text or "").split()
    if len(parts) != n:
        raise InputError(path, key, f"{text!r} has {len(parts)} numbers", f"{n} numbers")
    return [_float(path, key, p) for p in parts]


class _DoctypeFound(Exception):
    pass


def _has_doctype(data: bytes) -> bool:
    """True if expat sees a DOCTYPE or ENTITY declaration (catches encodings the byte regex misses)."""

    def found(*_: object) -> None:
        raise _DoctypeFound

    parser = xml.parsers.expat.ParserCreate()
    parser.StartDoctypeDeclHandler = found
    parser.EntityDeclHandler = found
    try:
        parser.Parse(data, True)
    except _DoctypeFound:
        return True
    except xml.parsers.expat.ExpatError:
        return False  # malformed: reported by the real parse
    return False


def _parse_xml(path: Path) -> ET.Element:
    """Root <robot> element; rejects DOCTYPE/ENTITY declarations (entity expansion) and malformed XML."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise InputError(path, None, f"cannot read URDF: {e.strerror or e}") from None
    if _DTD.search(data) or _has_doctype(data):
        raise InputError(path, "DOCTYPE", "DOCTYPE/ENTITY declarations are not allowed", "plain URDF XML")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise InputError(path, "xml", f"malformed XML: {e}", "well-formed URDF") from None
    if root.tag != "robot":
        raise InputError(path, "robot", f"root element is <{root.tag}>", "<robot>")
    return root


def _mesh_elements(root: ET.Element) -> tuple[ET.Element | None, list[ET.Element]]:
    """(link holding the first mesh, that link's mesh elements: visual ones first, then collision)."""
    for link in root.iter("link"):
        meshes = link.findall("visual/geometry/mesh") + link.findall("collision/geometry/mesh")
        if meshes:
            return link, meshes
    return None, []


def _urdf_properties(path: Path, root: ET.Element, link: ET.Element | None, mesh: ET.Element | None) -> dict:
    props: dict[str, Any] = {}
    # <dynamics> may sit under <robot> (InterMimic) or under a <joint>; the first one wins.
    dyn = root.find(".//dynamics")
    if dyn is not None:
        for attr in ("damping", "friction"):
            if dyn.get(attr) is not None:
                props[f"dynamics_{attr}"] = _float(path, f"dynamics.{attr}", dyn.get(attr))
    if link is not None:
        contact = link.find("contact")
        if contact is not None:
            for child in contact:
                if child.get("value") is None:
                    continue
                key = child.tag if child.tag in _FRICTION_TAGS else f"contact_{child.tag}"
                props[key] = _float(path, f"contact.{child.tag}", child.get("value"))
        inertial = link.find("inertial")
        if inertial is not None:
            m = inertial.find("mass")
            if m is not None and m.get("value") is not None:
                props["inertial_mass"] = _float(path, "inertial.mass", m.get("value"))
            origin = inertial.find("origin")
            if origin is not None:
                for attr in ("xyz", "rpy"):
                    if origin.get(attr) is not None:
                        props[f"inertial_origin_{attr}"] = _floats(path, f"inertial.origin.{attr}", origin.get(attr), 3)
            inertia = inertial.find("inertia")
            if inertia is not None:
                names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
                if all(inertia.get(n) is not None for n in names):
                    props["inertial_inertia"] = [_float(path, f"inertial.inertia.{n}", inertia.get(n)) for n in names]
        visual_origin = link.find("visual/origin")
        if visual_origin is not None:
            for attr in ("xyz", "rpy"):
                if visual_origin.get(attr) is not None:
                    props[f"visual_origin_{attr}"] = _floats(path, f"visual.origin.{attr}", visual_origin.get(attr), 3)
    if mesh is not None and mesh.get("scale") is not None:
        scale = mesh.get("scale", "").split()
        if len(scale) == 1:
            scale = scale * 3
        props["mesh_scale"] = _floats(path, "mesh.scale", " ".join(scale), 3)
    return props


def _strip_uri(filename: str) -> str:
    if filename.startswith("file://"):
        return filename[len("file://") :]
    if filename.startswith("package://"):
        rest = filename[len("package://") :]
        return rest.split("/", 1)[1] if "/" in rest else rest
    return filename


def _layout_candidates(objects_dir: Path, name: str) -> list[Path]:
    return [objects_dir / name / f"{name}.obj", objects_dir / f"{name}.obj"]


def _unique(paths: list[Path]) -> list[Path]:
    out: list[Path] = []
    for p in paths:
        if p not in out:
            out.append(p)
    return out


_FALLBACKS_SHOWN: set[tuple[Path, Path]] = set()


def _warn_fallback(urdf_path: Path, meshes: list[ET.Element], used: Path) -> None:
    """One ``warning:`` line on stderr (once per URDF and process) when the URDF's own mesh files are missing."""
    key = (urdf_path.resolve(), used.resolve())
    if key in _FALLBACKS_SHOWN:
        return
    _FALLBACKS_SHOWN.add(key)
    names = ", ".join(dict.fromkeys(str(m.get("filename")) for m in meshes if m.get("filename")))
    print(f"warning: {urdf_path}: mesh: {names} not found; using {used}", file=sys.stderr, flush=True)


def read_urdf(urdf_path: Path, *, warn: bool = True) -> tuple[Path, dict]:
    """Parse a URDF: (resolved mesh path, numeric properties).

    The mesh is the first ``<mesh filename=...>`` of the first link that has one (visual before collision);
    each filename is tried relative to the URDF's folder, then its parent; then the layouts
    ``<dir>/<stem>/<stem>.obj`` and ``<dir>/<stem>.obj`` (``<stem>`` = URDF file name without suffix). When
    the URDF names meshes and none of them exists, the layout's file is used with one ``warning:`` line on stderr
    if ``warn`` (SkillMimic's ``pot.urdf`` names ParaHome's ``pot/base_visual.obj``; the release ships ``pot.obj``).

    Property keys (present only when the URDF states them; floats unless noted):
    ``lateral_friction``, ``rolling_friction``, ``spinning_friction`` and ``contact_<tag>`` for any other
    ``<contact><tag value=.../>`` of the link (``contact_stiffness``, ``contact_damping``,
    ``contact_restitution`` ...); ``dynamics_damping``, ``dynamics_friction`` (first ``<dynamics>``);
    ``inertial_mass``; ``inertial_origin_xyz``, ``inertial_origin_rpy`` (3 floats);
    ``inertial_inertia`` ([ixx, ixy, ixz, iyy, iyz, izz]); ``visual_origin_xyz``, ``visual_origin_rpy``
    (3 floats; recorded, not applied); ``mesh_scale`` (3 floats).

    Raises InputError (naming the file) for unreadable or malformed XML, DOCTYPE/ENTITY declarations,
    non-numeric values, and when no mesh file can be found.
    """
    urdf_path = Path(urdf_path)
    root = _parse_xml(urdf_path)
    link, meshes = _mesh_elements(root)
    props = _urdf_properties(urdf_path, root, link, meshes[0] if meshes else None)
    tried: list[Path] = []
    for mesh in meshes:
        filename = mesh.get("filename")
        if not filename:
            continue
        rel = Path(_strip_uri(filename))
        if rel.is_absolute():
            tried.append(rel)
        else:
            tried += [urdf_path.parent / rel, urdf_path.parent.parent / rel]
    named = _unique(tried)
    tried = _unique([*named, *_layout_candidates(urdf_path.parent, urdf_path.stem)])
    for candidate in tried:
        if candidate.is_file():
            if warn and named and candidate not in named:
                _warn_fallback(urdf_path, meshes, candidate)  # the URDF names files that are not there
            return candidate, props
    raise InputError(
        urdf_path, "mesh", f"no mesh file found; tried {', '.join(str(p) for p in tried)}", "an existing OBJ"
    )


def _check_name(objects_dir: Path, name: str) -> None:
    if not name or name in (".", "..") or "/" in name or "\\" in name or "\x00" in name:
        raise InputError(objects_dir, "name", f"invalid object name {name!r}", "a plain file stem")


def find_object_files(objects_dir: Path, name: str, *, warn: bool = True) -> tuple[Path | None, Path]:
    """(URDF path or None, mesh path) of object ``name`` in ``objects_dir`` (either layout); ``warn``: as
    :func:`read_urdf`."""
    objects_dir = Path(objects_dir)
    _check_name(objects_dir, name)
    urdf = objects_dir / f"{name}.urdf"
    if urdf.is_file():
        return urdf, read_urdf(urdf, warn=warn)[0]
    tried = _layout_candidates(objects_dir, name)
    for candidate in tried:
        if candidate.is_file():
            return None, candidate
    raise InputError(
        objects_dir,
        name,
        f"no mesh for object {name!r} in {objects_dir}; tried {', '.join(str(p) for p in [urdf, *tried])}",
        "<name>.urdf, <name>/<name>.obj or <name>.obj",
    )


def list_objects(objects_dir: Path) -> list[str]:
    """Sorted names of the objects in ``objects_dir`` for which a mesh can be found."""
    objects_dir = Path(objects_dir)
    if not objects_dir.is_dir():
        return []
    names = {p.stem for p in objects_dir.glob("*.urdf")} | {p.stem for p in objects_dir.glob("*.obj")}
    names |= {d.name for d in objects_dir.iterdir() if d.is_dir() and (d / f"{d.name}.obj").is_file()}
    found = []
    for name in sorted(names):
        try:
            find_object_files(objects_dir, name, warn=False)  # listing only: warn when an object is loaded
        except InputError:
            continue
        found.append(name)
    return found


# --------------------------------------------------------------------------- mesh


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Silence trimesh's log messages and numpy warnings (this module prints only the mesh fallback warning)."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with np.errstate(all="ignore"):
                yield
    finally:
        logger.setLevel(level)


def load_obj(mesh_path: Path, scale: list[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V,3) float64 and faces (F,3) int32 of an OBJ, in file order, ``scale`` applied."""
    mesh_path = Path(mesh_path)
    try:
        with _quiet():
            mesh = trimesh.load(mesh_path, force="mesh", process=False, maintain_order=True, skip_materials=True)
    except Exception as e:  # noqa: BLE001 - trimesh raises many types for bad files
        raise InputError(mesh_path, "mesh", f"cannot load mesh: {type(e).__name__}: {e}", "a triangle OBJ") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    if len(vertices) == 0 or faces.size == 0:
        raise InputError(mesh_path, "mesh", "empty mesh (no vertices or no faces)", "a non-empty triangle mesh")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError(mesh_path, "faces", f"shape {faces.shape}", "(F, 3) triangles")
    if not np.isfinite(vertices).all():
        raise InputError(mesh_path, "vertices", "non-finite coordinates", "finite numbers")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(mesh_path, "faces", f"vertex index out of range [0, {len(vertices)})", "valid indices")
    if scale is not None:
        s = np.asarray(scale, dtype=np.float64)
        if s.shape != (3,) or not np.isfinite(s).all() or np.any(s == 0):
            raise InputError(mesh_path, "mesh.scale", f"invalid scale {scale}", "3 finite non-zero numbers")
        if not np.all(s == 1.0):
            vertices = vertices * s
            if np.prod(s) < 0:  # a mirroring scale flips the winding
                faces = faces[:, ::-1]
    return np.ascontiguousarray(vertices), np.ascontiguousarray(faces, dtype=np.int32)


def _valid_inertia(mass: float, inertia: np.ndarray) -> np.ndarray | None:
    """Symmetrised inertia if mass > 0 finite and inertia symmetric PSD with principal moments obeying the
    triangle inequality (relative tolerance 1e-9); else None."""
    if not (np.isfinite(mass) and mass > 0):
        return None
    inertia = np.asarray(inertia, dtype=np.float64)
    if inertia.shape != (3, 3) or not np.isfinite(inertia).all():
        return None
    scale = float(np.abs(inertia).max())
    if scale <= 0 or np.abs(inertia - inertia.T).max() > _REL_TOL * scale:
        return None
    inertia = 0.5 * (inertia + inertia.T)
    p = np.sort(np.linalg.eigvalsh(inertia))
    tol = _REL_TOL * p[-1]
    if p[0] < -tol or p[0] + p[1] < p[2] - tol:
        return None
    return inertia


def _mass_of(mesh: trimesh.Trimesh, density: float) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(mass, com, inertia about com) by the divergence theorem over ``mesh``'s triangles, or None."""
    if len(mesh.faces) == 0:
        return None
    with _quiet():
        mp = trimesh.triangles.mass_properties(mesh.triangles, density=density)
    mass = float(mp["mass"])
    com = np.asarray(mp["center_mass"], dtype=np.float64)
    if not np.isfinite(com).all():
        return None
    inertia = _valid_inertia(mass, mp["inertia"])
    if inertia is None:
        return None
    return mass, com, inertia


def _repaired(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Copy with merged vertices, no degenerate/duplicate faces, consistent outward winding, holes filled."""
    with _quiet():
        r = mesh.copy()
        r.merge_vertices()
        r.update_faces(r.nondegenerate_faces())
        r.update_faces(r.unique_faces())
        r.remove_unreferenced_vertices()
        trimesh.repair.fix_normals(r)
        trimesh.repair.fill_holes(r)
    return r


def mass_properties(
    vertices: np.ndarray, faces: np.ndarray, density: float
) -> tuple[float, np.ndarray, np.ndarray, str, bool]:
    """(mass, com, inertia about com, method, watertight) of a mesh of uniform ``density``.

    Methods, tried in order; each result must have finite mass > 0 and a symmetric PSD inertia whose
    principal moments satisfy the triangle inequality (relative tolerance 1e-9), else the next is tried:

    - ``visual_mesh``: the mesh as loaded, when it is watertight;
    - ``visual_mesh_repaired``: a repaired copy (vertices merged, degenerate/duplicate faces removed,
      winding made consistent and outward, holes filled), when that copy is watertight;
    - ``visual_mesh_open``: the unrepaired mesh although it is open, when its winding is consistent and its
      divergence-theorem volume is positive (approximate: the missing surface is ignored);
    - ``convex_hull``: the convex hull of the referenced vertices (overestimates non-convex objects).

    Raises InputError (key ``mass``) when none of them gives valid properties (e.g. a flat mesh).
    """
    if not (np.isfinite(density) and density > 0):
        raise InputError(None, "density", f"invalid density {density}", "a finite number > 0 (kg/m^3)")
    with _quiet():
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
        watertight = bool(mesh.is_watertight)
    if watertight:
        result = _mass_of(mesh, density)
        if result is not None:
            return (*result, "visual_mesh", watertight)
    repaired = _repaired(mesh)
    with _quiet():
        repaired_ok = bool(repaired.is_watertight)
    if repaired_ok:
        result = _mass_of(repaired, density)
        if result is not None:
            return (*result, "visual_mesh_repaired", watertight)
    with _quiet():
        open_ok = bool(mesh.is_winding_consistent)
    if open_ok:
        result = _mass_of(mesh, density)
        if result is not None and result[0] > 0:
            return (*result, "visual_mesh_open", watertight)
    try:
        with _quiet():
            used = np.unique(np.asarray(faces).ravel())
            hull = trimesh.convex.convex_hull(np.asarray(vertices)[used])
        result = _mass_of(hull, density)
    except Exception:  # noqa: BLE001 - qhull fails on flat/degenerate point sets
        result = None
    if result is not None:
        return (*result, "convex_hull", watertight)
    raise InputError(None, "mass", "no valid mass properties (mesh flat or degenerate)", "a solid mesh")


def sample_surface_points(vertices: np.ndarray, faces: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Exactly ``n`` float32 points on the mesh surface, deterministic for ``seed``.

    ``trimesh.sample.sample_surface_even(seed=seed)`` first; if it returns fewer points the rest come from
    ``trimesh.sample.sample_surface(seed=seed + 1)``.
    """
    if n < 1:
        raise InputError(None, "n_surface", f"invalid count {n}", ">= 1")
    with _quiet():
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
        area = float(mesh.area)
    if not (np.isfinite(area) and area > 0):
        raise InputError(None, "surface", f"mesh surface area is {area}", "a positive area")
    with _quiet():
        points, _ = trimesh.sample.sample_surface_even(mesh, n, seed=seed)
        points = np.asarray(points)[:n]
        if len(points) < n:
            extra, _ = trimesh.sample.sample_surface(mesh, n - len(points), seed=seed + 1)
            points = np.concatenate([points.reshape(-1, 3), extra])
    return np.ascontiguousarray(points, dtype=np.float32)


def load_object(
    name: str,
    objects_dir: Path,
    *,
    density: float = 1000.0,
    n_surface: int = 1024,
    surface_seed: int = 2024,
) -> ObjectAsset:
    """Load object ``name`` from ``objects_dir``: mesh, URDF properties, mass properties, surface samples.

    Mass, COM and inertia come from :func:`mass_properties` with ``density``; ``mass_method`` tells which
    method was used. Where the URDF gives ``<inertial><mass>``, that mass wins and the inertia is scaled to
    it (``mass_method`` gets ``+urdf_mass``). ``surface_points`` are :func:`sample_surface_points` of the visual mesh.
    """
    objects_dir = Path(objects_dir)
    urdf_path, mesh_path = find_object_files(objects_dir, name)
    props: dict[str, Any] = {}
    if urdf_path is not None:
        _, props = read_urdf(urdf_path, warn=False)  # find_object_files has warned
    return asset_from_mesh(name, mesh_path, urdf_path, props, density, n_surface, surface_seed)


def asset_from_mesh(
    name: str,
    mesh_path: Path,
    urdf_path: Path | None,
    props: dict[str, Any],
    density: float,
    n_surface: int,
    surface_seed: int,
) -> ObjectAsset:
    """An :class:`ObjectAsset` from a mesh file and its URDF properties ``props`` (``mesh_scale``,
    ``inertial_mass``; empty for a bare mesh): mass properties, surface samples, the URDF mass if stated."""
    vertices, faces = load_obj(mesh_path, props.get("mesh_scale"))
    try:
        mesh_hash = hashlib.sha256(mesh_path.read_bytes()).hexdigest()
    except OSError as e:
        raise InputError(mesh_path, "mesh", f"cannot read: {e.strerror or e}") from None
    try:
        mass, com, inertia, method, watertight = mass_properties(vertices, faces, density)
        points = sample_surface_points(vertices, faces, n_surface, surface_seed)
    except InputError as e:
        raise InputError(mesh_path, e.key, e.problem, e.expected) from None
    urdf_mass = props.get("inertial_mass")
    if urdf_mass is not None and np.isfinite(urdf_mass) and urdf_mass > 0:
        # the URDF states the mass: keep the geometry's COM and inertia shape, scaled to that mass
        inertia = inertia * (float(urdf_mass) / mass)
        mass = float(urdf_mass)
        method = f"{method}+urdf_mass"
    return ObjectAsset(
        name=name,
        vertices=vertices,
        faces=faces,
        mesh_path=mesh_path,
        urdf_path=urdf_path,
        mesh_sha256=mesh_hash,
        urdf=props,
        density=float(density),
        mass=mass,
        com=com,
        inertia=inertia,
        mass_method=method,
        watertight=watertight,
        surface_points=points,
        surface_seed=surface_seed,
    )
