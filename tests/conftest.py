"""Shared fixtures: the real data beside the checkout (skipped with a reason when absent) and converted files."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("WRISTMIMIC_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_path(*parts: str) -> Path:
    """A path under the shared data folder; skips the test, saying why, when it is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared data not found at {p} (set WRISTMIMIC_SHARED_DATA to the shared/data folder)")
    return p


@pytest.fixture(scope="session")
def hull_cache() -> Path | None:
    """coacd cache for real meshes: $WRISTMIMIC_CACHE_DIR/hulls or the user cache (results are keyed by mesh,
    parameters and coacd version, so sharing it between runs is safe)."""
    return None


@pytest.fixture(scope="session")
def omomo_h5(tmp_path_factory: pytest.TempPathFactory, hull_cache: Path | None) -> Path:
    """All shared InterMimic OMOMO sequences converted once per test session."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    src = shared_path("intermimic_omomo")
    out = tmp_path_factory.mktemp("omomo") / "omomo.h5"
    convert_intermimic(src, out, options=ConvertOptions(hull_cache_dir=hull_cache, show_progress=False))
    return out


@pytest.fixture(scope="session")
def parahome_h5(tmp_path_factory: pytest.TempPathFactory, hull_cache: Path | None) -> Path:
    """All shared SkillMimic ParaHome clips converted once per test session."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome

    src = shared_path("skillmimic_parahome")
    out = tmp_path_factory.mktemp("parahome") / "parahome.h5"
    convert_skillmimic_parahome(src, out, options=ConvertOptions(hull_cache_dir=hull_cache, show_progress=False))
    return out


def temporaries(folder: Path) -> list[Path]:
    """Every ``*.tmp`` file under ``folder`` (what an atomic write leaves when it is interrupted)."""
    return sorted(p for p in folder.rglob("*") if p.name.endswith(".tmp"))


def same_h5(a: Path, b: Path) -> None:
    """Assert every dataset and attribute of two HDF5 files equal, apart from the creation time."""
    import h5py
    import numpy as np

    def walk(g: h5py.Group, out: dict, pre: str = "") -> dict:
        for k, v in g.attrs.items():
            out[f"{pre}@{k}"] = v
        for k, v in g.items():
            if isinstance(v, h5py.Group):
                walk(v, out, f"{pre}{k}/")
            else:
                out[pre + k] = v[()]
        return out

    with h5py.File(a) as fa, h5py.File(b) as fb:
        da, db = walk(fa, {}), walk(fb, {})
    assert da.keys() == db.keys()
    assert [k for k in da if k != "@created_utc" and not np.array_equal(np.asarray(da[k]), np.asarray(db[k]))] == []
