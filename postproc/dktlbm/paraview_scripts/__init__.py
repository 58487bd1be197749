"""Scripts that ParaView's `pvpython` runs (they import paraview.simple, which plain Python
has not): `render.py`, the picture of dkt-paraview (dktlbm.paraview). They live in a folder of
their own so that pvpython, which puts a script's folder first on sys.path, does not take the
module dktlbm.paraview for ParaView's `paraview` package."""
