"""The restricted unpickler: numpy + builtin containers load, anything else is refused before it runs."""

from __future__ import annotations

import gzip
import os
import pickle
from pathlib import Path

import numpy as np
import pytest
from synthetic_raw import joblib_like_bytes

from wristmimic.errors import InputError
from wristmimic.safe_io import safe_npz_load, safe_pickle_load


class _Evil:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


class _Custom:
    pass


def _payload() -> dict:
    return {
        "body": {"pHipOrigin": {"jL5S1": np.array([0.1, 0.0, 0.2])}},
        "f32": np.arange(12, dtype=np.float32).reshape(3, 4),
        "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
        "scalar": np.float64(2.5),
        "ints": [1, 2, (3, 4.0)],
        "set": {1, 2},
        "name": "sub3_largetable_012",
        "big_endian": np.arange(3, dtype=">f8"),
    }


def _check(obj: dict) -> None:
    ref = _payload()
    np.testing.assert_array_equal(obj["body"]["pHipOrigin"]["jL5S1"], ref["body"]["pHipOrigin"]["jL5S1"])
    np.testing.assert_array_equal(obj["f32"], ref["f32"])
    assert obj["f32"].dtype == np.float32
    np.testing.assert_array_equal(obj["fortran"], ref["fortran"])
    np.testing.assert_array_equal(obj["big_endian"], [0.0, 1.0, 2.0])
    assert obj["scalar"] == 2.5 and obj["ints"] == [1, 2, (3, 4.0)] and obj["set"] == {1, 2}
    assert obj["name"] == "sub3_largetable_012"


@pytest.mark.parametrize("protocol", [2, 3, 4, 5])
def test_plain_pickles_of_numpy_and_containers_load(tmp_path: Path, protocol: int) -> None:
    p = tmp_path / "ok.pkl"
    p.write_bytes(pickle.dumps(_payload(), protocol=protocol))
    _check(safe_pickle_load(p))


def test_os_system_is_refused_and_nothing_runs(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    p = tmp_path / "evil.pkl"
    p.write_bytes(pickle.dumps({"a": np.zeros(3), "b": _Evil(marker)}))
    with pytest.raises(InputError) as e:
        safe_pickle_load(p)
    msg = str(e.value)
    assert str(p) in msg and "refused global" in msg and ("posix.system" in msg or "os.system" in msg)
    assert not marker.exists()


def test_other_classes_and_builtins_are_refused(tmp_path: Path) -> None:
    p = tmp_path / "cls.pkl"
    p.write_bytes(pickle.dumps(_Custom()))
    with pytest.raises(InputError, match="refused global"):
        safe_pickle_load(p)
    q = tmp_path / "getattr.pkl"  # builtins.getattr / eval are not on the list
    q.write_bytes(b"\x80\x04cbuiltins\neval\n(S'1+1'\ntR.")
    with pytest.raises(InputError, match="refused global builtins.eval"):
        safe_pickle_load(q)


def test_truncated_and_garbage_files_fail_cleanly(tmp_path: Path) -> None:
    good = pickle.dumps(_payload())
    p = tmp_path / "cut.pkl"
    p.write_bytes(good[: len(good) // 2])
    with pytest.raises(InputError, match="cannot be unpickled"):
        safe_pickle_load(p)
    with pytest.raises(InputError, match="file not found"):
        safe_pickle_load(tmp_path / "missing.pkl")


# --- joblib's format, written the way joblib.dump lays it out (joblib itself is not a dependency) --------


@pytest.mark.parametrize("align", [True, False])
def test_joblib_files_load_without_joblib(tmp_path: Path, align: bool) -> None:
    data = {0: {**_payload(), "labels": np.array(["a", {"k": 1}], dtype=object)}}
    raw = joblib_like_bytes(data, align)
    with pytest.raises((pickle.UnpicklingError, ImportError)):  # not a plain pickle: needs joblib
        pickle.loads(raw)
    p = tmp_path / "seq.p"
    p.write_bytes(raw)
    out = safe_pickle_load(p)
    _check(out[0])
    assert list(out[0]["labels"]) == ["a", {"k": 1}]
    gz = tmp_path / "seq.p.gz"
    gz.write_bytes(gzip.compress(raw))
    _check(safe_pickle_load(gz)[0])


def test_joblib_array_bigger_than_the_file_is_refused(tmp_path: Path) -> None:
    raw = joblib_like_bytes({"a": np.zeros(1000)}, True)
    p = tmp_path / "cut.p"
    p.write_bytes(raw[: len(raw) - 4000])
    with pytest.raises(InputError, match="joblib array"):
        safe_pickle_load(p)


def test_lz4_joblib_is_refused_with_the_reason(tmp_path: Path) -> None:
    p = tmp_path / "x.p"
    p.write_bytes(b"\x04\x22\x4d\x18rest")
    with pytest.raises(InputError, match="lz4"):
        safe_pickle_load(p)


def test_npz_with_pickled_objects(tmp_path: Path) -> None:
    ok = tmp_path / "ok.npz"
    np.savez(ok, a=np.arange(4.0), meta=np.array({"joint2num": {"pelvis": 0}}, dtype=object))
    d = safe_npz_load(ok)
    np.testing.assert_array_equal(d["a"], np.arange(4.0))
    assert d["meta"].item() == {"joint2num": {"pelvis": 0}}
    bad = tmp_path / "bad.npz"
    marker = tmp_path / "pwned"
    np.savez(bad, a=np.array([_Evil(marker)], dtype=object))
    with pytest.raises(InputError, match="refused global"):
        safe_npz_load(bad)
    assert not marker.exists()
