"""The application: `cli` (the `lgi` command), `pipeline` (a take from file to files, for
`lgi solve` and `lgi batch` alike), `batch` (many takes on Dask) and `interrupt` (Ctrl-C)."""
