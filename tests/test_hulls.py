"""Tests of wristmimic.convert.hulls: per-object parameters, coacd decomposition, cache, packing."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import coacd
import numpy as np
import pytest
import trimesh

from wristmimic.convert import hulls as H
from wristmimic.convert.hulls import (
    HullParams,
    HullSet,
    convex_decompose,
    default_cache_dir,
    hull_params_for,
    mesh_sha256,
    pack_hulls,
    unpack_hulls,
)
from wristmimic.errors import InputError


def voxel_solid(cells: list[tuple[int, int, int]], size: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward-wound surface of a union of unit voxels (shared vertices, watertight)."""
    occupied = set(cells)
    index: dict[tuple[int, int, int], int] = {}
    faces: list[tuple[int, int, int]] = []

    def vid(p: tuple[int, ...]) -> int:
        return index.setdefault(tuple(p), len(index))  # type: ignore[arg-type]

    for c in sorted(occupied):
        for axis in range(3):
            for sign in (1, -1):
                n = list(c)
                n[axis] += sign
                if tuple(n) in occupied:
                    continue
                u, w = (axis + 1) % 3, (axis + 2) % 3  # (u, w, axis) right-handed
                base = list(c)
                if sign > 0:
                    base[axis] += 1
                quad = []
                for du, dw in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = list(base)
                    p[u] += du
                    p[w] += dw
                    quad.append(vid(tuple(p)))
                a, b, cc, d = quad if sign > 0 else quad[::-1]
                faces += [(a, b, cc), (a, cc, d)]
    verts = np.array(sorted(index, key=index.get), dtype=np.float64) * size
    return verts, np.array(faces, dtype=np.int32)


U_CELLS = [(0, 0, 0), (0, 0, 1), (0, 0, 2), (1, 0, 0), (2, 0, 0), (2, 0, 1), (2, 0, 2)]


@pytest.fixture(scope="module")
def u_mesh() -> tuple[np.ndarray, np.ndarray]:
    v, f = voxel_solid(U_CELLS)
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.volume == pytest.approx(7e-3)
    return v, f


@pytest.fixture(scope="module")
def decomposed(u_mesh, tmp_path_factory) -> tuple[HullSet, Path]:
    cache = tmp_path_factory.mktemp("hull_cache")
    return convex_decompose(*u_mesh, HullParams(), cache), cache


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    ("name", "hulls"),
    [
        ("kettle", 80),
        ("Kettle", 80),
        ("cup", 80),
        ("whitecup", 80),
        ("chair", 50),
        ("woodchair", 50),
        ("whitechair", 50),
        ("deskchair", 50),
        ("cuttingboard", 10),
        ("cupboard", 10),
        ("largetable", 10),
        ("pan", 10),
    ],
)
def test_hull_params_for(name: str, hulls: int) -> None:
    assert hull_params_for(name).max_convex_hull == hulls


def test_hull_params_for_keeps_base_fields() -> None:
    base = HullParams(max_convex_hull=7, seed=3, threshold=0.1)
    assert hull_params_for("box", base) == base
    kettle = hull_params_for("kettle", base)
    assert (kettle.max_convex_hull, kettle.seed, kettle.threshold) == (80, 3, 0.1)


def test_hull_params_dict_round_trip_and_validation() -> None:
    p = HullParams(threshold=0.08, seed=5, preprocess_mode="on")
    assert HullParams.from_dict(p.to_dict()) == p
    assert set(p.to_dict()) == {f.name for f in dataclasses.fields(HullParams)}
    with pytest.raises(InputError, match="unknown"):
        HullParams.from_dict({**p.to_dict(), "bogus": 1})
    with pytest.raises(InputError, match="max_ch_vertex"):
        HullParams(max_ch_vertex=3)
    with pytest.raises(InputError, match="preprocess_mode"):
        HullParams(preprocess_mode="maybe")
    with pytest.raises(InputError, match="seed"):
        HullParams(seed=True)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="threshold"):
        HullParams(threshold="0.05")  # type: ignore[arg-type]
    # numpy scalars (e.g. read back from HDF5) become plain Python values: JSON-able, same cache key
    q = HullParams(seed=np.int64(5), threshold=np.float64(0.08), merge=np.bool_(True), preprocess_mode="on")
    assert q == p and type(q.seed) is int and type(q.merge) is bool
    assert json.dumps(q.to_dict()) == json.dumps(p.to_dict())


