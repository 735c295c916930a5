"""woundsweep.mesh.cache: reuse, validation, rebuild of damaged or stale files, atomic writes."""

from __future__ import annotations

import dataclasses
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
    first = get_mesh(tmp_path, SPEC)
    assert first.status == "built" and first.path == tmp_path / "meshes" / f"{SPEC.mesh_id}.npz"
    assert first.path.is_file() and same(first.mesh, reference)
    no_build(monkeypatch)
    second = get_mesh(tmp_path, SPEC)
    assert second.status == "cached" and second.reason == ""
    assert same(second.mesh, reference)
    assert second.mesh.info["cells"] == reference.info["cells"]
    # only the final file, no temporary left behind
    assert sorted(p.name for p in (tmp_path / "meshes").iterdir()) == [f"{SPEC.mesh_id}.npz"]


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
    path = get_mesh(tmp_path, SPEC).path
    damage(path)
    with pytest.raises(StoreError, match=reason):
        load_mesh(path, SPEC)
    again = get_mesh(tmp_path, SPEC)
    assert again.status == "rebuilt" and re.search(reason, again.reason)
    assert same(again.mesh, reference)
    assert same(load_mesh(path, SPEC), reference)  # the replacement file is valid


def test_file_of_another_mesh_or_law_version_is_rebuilt(tmp_path: Path, monkeypatch) -> None:
    # A file under this mesh's name that holds another mesh (copied, renamed) is not used.
    other = GeometrySpec.cylindrical(1.0, 1.0, 1.5, 1.0, 0.1, 0.3)
    path = mesh_path(tmp_path, SPEC.mesh_id)
    save_mesh(path, build_mesh(other), other)
    got = get_mesh(tmp_path, SPEC)
    assert got.status == "rebuilt" and f"holds mesh {other.mesh_id}" in got.reason
    assert json.loads(np.load(path)["meta"].tobytes())["spec"]["wound_aspect_factor"] == 0.2
    monkeypatch.setattr(meshcache, "MESH_LAW_VERSION", 999)
    got = get_mesh(tmp_path, SPEC)
    assert got.status == "rebuilt" and "mesh law" in got.reason


def test_other_closure_zone_is_another_mesh(tmp_path: Path) -> None:
    # The zone is imprinted on the mesh, so a mesh of another zone has its own file.
    first = get_mesh(tmp_path, SPEC)
    wider = GeometrySpec(**SPEC.to_dict() | {"zone_y_fraction": 0.5})
    got = get_mesh(tmp_path, wider)
    assert got.status == "built" and got.path != first.path
    assert got.mesh.info["closure_zone"]["y_fraction"] == 0.5
    assert get_mesh(tmp_path, wider).status == get_mesh(tmp_path, SPEC).status == "cached"


def test_file_records_the_element_degree_and_a_mismatch_is_refused(tmp_path: Path) -> None:
    path = get_mesh(tmp_path, SPEC).path
    meta = json.loads(np.load(path)["meta"].tobytes())
    assert meta["element_degree"] == meta["info"]["element_degree"] == SPEC.element_degree == 2
    assert meta["mesh_id"] == SPEC.mesh_id
    # The P1 mesh of the same geometry under the P2 mesh's name: refused, naming both.
    p1 = dataclasses.replace(SPEC, element_degree=1)
    save_mesh(path, build_mesh(p1), p1)
    with pytest.raises(StoreError, match=r"built for P1 elements, not P2$") as err:
        load_mesh(path, SPEC)
    assert "\n" not in str(err.value)
    got = get_mesh(tmp_path, SPEC)
    assert got.status == "rebuilt" and "built for P1 elements" in got.reason
    assert got.mesh.info["element_degree"] == 2


