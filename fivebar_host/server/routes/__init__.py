"""The daemon's HTTP routes, one FastAPI `APIRouter` per concern.

- `status`: `GET /api/status` (daemon, machine, queue counts).
- `jobs`: the queue and history — list, one job, pause, resume, cancel, delete, reorder,
  the planned path, the live overrides.
- `submit`: submissions and the dry run (compiled in a compilation slot, in a compiling
  process).
- `machine`: home, jog, pen, motors off, clear alarm.
- `page`: the web page, its files, the job options' definitions, the event stream.

Every route takes the application's `Context` as the dependency `ctx: Ctx`
(server.context); `server.app` includes the routers in this order.
"""
