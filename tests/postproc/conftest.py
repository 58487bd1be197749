"""The post-processing tests import the postproc modules and tests/dkt_run.py by plain name;
ctest puts the source root and postproc/ on PYTHONPATH, this also makes a bare
`python3 -m pytest tests/postproc` work."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
for path in (ROOT / "postproc", ROOT / "tests", Path(__file__).resolve().parent):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))
