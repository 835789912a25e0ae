"""The capture front end, 2D marker tracks to bundles for `Model.solve` (pure numpy;
docs/capture-front-end.md): `camera` (OpenCV-convention fisheye and pinhole cameras),
`triangulation` (tracks to 3D points, single-view markers as rays), `stabilize` (the head's
motion removed: robust rigid alignment, stable weights, despike), `rays` (single-view markers
as ray constraints around `Model.solve`), `frontend` (the chain in one call) and
`calibration` (camera calibration files, OpenCV FileStorage YAML/JSON). Track files are
`lgi.io.tracks`'.
"""

from lgi.capture import calibration, camera, frontend, rays, stabilize, triangulation

__all__ = ["calibration", "camera", "frontend", "rays", "stabilize", "triangulation"]
