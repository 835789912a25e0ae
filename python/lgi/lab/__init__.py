"""The lab: synthetic data, ground truth and evaluation, the project's own test bench, not the
library. `sample` (the built-in sample, made on `face`), `capture` (the capture protocol's
ground truth: real motion curves on a dataset with a hinged jaw), `helmet` (a synthetic helmet
take for the capture front end), `evaluate` (the protocols and their scores), `render` and
`quality` (error pictures, mesh-quality figures), `ict` (the ICT-FaceKit facts) and `demo`
(`lgi demo`, `lgi helmet-demo`). No module outside `lgi.lab` imports it, except the CLI's
`demo`, `evaluate` and `helmet-demo` commands, lazily.
"""
