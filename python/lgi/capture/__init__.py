"""The capture front end, 2D marker tracks to bundles for `Model.solve` (pure numpy;
docs/capture-front-end.md): `camera` (OpenCV-convention fisheye and pinhole cameras),
`triangulation` (tracks to 3D points, single-view markers as rays), `stabilize` (the head's
motion removed: robust rigid alignment, stable weights, despike), `rays` (single-view markers
as ray constraints around `Model.solve`) and `frontend` (the chain in one call). Calibration
and track files are `lgi.io`'s.
"""

from lgi.capture import camera, frontend, rays, stabilize, triangulation

__all__ = ["camera", "frontend", "rays", "stabilize", "triangulation"]