def test_mesh_sha256_and_default_cache_dir(u_mesh, monkeypatch, tmp_path) -> None:
    v, f = u_mesh
    assert mesh_sha256(v, f) == mesh_sha256(v.copy(), f.astype(np.int64))
    assert mesh_sha256(v, f) == mesh_sha256(np.asfortranarray(v), f)
    moved = v.copy()
    moved[0, 0] += 1e-9
    assert mesh_sha256(moved, f) != mesh_sha256(v, f)
    monkeypatch.setenv("WRISTMIMIC_CACHE_DIR", str(tmp_path))
    assert default_cache_dir() == tmp_path / "hulls"
    monkeypatch.delenv("WRISTMIMIC_CACHE_DIR")
    assert default_cache_dir() == Path.home() / ".cache" / "wristmimic" / "hulls"


# --------------------------------------------------------------------------- decomposition


def _assert_convex_outward(v: np.ndarray, f: np.ndarray) -> None:
    tri = v[f]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # every vertex lies on the inner side of every face plane
    side = np.einsum("fk,vk->fv", normal, v) - np.einsum("fk,fk->f", normal, tri[:, 0])[:, None]
    assert side.max() <= 1e-9 * max(1.0, float(np.abs(normal).max()))
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.volume > 0


def _inside_convex(v: np.ndarray, f: np.ndarray, point: np.ndarray) -> bool:
    tri = v[f]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return bool(np.all(np.einsum("fk,fk->f", normal, point[None] - tri[:, 0]) < 0))


def test_convex_decompose_small_mesh(u_mesh, decomposed) -> None:
    hs, _ = decomposed
    v, _ = u_mesh
    assert not hs.cache_hit
    assert hs.num_hulls >= 2
    lo, hi = v.min(axis=0) - 1e-3, v.max(axis=0) + 1e-3
    for hv, hf in zip(hs.vertices, hs.faces, strict=False):
        assert hv.dtype == np.float64 and hf.dtype == np.int32
        assert 4 <= len(hv) <= hs.params.max_ch_vertex
        assert np.all(hv >= lo) and np.all(hv <= hi)
        _assert_convex_outward(hv, hf)
    assert len(hs.cache_key) == 64 and hs.coacd_version
    # the pieces cover the U (volume within a factor ~1.5) but do not fill the notch between its arms
    total = sum(trimesh.Trimesh(hv, hf, process=False).volume for hv, hf in zip(hs.vertices, hs.faces, strict=False))
    assert 7e-3 * 0.95 <= total <= 7e-3 * 1.5
    notch = np.array([0.15, 0.05, 0.2])
    assert not any(_inside_convex(hv, hf, notch) for hv, hf in zip(hs.vertices, hs.faces, strict=False))


def test_cache_hit_skips_coacd(u_mesh, decomposed, monkeypatch) -> None:
    first, cache = decomposed
    assert (cache / f"{first.cache_key}.npz").is_file()

    def boom(*args, **kwargs):
        raise AssertionError("coacd must not run on a cache hit")

    monkeypatch.setattr(coacd, "run_coacd", boom)
    second = convex_decompose(*u_mesh, HullParams(), cache)
    assert second.cache_hit and second.cache_key == first.cache_key
    assert len(second.vertices) == len(first.vertices)
    for a, b in zip(first.vertices, second.vertices, strict=False):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(first.faces, second.faces, strict=False):
        np.testing.assert_array_equal(a, b)
    # without the cache coacd would run (and here fail)
    with pytest.raises(AssertionError, match="must not run"):
        convex_decompose(*u_mesh, HullParams(), cache, use_cache=False)


def test_deterministic_and_param_changes_key(u_mesh, decomposed) -> None:
    first, cache = decomposed
    again = convex_decompose(*u_mesh, HullParams(), cache, use_cache=False)
    assert not again.cache_hit and again.cache_key == first.cache_key
    for a, b in zip(first.vertices, again.vertices, strict=True):
        np.testing.assert_array_equal(a, b)
    other = convex_decompose(*u_mesh, HullParams(seed=1), cache)
    assert other.cache_key != first.cache_key and not other.cache_hit
    assert (cache / f"{other.cache_key}.npz").is_file()


