"""`fivebar serve`: the host daemon that owns the serial port and runs a queue of jobs.

A plotter hangs off a small computer that stays on; the daemon keeps the port open (so the
Arduino is not reset for every job), compiles and checks each submitted drawing before it is
queued, streams the jobs one after another through `run.job.run_job`, and lets the CLI
(`fivebar plot DRAWING --server URL`) and other programs submit and follow them over a small
HTTP + JSON API (docs/serve.md).

Modules:

- `store`: the SQLite database — the queue, each job's upload, options, progress and resume
  point, and what the daemon knows about the machine's pose.
- `security`: the token file, the loopback rule, request size limits, Host/Origin checks.
- `jobs`: submitted options and uploads → a compiled, checked `Job` (private temp dir);
  `compiler`: each compilation and dry run in a child process of its own.
- `worker`: the machine thread, which owns the `Link` and runs the queue (pause, resume,
  cancel, SIGTERM stop at a segment boundary, recovery after a crash). Its state is one
  record only it writes (`state`: also the immutable snapshot other threads read); other
  threads reach it through one request queue (`requests`: the requests and the
  `WorkerHandle`). It composes one collaborator per concern: `jobrun` (one job's run),
  `control` (pause / resume / cancel / overrides, the stop kind), `manual` (home, jog, pen,
  motors off, clear alarm), `recovery` (after a restart or a lost link), `pose` (the pose
  record, the motors, parking); `operator` (the run's operator and resume store), `stored`
  (queued jobs compiled again) and `journal` (journalled link, progress writer) serve them.
- `app`: the FastAPI application (error format, unknown-parameter check) over `routes`
  (one `APIRouter` each: `status`, `jobs`, `submit`, `machine`, `page`), which take the
  `context` (store, handle to the machine thread, compiled jobs, profile, compilation slots,
  event hub) as the public dependency `Ctx`; `models` (the JSON shapes, the error answer),
  `dryrun` (the dry run's report and preview) and `events` (the web page's event stream)
  serve them.
- `daemon`: wiring and lifecycle (uvicorn in a thread, signals, logging).
- `client`: the stdlib HTTP client used by `fivebar plot --server`.
- `ptydevice`: a `fivebar-mock://` machine served on a pseudo-terminal, a stand-in controller
  that outlives the daemon (for trying the daemon without hardware, and for crash tests).
"""

from __future__ import annotations
