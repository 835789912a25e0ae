"""Files in and out: every format lgi reads or writes, one module per kind of file.

`npz_dataset` (the dataset `.npz` layout), `takes` (marker takes: C3D, TRC, labelled CSV, `.npz`;
marker layouts), `livelink` (Live Link Face curves), `units` (the one unit table and its
conversions), `tracks` (the capture front end's 2D tracks in and bundles out), `csv_rows` (every CSV
opened one way); out: `topology` (the faces every mesh writer carries), `usd` (USD point caches),
`obj` (OBJ sequences), `result` (solved takes as `.npz`), `sink` (solved frames to any of those,
chunk by chunk) and `rig` (blendshape rigs as glTF morph targets or USD blendshapes). Every writer
checks its output path with `output_file`. io imports nothing it serves (`served`): camera
calibration files are `lgi.capture.calibration`'s.
"""

from lgi.io import (
    csv_rows,
    livelink,
    npz_dataset,
    obj,
    result,
    rig,
    sink,
    takes,
    topology,
    tracks,
    units,
    usd,
)
from lgi.io.paths import output_file

__all__ = [
    "csv_rows",
    "livelink",
    "npz_dataset",
    "obj",
    "output_file",
    "result",
    "rig",
    "sink",
    "takes",
    "topology",
    "tracks",
    "units",
    "usd",
]