def test_corrupt_cache_is_recomputed(u_mesh, decomposed, tmp_path) -> None:
    first, _ = decomposed
    path = tmp_path / f"{first.cache_key}.npz"
    path.write_bytes(b"not an npz file")
    redone = convex_decompose(*u_mesh, HullParams(), tmp_path)
    assert not redone.cache_hit
    for a, b in zip(first.vertices, redone.vertices, strict=True):
        np.testing.assert_array_equal(a, b)
    assert convex_decompose(*u_mesh, HullParams(), tmp_path).cache_hit  # overwritten with a good file
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary files left


def test_cache_with_bad_hull_is_recomputed(u_mesh, decomposed, tmp_path) -> None:
    first, _ = decomposed
    bad = dataclasses.replace(first, vertices=[np.full((5, 3), np.nan)] + first.vertices[1:])
    H._write_cache(
        tmp_path / f"{first.cache_key}.npz",
        first.cache_key,
        first.mesh_sha256,
        first.params,
        first.coacd_version,
        bad,
    )
    redone = convex_decompose(*u_mesh, HullParams(), tmp_path)
    assert not redone.cache_hit and np.isfinite(redone.vertices[0]).all()


def test_oversized_hull_is_reduced(u_mesh, monkeypatch, tmp_path) -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)  # 642 vertices
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)  # degenerate: dropped
    parts = [
        [np.array(sphere.vertices), np.array(sphere.faces, np.int32)],
        [np.array(box.vertices), np.array(box.faces, np.int32)],
        [flat, np.array([[0, 1, 2], [1, 3, 2]], np.int32)],
    ]
    monkeypatch.setattr(coacd, "run_coacd", lambda *a, **k: parts)
    params = HullParams(max_ch_vertex=32)
    hs = convex_decompose(*u_mesh, params, tmp_path)
    assert hs.num_hulls == 2
    assert len(hs.vertices[0]) == 32 and len(hs.vertices[1]) == 8
    # reduced hull vertices are a subset of the original points
    d = np.linalg.norm(hs.vertices[0][:, None] - sphere.vertices[None], axis=2).min(axis=1)
    assert d.max() == 0.0
    for hv, hf in zip(hs.vertices, hs.faces, strict=False):
        _assert_convex_outward(hv, hf)
    assert trimesh.Trimesh(hs.vertices[0], hs.faces[0]).volume > 0.8 * sphere.volume


def test_no_valid_hull_raises(u_mesh, monkeypatch, tmp_path) -> None:
    monkeypatch.setattr(coacd, "run_coacd", lambda *a, **k: [])
    with pytest.raises(InputError, match="no non-degenerate"):
        convex_decompose(*u_mesh, HullParams(), tmp_path)


def test_bad_input_mesh_raises(u_mesh, tmp_path) -> None:
    v, f = u_mesh
    with pytest.raises(InputError, match="faces"):
        convex_decompose(v, f + len(v), HullParams(), tmp_path)
    bad = v.copy()
    bad[0, 0] = np.inf
    with pytest.raises(InputError, match="non-finite"):
        convex_decompose(bad, f, HullParams(), tmp_path)


# --------------------------------------------------------------------------- packing


def test_pack_unpack_round_trip(decomposed) -> None:
    hs, _ = decomposed
    verts, faces, vo, fo = pack_hulls(hs)
    assert verts.dtype == np.float32 and faces.dtype == np.int32
    assert vo.dtype == np.int64 and fo.dtype == np.int64
    assert len(vo) == len(fo) == hs.num_hulls + 1
    assert vo[-1] == len(verts) and fo[-1] == len(faces)
    back_v, back_f = unpack_hulls(verts, faces, vo, fo)
    assert len(back_v) == hs.num_hulls
    for a, b in zip(hs.vertices, back_v, strict=False):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-7)
    for a, b in zip(hs.faces, back_f, strict=False):
        np.testing.assert_array_equal(a, b)
    bad_vo = vo.copy()
    bad_vo[1] = bad_vo[2] + 1
    with pytest.raises(InputError, match="vertex_offsets"):
        unpack_hulls(verts, faces, bad_vo, fo)
    with pytest.raises(InputError, match="faces"):
        unpack_hulls(verts, faces + 1000, vo, fo)
