"""What a TD reviews of a solve: `diagnose` (findings: markers off, spikes, swaps), `report`
(the HTML report), `view` (the browser viewer's local server and its page under `viewer/`) and
`render` (a mesh drawn headless for the report's pictures)."""
