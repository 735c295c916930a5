"""ParaView's default look at an export, through VTK offscreen: the ``surface`` block of a
stage's multiblock, coloured by its cell data ``von_mises_kPa`` (range 0 to its p99), white
background. NaN cells would be drawn in the lookup table's NaN colour (magenta, a hue the
blue-to-red map never takes), so the image's magenta pixels, whatever their shading, count the
NaN faces a user would see.

The rendering runs in a fresh interpreter: VTK's offscreen window aborts (std::bad_alloc in
vtkRenderer::Render, VTK 9.7) in a process that has created a DOLFINx mesh, as the in-process
finite-element tests before it do."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["NAN_RGB", "render_surface"]

NAN_RGB = (255, 0, 255)


def render_surface(vtm: Path, png: Path, size: tuple[int, int] = (1100, 750)) -> dict[str, Any]:
    """Render ``vtm``'s surface block to ``png`` in a fresh interpreter; returns counts of
    cells and pixels."""
    argv = [sys.executable, __file__, str(vtm), str(png), str(size[0]), str(size[1])]
    res = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def _render(vtm: Path, png: Path, size: tuple[int, int]) -> dict[str, Any]:
    """`render_surface` in this process."""
    import vtk
    from vtkmodules.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLMultiBlockDataReader()
    reader.SetFileName(str(vtm))
    reader.Update()
    mb = reader.GetOutput()
    names = [
        mb.GetMetaData(i).Get(vtk.vtkCompositeDataSet.NAME()) for i in range(mb.GetNumberOfBlocks())
    ]
    grid = mb.GetBlock(names.index("surface"))
    vm = vtk_to_numpy(grid.GetCellData().GetArray("von_mises_kPa"))
    warp = vtk.vtkWarpVector()
    warp.SetInputData(grid)
    grid.GetPointData().SetActiveVectors("displacement_mm")
    warp.SetScaleFactor(1.0)
    geom = vtk.vtkGeometryFilter()
    geom.SetInputConnection(warp.GetOutputPort())
    lut = vtk.vtkLookupTable()
    lut.SetHueRange(0.667, 0.0)
    lut.SetNanColor(NAN_RGB[0] / 255, NAN_RGB[1] / 255, NAN_RGB[2] / 255, 1.0)
    lut.Build()
    mapper = vtk.vtkPolyDataMapper()
    mapper.SetInputConnection(geom.GetOutputPort())
    mapper.SetScalarModeToUseCellFieldData()
    mapper.SelectColorArray("von_mises_kPa")
    mapper.SetLookupTable(lut)
    finite = vm[np.isfinite(vm)]
    mapper.SetScalarRange(0.0, float(np.percentile(finite, 99)) if finite.size else 1.0)
    mapper.SetColorModeToMapScalars()
    mapper.ScalarVisibilityOn()
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    bar = vtk.vtkScalarBarActor()
    bar.SetLookupTable(lut)
    bar.SetTitle("von Mises (kPa)")
    bar.SetNumberOfLabels(5)
    bar.GetTitleTextProperty().SetColor(0, 0, 0)
    bar.GetLabelTextProperty().SetColor(0, 0, 0)
    ren = vtk.vtkRenderer()
    ren.AddActor(actor)
    ren.AddViewProp(bar)
    ren.SetBackground(1, 1, 1)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.AddRenderer(ren)
    win.SetSize(*size)
    cam = ren.GetActiveCamera()
    cam.SetPosition(1.2, -1.6, 1.1)
    cam.SetFocalPoint(0, 0, 0)
    cam.SetViewUp(0, 0, 1)
    ren.ResetCamera()
    cam.Zoom(1.3)
    win.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.ReadFrontBufferOff()
    grab.Update()
    img = grab.GetOutput()
    w, h, _ = img.GetDimensions()
    rgb = vtk_to_numpy(img.GetPointData().GetScalars()).reshape(h, w, -1)[:, :, :3]
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(str(png))
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()
    background = (rgb == 255).all(axis=2)
    r, g, b = (rgb[:, :, i].astype(int) for i in range(3))
    nan = (r > 40) & (b > 40) & (abs(r - b) < 40) & (g < 0.3 * np.minimum(r, b))  # shaded magenta
    return {
        "cells": int(len(vm)),
        "nan_cells": int(np.isnan(vm).sum()),
        "nan_pixels": int(nan.sum()),
        "coloured_fraction": float(1.0 - background.mean()),
    }


if __name__ == "__main__":
    vtm_arg, png_arg, width, height = sys.argv[1:5]
    stats = _render(Path(vtm_arg), Path(png_arg), (int(width), int(height)))
    print(json.dumps(stats))
