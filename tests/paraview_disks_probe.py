"""Open a many-disk run's particle sidecar `<name>_particles.xdmf` with ParaView's XDMF reader,
draw every disk as a glyph scaled by its radius, and print what ParaView made, as JSON on the
last line of stdout, for tests/test_paraview_disks.py.

Run with pvpython: `pvpython tests/paraview_disks_probe.py RUN_particles.xdmf`. For the last time
step: the particle grid's point count, its coordinates and `radius`; and for the Glyph filter (a
sphere of diameter 1 per disk, scaled by `radius` times 2, so its radius is the disk's) the point
count, and each disk's glyph: its radius (half its height along z, where the sphere's poles
reach it) and the middle of its extent in x and y.
"""

import json
import sys

from paraview import servermanager
from paraview.simple import Glyph, XDMFReader
from vtkmodules.util.numpy_support import vtk_to_numpy


def main() -> None:
    reader = XDMFReader(FileNames=[sys.argv[1]])
    reader.UpdatePipelineInformation()
    # the disks alone: the lattice is not read, and the Glyph filter draws the disks only
    t = list(reader.TimestepValues)[-1]
    reader.UpdatePipeline(t)
    parts = servermanager.Fetch(reader)
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
    points = vtk_to_numpy(drawn.GetPoints().GetData()).astype(float)
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
