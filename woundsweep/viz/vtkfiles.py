"""VTK XML files for ParaView: an unstructured grid (`write_vtu`, by meshio, binary and zlib)
with the units of its arrays in an XML comment, a multiblock (`vtm`) naming its blocks, and a
time series (`pvd`). Every file is written atomically.

The units are a comment, not a field-data array: meshio (and so every script that reads a VTU
through it) refuses VTK's String arrays, and every array's name carries its unit anyway."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..core.fsutil import atomic_write

__all__ = ["UNITS_COMMENT", "pvd", "units_of", "vtm", "write_text", "write_vtu"]

# The comment of every VTU that names each array's unit: "<!-- units: name=unit; ... -->".
UNITS_COMMENT = "units:"


def _units_comment(units: Sequence[tuple[str, str]]) -> str:
    text = "; ".join(f"{n}={u}" for n, u in units).replace("--", "- -")
    return f"<!-- {UNITS_COMMENT} {text} -->\n"


def units_of(text: str) -> dict[str, str]:
    """The units a VTU's comment names (``{}`` if it has none)."""
    start = text.find(f"<!-- {UNITS_COMMENT} ")
    if start < 0:
        return {}
    body = text[start + len(UNITS_COMMENT) + 6 : text.index(" -->", start)]
    return dict(item.split("=", 1) for item in body.split("; ") if "=" in item)


def _flat(a: np.ndarray) -> np.ndarray:
    """Tensors (n, 3, 3) as VTK's 9 components (meshio writes no component count for them)."""
    a = np.asarray(a)
    return a.reshape(len(a), -1) if a.ndim > 2 else a


def write_vtu(
    path: Path,
    points: np.ndarray,
    cells: Sequence[tuple[str, np.ndarray]],
    point_data: Mapping[str, np.ndarray],
    cell_data: Mapping[str, list[np.ndarray]],
    units: Mapping[str, str],
) -> None:
    """One VTU; ``units`` maps each array name to its unit ("1" for a ratio)."""
    import meshio

    mesh = meshio.Mesh(
        points,
        list(cells),
        point_data={k: _flat(v) for k, v in point_data.items()},
        cell_data={k: [_flat(b) for b in v] for k, v in cell_data.items()},
    )
    names = [*point_data, *cell_data]
    missing = [n for n in names if n not in units]
    if missing:
        raise ValueError(f"no unit for {missing}")
    block = _units_comment([(n, units[n]) for n in names])

    def write(tmp: str) -> None:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression="zlib")
        text = Path(tmp).read_text("ascii")
        Path(tmp).write_text(
            text.replace("<UnstructuredGrid>\n", "<UnstructuredGrid>\n" + block, 1)
        )

    atomic_write(path, write)


def vtm(blocks: Sequence[tuple[str, str]]) -> str:
    """A multiblock of VTU files: (block name, file relative to the .vtm)."""
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="vtkMultiBlockDataSet" version="1.0" byte_order="LittleEndian">',
        "  <vtkMultiBlockDataSet>",
    ]
    lines += [
        f'    <DataSet index="{i}" name={quoteattr(name)} file={quoteattr(f)}/>'
        for i, (name, f) in enumerate(blocks)
    ]
    lines += ["  </vtkMultiBlockDataSet>", "</VTKFile>", ""]
    return "\n".join(lines)


def pvd(files: Sequence[tuple[int, str]]) -> str:
    """A time series: (timestep, file) per step."""
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
    ]
    lines += [
        f'    <DataSet timestep="{k}" group="" part="0" file={quoteattr(name)}/>'
        for k, name in files
    ]
    lines += ["  </Collection>", "</VTKFile>", ""]
    return "\n".join(lines)


def write_text(path: Path, text: str) -> None:
    """A small text file, atomically."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))
