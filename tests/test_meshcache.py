"""woundsweep.mesh.cache: reuse, validation, rebuild of damaged or stale files, atomic writes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import woundsweep.mesh.cache as meshcache
from woundsweep.config.geometry import GeometrySpec
from woundsweep.core.errors import GeometryError, StoreError
from woundsweep.mesh.build import MeshData, build_mesh
from woundsweep.mesh.cache import get_mesh, load_mesh, mesh_path, save_mesh

GID = "0123456789abcdef"
SPEC = GeometrySpec.cylindrical(1.0, 1.0, 1.5, 1.0, 0.2, 0.3)
ARRAYS = ("points", "cells", "cell_tags", "facets", "facet_tags")


@pytest.fixture(scope="module")
def reference() -> MeshData:
    return build_mesh(SPEC)


def same(a: MeshData, b: MeshData) -> bool:
    return all(
        np.array_equal(getattr(a, f), getattr(b, f)) and getattr(a, f).dtype == getattr(b, f).dtype
        for f in ARRAYS
    )


def no_build(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(spec: GeometrySpec) -> MeshData:
        raise AssertionError("build_mesh called although a valid cached mesh exists")

    monkeypatch.setattr(meshcache, "build_mesh", fail)


def test_build_then_reuse(tmp_path: Path, reference: MeshData, monkeypatch) -> None:
    first = get_mesh(tmp_path, GID, SPEC)
    assert first.status == "built" and first.path == tmp_path / "meshes" / f"{GID}.npz"
    assert first.path.is_file() and same(first.mesh, reference)
    no_build(monkeypatch)
    second = get_mesh(tmp_path, GID, SPEC)
    assert second.status == "cached" and second.reason == ""
    assert same(second.mesh, reference)
    assert second.mesh.info["cells"] == reference.info["cells"]
    # only the final file, no temporary left behind
    assert sorted(p.name for p in (tmp_path / "meshes").iterdir()) == [f"{GID}.npz"]


def _damage_truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _damage_flip_middle(path: Path) -> None:
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 8] = bytes(b ^ 0xFF for b in data[mid : mid + 8])
    path.write_bytes(bytes(data))


def _damage_empty(path: Path) -> None:
    path.write_bytes(b"")


def _damage_arrays_keep_checksum(path: Path) -> None:
    # A well-formed npz whose arrays do not match the stored checksum.
    with np.load(path) as npz:
        content = {k: npz[k] for k in npz.files}
    content["points"] = content["points"].copy()
    content["points"][0, 0] += 1e-3
    with open(path, "wb") as fh:
        np.savez(fh, **content)


def _damage_index_out_of_range(path: Path) -> None:
    with np.load(path) as npz:
        content = {k: npz[k] for k in npz.files}
    content["cells"] = content["cells"].copy()
    content["cells"][0, 0] = len(content["points"]) + 5
    with open(path, "wb") as fh:
        np.savez(fh, **content)


def _damage_wrong_dtype(path: Path) -> None:
    with np.load(path) as npz:
        content = {k: npz[k] for k in npz.files}
    content["cell_tags"] = content["cell_tags"].astype(np.float64)
    with open(path, "wb") as fh:
        np.savez(fh, **content)


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (_damage_truncate, "unreadable"),
        (_damage_flip_middle, "unreadable|checksum mismatch"),  # zip CRC or our checksum
        (_damage_empty, "unreadable"),
        (_damage_arrays_keep_checksum, "checksum mismatch"),
        (_damage_index_out_of_range, "missing nodes"),
        (_damage_wrong_dtype, "cell_tags has dtype float64"),
    ],
)
def test_damaged_cache_file_is_detected_and_rebuilt(
    tmp_path: Path, reference: MeshData, damage, reason: str
) -> None:
    path = get_mesh(tmp_path, GID, SPEC).path
    damage(path)
    with pytest.raises(StoreError, match=reason):
        load_mesh(path, SPEC, GID)
    again = get_mesh(tmp_path, GID, SPEC)
    assert again.status == "rebuilt" and re.search(reason, again.reason)
    assert same(again.mesh, reference)
    assert same(load_mesh(path, SPEC, GID), reference)  # the replacement file is valid


def test_stale_parameters_or_law_version_rebuild(tmp_path: Path, monkeypatch) -> None:
    path = get_mesh(tmp_path, GID, SPEC).path
    other = GeometrySpec.cylindrical(1.0, 1.0, 1.5, 1.0, 0.1, 0.3)
    got = get_mesh(tmp_path, GID, other)
    assert got.status == "rebuilt" and "other geometric parameters" in got.reason
    assert json.loads(np.load(path)["meta"].tobytes())["spec"]["wound_aspect_factor"] == 0.1
    monkeypatch.setattr(meshcache, "MESH_LAW_VERSION", 999)
    got = get_mesh(tmp_path, GID, other)
    assert got.status == "rebuilt" and "mesh law" in got.reason


def test_other_closure_zone_rebuilds(tmp_path: Path) -> None:
    # The zone is imprinted on the mesh, so a cached mesh of another zone is stale.
    get_mesh(tmp_path, GID, SPEC)
    wider = GeometrySpec(**SPEC.to_dict() | {"zone_y_fraction": 0.5})
    got = get_mesh(tmp_path, GID, wider)
    assert got.status == "rebuilt" and "other geometric parameters" in got.reason
    assert got.mesh.info["closure_zone"]["y_fraction"] == 0.5
    assert get_mesh(tmp_path, GID, wider).status == "cached"


def test_cached_file_of_another_geometry_id_is_rejected(tmp_path: Path, reference) -> None:
    path = mesh_path(tmp_path, GID)
    save_mesh(path, reference, SPEC, "fedcba9876543210")
    with pytest.raises(StoreError, match="holds geometry fedcba9876543210"):
        load_mesh(path, SPEC, GID)


def test_failed_write_leaves_old_file_and_no_temporary(
    tmp_path: Path, reference, monkeypatch
) -> None:
    path = get_mesh(tmp_path, GID, SPEC).path
    before = path.read_bytes()

    def broken_savez(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(meshcache.np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        save_mesh(path, reference, SPEC, GID)
    assert path.read_bytes() == before
    assert [p.name for p in path.parent.iterdir()] == [path.name]


def test_geometry_failure_writes_nothing(tmp_path: Path, monkeypatch) -> None:
    def fail(spec: GeometrySpec) -> MeshData:
        raise GeometryError("gmsh failed: simulated")

    monkeypatch.setattr(meshcache, "build_mesh", fail)
    with pytest.raises(GeometryError, match="simulated"):
        get_mesh(tmp_path, GID, SPEC)
    assert not mesh_path(tmp_path, GID).exists()


@pytest.mark.parametrize("bad", ["../../etc/passwd", "0123", "0123456789ABCDEF", 12])
def test_geometry_id_must_be_16_hex(tmp_path: Path, bad) -> None:
    with pytest.raises(StoreError, match="16 lowercase hex"):
        mesh_path(tmp_path, bad)
