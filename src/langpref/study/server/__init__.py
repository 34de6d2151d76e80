"""The running web app: the HTTP contract (docs/design.md) over a `session` and the `protocol`'s database, and
what a server process needs around it. May import `protocol`, `session` and (the admin's export, lazily)
`analysis`; nothing below imports it (tests/test_layout.py holds it).

settings.py      ServeConfig, VideoConfig, SimulateConfig: the options of `study serve` and `study simulate`
state.py         StudyApp: what every request shares (database, engine, videos, locks, rate limits)
participants.py  the participants' router: join, resume, step, answer, videos
admin.py         the lab's router: dashboard data, exclusions, export, status (admin token)
pages.py         the pages, static files, /healthz and /api/info (`study/templates`, `study/static`)
app.py           create_app: the routers behind the Host/cross-site checks, security headers, errors
guard.py         what is refused before a request reaches the study (sizes, nesting, hosts, rate limits)
transport.py     one send per response (uvicorn's HTTP protocol, joined writes)
videos.py        render cache with background pre-rendering
hook.py          the `--on-show` hook: a command run before each trajectory is shown (a real robot)
watchdog.py      the hook's runs killed when the server dies
serve.py         starting a server (CLI, tests)
simulate.py      simulated participants over HTTP, the contract's other side (load test, benchmark, demo data)
"""
