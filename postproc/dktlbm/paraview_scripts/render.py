"""Render the vorticity of a dktlbm run with its disks as glyphs to a PNG, from the run's XDMF
sidecars: the ParaView view a user builds by hand (docs/output.md, "Open it in ParaView").
The command dkt-paraview (dktlbm.paraview) runs it with ParaView's Python:

    pvpython render.py runs/case1/case1.xdmf --time 1.5 -o case1_paraview.png

The field grids of <name>.xdmf are coloured by vorticity (1/s, a symmetric range, blue
clockwise, red anticlockwise); each disk of <name>_particles.xdmf is a sphere glyph of its
radius at its centre; the title gives the scene and the time of the output shown (the output
nearest to --time).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from paraview.simple import (
    ColorBy,
    CreateView,
    GetColorTransferFunction,
    GetScalarBar,
    Glyph,
    Render,
    SaveScreenshot,
    Show,
    Text,
    XDMFReader,
)


def main() -> None:
    # every option is given by dkt-paraview, which holds the defaults
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("xdmf", type=Path, help="the run's <name>.xdmf")
    ap.add_argument("--time", type=float, default=None, help="s; default: the last output")
    ap.add_argument("--field", required=True, help="point field to colour by")
    ap.add_argument("--range", type=float, required=True,
                    help="colour range +-RANGE in the field's unit")
    ap.add_argument("--size", type=int, nargs=2, required=True, metavar=("W", "H"),
                    help="image size in pixels")
    ap.add_argument("-o", "--output", type=Path, required=True, help="the PNG to write")
    args = ap.parse_args()
    path = str(args.xdmf.resolve())

    # the fields from <name>.xdmf (the reader names the grids of each output time fields,
    # fields[1], ...), the disks from <name>_particles.xdmf, written for runs with disks; a
    # run written before that file existed has its disks only in <name>.xdmf (particles,
    # particles[1], ...), which a script, unlike the GUI, can select at every time
    fields = XDMFReader(FileNames=[path])
    grids = list(fields.GetProperty("GridInfo")[::2])
    fields.GridStatus = [g for g in grids if g.startswith("fields")]
    particles = args.xdmf.with_name(args.xdmf.stem + "_particles.xdmf")
    disks = None
    if particles.is_file():
        disks = XDMFReader(FileNames=[str(particles.resolve())])
    elif any(g.startswith("particles") for g in grids):
        disks = XDMFReader(FileNames=[path])
        disks.GridStatus = [g for g in grids if g.startswith("particles")]
    times = list(fields.TimestepValues) or [0.0]
    t = times[-1] if args.time is None else min(times, key=lambda v: abs(v - args.time))

    view = CreateView("RenderView")
    view.ViewSize = list(args.size)
    view.ViewTime = t
    view.OrientationAxesVisibility = 0
    view.Background = [1.0, 1.0, 1.0]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0

    shown = Show(fields, view)
    # ParaView shows a lone image grid (a run without disks) as its outline
    shown.SetRepresentationType("Surface")
    ColorBy(shown, ("POINTS", args.field))
    lut = GetColorTransferFunction(args.field)
    lut.ApplyPreset("Cool to Warm", True)
    lut.RescaleTransferFunction(-args.range, args.range)
    lut.AutomaticRescaleRangeMode = "Never"
    # the colours as they are, not shaded by the light
    shown.Ambient, shown.Diffuse, shown.Specular = 1.0, 0.0, 0.0
    shown.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title = f"{args.field} (1/s)" if args.field == "vorticity" else args.field
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0.0, 0.0, 0.0]
    bar.TitleFontSize = bar.LabelFontSize = 18
    bar.WindowLocation = "Any Location"
    bar.Position = [0.80, 0.3]
    bar.RangeLabelFormat = "%-#.3g"
    bar.ScalarBarLength = 0.4

    if disks is not None:
        glyphs = Glyph(Input=disks, GlyphType="Sphere")
        glyphs.GlyphType.ThetaResolution = 64
        glyphs.GlyphType.PhiResolution = 32
        glyphs.ScaleArray = ["POINTS", "radius"]
        glyphs.ScaleFactor = 2.0  # the sphere source has radius 1/2: a sphere of radius `radius`
        glyphs.GlyphMode = "All Points"
        glyphs.OrientationArray = ["POINTS", "No orientation array"]
        gshown = Show(glyphs, view)
        ColorBy(gshown, None)
        gshown.DiffuseColor = gshown.AmbientColor = [0.15, 0.15, 0.15]

    title = Text(Text=f"{args.xdmf.stem}: {args.field}, t = {t:.3f} s")
    tshown = Show(title, view)
    tshown.WindowLocation = "Upper Center"
    tshown.FontSize = 22
    tshown.Color = [0.0, 0.0, 0.0]

    # looking down on the X-Y plane, x across and y up the channel, the window filling the
    # height (the title above, the colour bar beside)
    fields.UpdatePipeline(t)
    x0, x1, y0, y1, _, _ = fields.GetDataInformation().GetBounds()
    xc, yc = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    Render(view)  # the first render places the camera itself; it is set after that
    view.InteractionMode = "2D"
    view.CameraParallelProjection = 1
    view.CameraFocalPoint = [xc + 0.12 * (x1 - x0), yc, 0.0]
    view.CameraPosition = [xc + 0.12 * (x1 - x0), yc, 10.0 * (y1 - y0)]
    view.CameraViewUp = [0.0, 1.0, 0.0]
    view.CameraParallelScale = 0.56 * (y1 - y0)
    Render(view)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    SaveScreenshot(str(args.output), view, ImageResolution=list(args.size))
    print(f"wrote {args.output} (t = {t} s)")


if __name__ == "__main__":
    main()
