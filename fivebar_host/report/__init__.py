"""Pictures: every module of fivebar that imports matplotlib lives here, and only those.

`preview` draws the dry-run picture of a compiled job, `workspace` the picture of
`fivebar workspace`, `linkage` a linkage simulation. Each is imported lazily by the command
that draws, so the CLI starts (and the text reports, files and the pipeline run) without
loading matplotlib. This package file imports nothing for the same reason.
"""
