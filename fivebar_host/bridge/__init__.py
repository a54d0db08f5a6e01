"""`fivebar bridge`: a GRBL 1.1 controller in front of a five-bar (docs/grbl.md).

Split by concern: `policy` (how the bridge reads G-code through fivebar's one interpreter,
`fivebar_host.gcode`: GRBL's rules and the commands it refuses; the moves are compiled by
`fivebar_host.compile.incremental`), `codes` (GRBL's reply codes), `realtime` (the
sender's byte stream: real-time bytes, lines, overrides), `views` (status report, `$$`,
`$G`, `$#`, `$I` as GRBL shows them), `system` (`$` commands), `controller` (the `Bridge`
tying them together), `machine` (the thread that drives the fivebar firmware through
`fivebar_host.controllers.fivebar.link`), `serve` (pty and TCP).
"""
