"""The readings behind `--recommended`: what a take's own markers say about how to solve it.
`leave_out` (the left-out rows every reading solves), `noise` (the markers' noise),
`denoise` (the take's low-rank denoising), `local`, `unbounded`, `take_prior` and `detail`
(one reading each) and `choices` (`plan_solve`: every choice, read in order)."""
