"""Files in and out: every format lgi reads or writes, one module per kind of file.

`npz_dataset` (the dataset `.npz` layout), `takes` (marker takes: C3D, TRC, labelled CSV,
`.npz`; marker layouts), `livelink` (Live Link Face curves), `units` (the one unit table and its
conversions), `tracks` (the capture front end's 2D tracks in and bundles out), `calibration`
(camera calibration files, OpenCV FileStorage YAML/JSON), `csv_rows` (every CSV opened one
way); out: `topology` (the faces every mesh writer carries), `usd` (USD point caches), `obj`
(OBJ sequences), `result` (solved takes as `.npz`), `sink` (solved frames to any of those,
chunk by chunk) and `rig` (blendshape rigs as glTF morph targets or USD blendshapes). Every
writer checks its output path with `output_file`.
"""

from lgi.io import (
    calibration,
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
    "calibration",
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
