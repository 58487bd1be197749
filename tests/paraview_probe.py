"""Open a dktlbm run's XDMF sidecar with ParaView's XDMF reader and print what ParaView sees,
as JSON on the last line of stdout, for tests/test_paraview.py.

Run with pvpython: `pvpython tests/paraview_probe.py RUN.xdmf I,J [I,J ...]`. For every time
step: the field grid's dimensions and bounds, the arrays with their component counts, the
`velocity` vector at the nodes (i, j) given (0-based column i, row j), and the particle grid's
point coordinates and arrays.
"""

import json
import sys

from paraview import servermanager
from paraview.simple import XDMFReader


def arrays(data) -> dict:
    pd = data.GetPointData()
    return {
        pd.GetArray(k).GetName(): pd.GetArray(k).GetNumberOfComponents()
        for k in range(pd.GetNumberOfArrays())
    }


def values(data, name: str) -> list:
    a = data.GetPointData().GetArray(name)
    return [list(a.GetTuple(k)) for k in range(a.GetNumberOfTuples())]


def main() -> None:
    path = sys.argv[1]
    nodes = [tuple(int(v) for v in arg.split(",")) for arg in sys.argv[2:]]
    reader = XDMFReader(FileNames=[path])
    reader.UpdatePipelineInformation()
    out = {"times": list(reader.TimestepValues), "steps": []}
    for t in out["times"]:
        reader.UpdatePipeline(t)
        root = servermanager.Fetch(reader)
        blocks = {}
        for k in range(root.GetNumberOfBlocks()):
            # the reader appends "[n]" to grid names that repeat across the time steps
            name = root.GetMetaData(k).Get(root.NAME()).split("[")[0]
            blocks[name] = root.GetBlock(k)
        step = {"time": t, "blocks": sorted(blocks)}
        fields = blocks.get("fields")
        if fields is not None:
            bounds = [0.0] * 6
            fields.GetBounds(bounds)
            nx = fields.GetDimensions()[0]
            vel = fields.GetPointData().GetArray("velocity")
            step["fields"] = {
                "class": fields.GetClassName(),
                "dimensions": list(fields.GetDimensions()),
                "bounds": bounds,
                "arrays": arrays(fields),
                "velocity": {f"{i},{j}": list(vel.GetTuple(i + nx * j)) for i, j in nodes}
                if vel is not None
                else {},
            }
        parts = blocks.get("particles")
        if parts is not None:
            step["particles"] = {
                "points": [list(parts.GetPoint(k)) for k in range(parts.GetNumberOfPoints())],
                "arrays": arrays(parts),
                "radius": values(parts, "radius"),
                "omega": values(parts, "omega"),
                "velocity": values(parts, "velocity"),
            }
        out["steps"].append(step)
    print(json.dumps(out))


main()
