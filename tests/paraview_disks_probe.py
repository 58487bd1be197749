"""Open a many-disk run's XDMF sidecar with ParaView's XDMF reader, draw every disk as a glyph
scaled by its radius, and print what ParaView made, as JSON on the last line of stdout, for
tests/test_paraview_disks.py.

Run with pvpython: `pvpython tests/paraview_disks_probe.py RUN.xdmf`. For the last time step: the
particle grid's point count, its coordinates and `radius`; and for the Glyph filter (a sphere of
diameter 1 per disk, scaled by `radius` times 2, so its radius is the disk's) the point count,
and each disk's glyph: its radius (half its height along z, where the sphere's poles reach it)
and the middle of its extent in x and y.
"""

import json
import sys

from paraview import servermanager
from paraview.simple import Glyph, XDMFReader
from vtkmodules.util.numpy_support import vtk_to_numpy


def main() -> None:
    reader = XDMFReader(FileNames=[sys.argv[1]])
    reader.UpdatePipelineInformation()
    # the particle grids only (the reader names a grid of the k-th repeat "particles[k]"): the
    # fields are not read, and the Glyph filter draws the disks alone
    grids = reader.GetProperty("GridInfo")[::2]
    reader.GridStatus = [g for g in grids if g.split("[")[0] == "particles"]
    t = list(reader.TimestepValues)[-1]
    reader.UpdatePipeline(t)
    root = servermanager.Fetch(reader)
    parts = None
    for k in range(root.GetNumberOfBlocks()):
        if root.GetMetaData(k).Get(root.NAME()).split("[")[0] == "particles":
            parts = root.GetBlock(k)
    radius = parts.GetPointData().GetArray("radius")
    out = {
        "time": t,
        "points": [list(parts.GetPoint(k))[:2] for k in range(parts.GetNumberOfPoints())],
        "radius": [radius.GetValue(k) for k in range(radius.GetNumberOfTuples())],
    }
    glyph = Glyph(Input=reader, GlyphType="Sphere")
    glyph.ScaleArray = ["POINTS", "radius"]
    glyph.ScaleFactor = 2.0
    glyph.GlyphMode = "All Points"
    glyph.UpdatePipeline(t)
    drawn = servermanager.Fetch(glyph)
    # one block per particle grid read; the last time step's is the one drawn
    blocks = [drawn.GetBlock(k) for k in range(drawn.GetNumberOfBlocks())] \
        if drawn.IsA("vtkMultiBlockDataSet") else [drawn]
    block = [b for b in blocks if b is not None and b.GetNumberOfPoints() > 0][-1]
    points = vtk_to_numpy(block.GetPoints().GetData()).astype(float)
    # the glyphs' points come disk after disk, the same number for each: a sphere reaches its
    # radius at its poles, along z, whatever its tessellation
    per = points.reshape(parts.GetNumberOfPoints(), -1, 3)
    out["glyphs"] = {
        "points": int(points.shape[0]),
        "radius": ((per[:, :, 2].max(axis=1) - per[:, :, 2].min(axis=1)) / 2).tolist(),
        "centre": ((per[:, :, :2].max(axis=1) + per[:, :, :2].min(axis=1)) / 2).tolist(),
    }
    print(json.dumps(out))


main()
