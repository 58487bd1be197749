"""Open a run's particle sidecar `<name>_particles.xdmf` as the ParaView GUI does and step
through its output times with one Glyph filter made once; print what the glyphs show, as JSON
on the last line of stdout, for tests/test_paraview_particles.py.

Run with pvpython: `pvpython tests/paraview_particles_probe.py RUN_particles.xdmf`. The steps are
those of docs/output.md, "Open it in ParaView": the XDMF reader on the file, then a Glyph on the
reader (Glyph Type Sphere, Scale Array `radius`, Scale Factor 2, Glyph Mode All Points), made
once; then for every time the reader offers, the pipeline is updated to that time, as the time
control of the GUI does. Printed for each time: the disks the reader gives, the glyph's point
count, and each disk's glyph, split disk after disk (every disk has the same number of glyph
points): the middle of its extent in x and y, and its radius (half its height along z, where the
sphere's poles reach).
"""

import json
import sys

import numpy as np
from paraview import servermanager
from paraview.simple import Glyph, XDMFReader
from vtkmodules.util.numpy_support import vtk_to_numpy


def leaves(data) -> list:
    """The non-empty datasets of `data`, itself or the blocks of a composite dataset."""
    if not data.IsA("vtkCompositeDataSet"):
        return [data] if data.GetNumberOfPoints() > 0 else []
    it = data.NewIterator()
    it.InitTraversal()
    found = []
    while not it.IsDoneWithTraversal():
        block = it.GetCurrentDataObject()
        if block is not None and block.GetNumberOfPoints() > 0:
            found.append(block)
        it.GoToNextItem()
    return found


def main() -> None:
    reader = XDMFReader(FileNames=[sys.argv[1]])
    reader.UpdatePipelineInformation()
    glyph = Glyph(Input=reader, GlyphType="Sphere")
    glyph.ScaleArray = ["POINTS", "radius"]
    glyph.ScaleFactor = 2.0
    glyph.GlyphMode = "All Points"
    out = {"times": list(reader.TimestepValues), "steps": []}
    for t in out["times"]:
        glyph.UpdatePipeline(t)
        disks = sum(b.GetNumberOfPoints() for b in leaves(servermanager.Fetch(reader)))
        drawn = leaves(servermanager.Fetch(glyph))
        step = {"time": t, "disks": disks,
                "glyph_points": sum(b.GetNumberOfPoints() for b in drawn)}
        if disks and step["glyph_points"] and step["glyph_points"] % disks == 0:
            points = np.concatenate([vtk_to_numpy(b.GetPoints().GetData()) for b in drawn])
            per = points.astype(float).reshape(disks, -1, 3)
            step["radius"] = ((per[:, :, 2].max(axis=1) - per[:, :, 2].min(axis=1)) / 2).tolist()
            step["centre"] = ((per[:, :, :2].max(axis=1) + per[:, :, :2].min(axis=1)) / 2).tolist()
        out["steps"].append(step)
    print(json.dumps(out))


main()