def test_failed_write_leaves_old_file_and_no_temporary(
    tmp_path: Path, reference, monkeypatch
) -> None:
    path = get_mesh(tmp_path, SPEC).path
    before = path.read_bytes()

    def broken_savez(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(meshcache.np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        save_mesh(path, reference, SPEC)
    assert path.read_bytes() == before
    assert [p.name for p in path.parent.iterdir()] == [path.name]


def test_geometry_failure_writes_nothing(tmp_path: Path, monkeypatch) -> None:
    def fail(spec: GeometrySpec) -> MeshData:
        raise GeometryError("gmsh failed: simulated")

    monkeypatch.setattr(meshcache, "build_mesh", fail)
    with pytest.raises(GeometryError, match="simulated"):
        get_mesh(tmp_path, SPEC)
    assert not mesh_path(tmp_path, SPEC.mesh_id).exists()


@pytest.mark.parametrize("bad", ["../../etc/passwd", "0123", "0123456789ABCDEF", 12])
def test_mesh_id_must_be_16_hex(tmp_path: Path, bad) -> None:
    with pytest.raises(StoreError, match="16 lowercase hex"):
        mesh_path(tmp_path, bad)


# -- the mesh id ------------------------------------------------------------------------------

WEDGE = GeometrySpec.wedge(1.0, 1.0, 2.0, 1.0, 0.6, 0.3)


@pytest.mark.parametrize(
    "change",
    [
        {"dermal_thickness_mm": 1.1},
        {"subcutis_thickness_mm": 1.2},
        {"patch_half_length_mm": 2.5},
        {"wound_width_mm": 0.8},
        {"wound_depth_mm": 0.5},
        {"mesh_size_factor": 0.5},
        {"zone_y_fraction": 0.5},
        {"zone_depth_fraction": 0.25},
        {"element_degree": 1},
    ],
    ids=lambda change: next(iter(change)),
)
def test_mesh_id_changes_with_every_input_of_the_mesh(change: dict) -> None:
    other = GeometrySpec(**WEDGE.to_dict() | change)
    assert re.fullmatch(r"[0-9a-f]{16}", other.mesh_id) and other.mesh_id != WEDGE.mesh_id


def test_mesh_id_changes_with_the_shape_and_the_size_law(monkeypatch) -> None:
    import woundsweep.config.geometry as geometry

    cyl = GeometrySpec.cylindrical(1.0, 1.0, 2.0, 1.0, 0.0, 0.3)
    fusiform = GeometrySpec.fusiform(1.0, 1.0, 2.0, 1.0, 3.0, 0.6, 0.3)
    longer = GeometrySpec.fusiform(1.0, 1.0, 2.0, 1.0, 3.5, 0.6, 0.3)
    assert len({WEDGE.mesh_id, cyl.mesh_id, fusiform.mesh_id, longer.mesh_id}) == 4
    before = WEDGE.mesh_id
    monkeypatch.setattr(geometry, "MESH_LAW_VERSION", geometry.MESH_LAW_VERSION + 1)
    assert WEDGE.mesh_id != before
    # Equal parameters name one mesh, however the numbers are spelled.
    monkeypatch.undo()
    assert GeometrySpec.wedge(1, 1, 2, 1, 0.6, 0.3).mesh_id == before


def test_mesh_id_is_the_geometrys_not_the_jobs(demo_manifest) -> None:
    """The skin types and orientations of a geometry share its mesh; materials, contact and
    Newton's settings do not name meshes, the sweep's closure zone and element do."""
    from cli_run import DEMO

    from woundsweep.config.manifest import job_geometry
    from woundsweep.config.paper import ClosureZone
    from woundsweep.config.sweep import load_sweep

    sweep = load_sweep(DEMO)
    rows = demo_manifest.to_dict("records")
    ids = [job_geometry(sweep, r).mesh_id for r in rows]
    by_geometry: dict[str, set[str]] = {}
    for row, mesh_id in zip(rows, ids):
        by_geometry.setdefault(row["geometry_id"], set()).add(mesh_id)
    assert all(len(v) == 1 for v in by_geometry.values())
    assert len(set(ids)) == len(by_geometry) < len(rows)
    row = rows[0]
    skins = sweep.materials.skin_types
    same = [
        sweep._replace(
            materials=dataclasses.replace(
                sweep.materials,
                skin_types={**skins, "stiff": dataclasses.replace(skins["stiff"], c_kPa=50.0)},
            )
        ),
        sweep._replace(stages=dataclasses.replace(sweep.stages, contact_penalty_GPa=(1, 2, 3))),
        sweep._replace(solver=dataclasses.replace(sweep.solver, quadrature_degree=2)),
    ]
    for s in same:
        assert job_geometry(s, row).mesh_id == ids[0]
    for s in (
        sweep._replace(stages=dataclasses.replace(sweep.stages, closure_zone=ClosureZone(0.5))),
        sweep._replace(solver=dataclasses.replace(sweep.solver, element_degree=1)),
    ):
        assert job_geometry(s, row).mesh_id != ids[0]
    other_skin = {**row, "skin_type": "soft" if row["skin_type"] != "soft" else "stiff"}
    assert job_geometry(sweep, {**other_skin, "orientation_deg": 45.0}).mesh_id == ids[0]


@pytest.mark.fem
def test_a_job_refuses_a_mesh_of_another_element_degree(demo_run: Path) -> None:
    from woundsweep.config.manifest import load_run
    from woundsweep.physics.job import job_model

    run = load_run(demo_run)
    row = run.job(0)
    p1 = build_mesh(dataclasses.replace(run.geometry(row), element_degree=1))
    with pytest.raises(
        GeometryError, match=r"^job 0: the mesh was built for P1 elements, the sweep's are P2$"
    ):
        job_model(run, row, p1)
