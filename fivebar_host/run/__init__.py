"""Running jobs on the machine: the serial link, streaming, programs, faults and resume.

Modules, from the wire up: `errors` (link errors, `FaultKind`), `stream` (the streaming
state machine), `link` (pyserial session: handshake, status, commands, resets), `program`
(job → firmware lines, no I/O), `resume` (the resume file and mapping a stopped stream back
to segments), `faults` (stop safely after a fault, record where) and `sender` (run a job:
start pose, stream, wait, report). Import from the submodules.
"""
