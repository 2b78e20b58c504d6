"""The station's read-only live page (aiohttp): state, progress, the last robots with
their verdicts, and the drift plot of a chosen robot. Refreshes itself every second.

It shows exactly the station's state (`StationStatus`): the progress bar and the run's
output line only while a run is RUNNING; the last run's verdict, result code, one-line
reason and report link until the PLC acknowledges it; an IDLE station shows "idle" and
nothing of the last run (the table of last robots keeps it, with its report).

aiohttp serves it because the station already runs an asyncio loop: the page shares it,
with no second thread or framework. Routes: `/` (the page), `/api/state` (JSON),
`/drift/{serial}.png` (plot), `/runs/{id}/report.html` (an archived run's report).
Nothing on it changes the station.

Against hostile peers (docs/security.md): the page listens through a `ConnectionGuard`
(at most `MAX_CONNECTIONS`, `MAX_PER_ADDRESS` per peer address, a connection that completes
no request within `FIRST_REQUEST_TIMEOUT_S` or none for `IDLE_TIMEOUT_S` is closed, silent
ones evicted first), aiohttp closes keep-alive connections after `KEEPALIVE_TIMEOUT_S`, and
drift plots are rendered one at a time on their own thread, once per robot and archive
state (`DriftPlots`), so a burst of plot requests neither renders twice nor starves the
state requests. aiohttp's and asyncio's log is rate-limited, one line per record.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import html
import logging
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from aiohttp import web

from hostpc.archive.drift import drift_findings
from hostpc.archive.history_page import drift_plot_png, local_time
from hostpc.archive.rows import ArchivedRun
from hostpc.json_object import JsonObject
from hostpc.serving.guard import ConnectionGuard, GuardedConnection
from hostpc.serving.log_limits import SERVER_LOGGERS, limit_logging
from hostpc.station.service import Station
from protocol.connection_table import ConnectionTable

logger = logging.getLogger("hostpc.station.web")

MAX_CONNECTIONS = 64
MAX_PER_ADDRESS = 32
FIRST_REQUEST_TIMEOUT_S = 10.0
"""A connection that sends no whole request head this long after connecting is closed (s)."""
IDLE_TIMEOUT_S = 30.0
"""A connection without a new request for this long is closed (s); a slowloris that dribbles
a header byte at a time counts as idle."""
KEEPALIVE_TIMEOUT_S = 15.0
PLOT_CACHE_SIZE = 32

PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>zerocal station {name}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:60em}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:3px 8px}}
#state{{font-size:200%;font-weight:bold}}.PASS{{color:#070}}.FAIL,.ERROR{{color:#b00}}
.RUNNING{{color:#05a}}progress{{width:20em}}</style></head><body>
<h1>zerocal station <span id="name">{name}</span></h1>
<p>state: <span id="state" class="{state}">{state}</span>
 <span id="running" hidden><progress id="progress" max="100" value="0"></progress>
 <span id="percent"></span></span></p>
<p id="robot-line" hidden>robot: <span id="serial"></span> <span id="model"></span><br>
<small id="line"></small></p>
<p id="result" hidden>result code <span id="code"></span>
<span id="reason-line">: <span id="reason"></span></span>
<a id="report" href="">report</a></p>
<h2>Last robots</h2><table id="recent"><tr><th>robot</th><th>model</th><th>started</th>
<th>verdict</th><th>push</th><th>reason</th><th>report</th></tr></table>
<h2>Drift of <select id="robot"></select></h2><img id="drift" alt="drift plot">
<script>
let chosen = null;
async function refresh() {{
  const s = await (await fetch('/api/state')).json();
  const st = document.getElementById('state');
  st.textContent = s.state; st.className = s.state;
  const running = s.state === 'RUNNING', finished = ['PASS', 'FAIL', 'ERROR'].includes(s.state);
  document.getElementById('running').hidden = !running;
  document.getElementById('progress').value = running ? s.progress : 0;
  document.getElementById('percent').textContent = running ? s.progress + ' %' : '';
  document.getElementById('robot-line').hidden = s.state === 'IDLE';
  document.getElementById('serial').textContent = s.serial;
  document.getElementById('model').textContent = s.model;
  document.getElementById('line').textContent = running ? s.last_line : '';
  document.getElementById('result').hidden = !finished;
  document.getElementById('code').textContent = finished ? s.result_code : '';
  document.getElementById('reason-line').hidden = !s.reason;
  document.getElementById('reason').textContent = finished ? s.reason : '';
  const report = document.getElementById('report');
  report.hidden = !(finished && s.report);
  report.setAttribute('href', finished && s.report ? s.report : '');
  const table = document.getElementById('recent');
  table.querySelectorAll('tr.run').forEach(r => r.remove());
  for (const r of s.runs) {{
    const tr = document.createElement('tr'); tr.className = 'run';
    for (const v of [r.serial, r.model, r.started_at, r.verdict, r.push_status,
                     r.reason || '']) {{
      const td = document.createElement('td'); td.textContent = v; tr.appendChild(td); }}
    const td = document.createElement('td');
    if (r.report) {{ const a = document.createElement('a'); a.href = r.report;
      a.textContent = 'report'; a.className = 'report'; td.appendChild(a); }}
    tr.appendChild(td);
    tr.children[3].className = r.verdict; table.appendChild(tr);
  }}
  const select = document.getElementById('robot');
  const serials = [...new Set(s.runs.map(r => r.serial))];
  if (select.options.length !== serials.length) {{
    select.innerHTML = '';
    for (const x of serials) {{ const o = document.createElement('option');
      o.value = x; o.textContent = x; select.appendChild(o); }}
  }}
  if (select.value && select.value !== chosen) {{
    chosen = select.value;
    document.getElementById('drift').src =
      '/drift/' + encodeURIComponent(chosen) + '.png?' + s.runs_done;
  }}
}}
document.getElementById('robot').addEventListener('change', () => {{ chosen = null; refresh(); }});
refresh(); setInterval(refresh, 1000);
</script></body></html>"""


class DriftPlots:
    """Drift plot PNGs by (serial, the robot's archived runs: count and last id): rendered
    once, on one thread of their own, concurrent requests for the same plot waiting for the
    same rendering; at most PLOT_CACHE_SIZE kept (least recently used dropped)."""

    def __init__(self) -> None:
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="drift-plot")
        self._plots: collections.OrderedDict[tuple[object, ...], asyncio.Future[bytes]] = (
            collections.OrderedDict())
        self.rendered = 0

    async def png(self, serial: str, runs: list[ArchivedRun]) -> bytes:
        key = (serial, len(runs), max(r.id for r in runs))
        plot = self._plots.get(key)
        if plot is None or (plot.done() and plot.exception() is not None):
            plot = asyncio.get_running_loop().run_in_executor(self._executor, self._render, runs)
            self._plots[key] = plot
            while len(self._plots) > PLOT_CACHE_SIZE:
                self._plots.popitem(last=False)
        self._plots.move_to_end(key)
        return await asyncio.shield(plot)

    def _render(self, runs: list[ArchivedRun]) -> bytes:
        self.rendered += 1
        return drift_plot_png(runs, drift_findings(runs))

    def close(self) -> None:
        self._executor.shutdown(wait=False, cancel_futures=True)


def _listed(run: ArchivedRun) -> JsonObject:
    """A run as /api/state lists it (the page's table of last robots)."""
    return {"id": run.id, "serial": run.serial, "model": run.model, "verdict": run.verdict,
            "push_status": run.push_status, "reason": run.reason,
            "started_at": local_time(run.started_at),
            "report": f"/runs/{run.id}/report.html" if run.report_path else None}


def build_app(station: Station, guard: ConnectionGuard | None = None,
              plots: DriftPlots | None = None) -> web.Application:
    plots = plots if plots is not None else DriftPlots()

    @web.middleware
    async def count_request(request: web.Request,
                            handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                            ) -> web.StreamResponse:
        connection = guard.connection_of(request.transport) if guard is not None else None
        if connection is not None:
            connection.request_done()
        return await handler(request)

    async def page(_request: web.Request) -> web.Response:
        return web.Response(text=PAGE.format(name=html.escape(station.config.station),
                                             state=html.escape(station.status.state)),
                            content_type="text/html")

    async def state(_request: web.Request) -> web.Response:
        runs: list[ArchivedRun] = []
        if station.archive is not None:
            runs = await asyncio.to_thread(station.archive.runs)
        body = dataclasses.asdict(station.status)
        body["runs"] = [_listed(run) for run in list(reversed(runs))[:20]]
        return web.json_response(body)

    async def report(request: web.Request) -> web.StreamResponse:
        run_id = request.match_info["run_id"]
        if station.archive is None or not run_id.isdigit() or len(run_id) > 10:
            raise web.HTTPNotFound()
        path = await asyncio.to_thread(station.archive.report_path, int(run_id))
        if not path:
            raise web.HTTPNotFound(text=f"run {run_id}: no report archived")
        try:
            text = await asyncio.to_thread(Path(path).read_bytes)
        except OSError:
            raise web.HTTPNotFound(text=f"run {run_id}: its report {path} is gone") from None
        return web.Response(body=text, content_type="text/html", charset="utf-8")

    async def drift(request: web.Request) -> web.Response:
        serial = request.match_info["serial"]
        if station.archive is None:
            raise web.HTTPNotFound()
        runs = await asyncio.to_thread(station.archive.runs, serial)
        if not runs:
            raise web.HTTPNotFound(text=f"no runs of {serial}")
        png = await plots.png(serial, runs)
        return web.Response(body=png, content_type="image/png")

    app = web.Application(middlewares=[count_request])
    app.add_routes([web.get("/", page), web.get("/api/state", state),
                    web.get("/drift/{serial}.png", drift),
                    web.get("/runs/{run_id}/report.html", report)])
    return app


class LivePage:
    """The served page: its bound address, its guard (counters), `cleanup()` to stop."""

    def __init__(self, runner: web.AppRunner, guard: ConnectionGuard, plots: DriftPlots,
                 address: tuple[str, int]) -> None:
        self.runner, self.guard, self.plots, self.address = runner, guard, plots, address

    async def cleanup(self) -> None:
        await self.guard.close()
        await self.runner.cleanup()
        self.plots.close()


async def serve_page(station: Station, host: str, port: int, *,
                     max_connections: int = MAX_CONNECTIONS,
                     max_per_address: int = MAX_PER_ADDRESS,
                     first_request_timeout_s: float = FIRST_REQUEST_TIMEOUT_S,
                     idle_timeout_s: float = IDLE_TIMEOUT_S) -> LivePage:
    """Serve the page on host:port (0: a free port) behind the connection guard."""
    limit_logging(*SERVER_LOGGERS, logger.name)
    plots = DriftPlots()
    runner: web.AppRunner | None = None

    def handler(_connection: GuardedConnection) -> asyncio.Protocol:
        assert runner is not None and runner.server is not None
        return runner.server()

    guard = ConnectionGuard(
        "page", ConnectionTable(max_connections, max_per_address, first_request_timeout_s,
                                idle_timeout_s), handler, logger)
    runner = web.AppRunner(build_app(station, guard, plots), access_log=None,
                           keepalive_timeout=KEEPALIVE_TIMEOUT_S)
    await runner.setup()
    try:
        address = await guard.listen(host, port)
    except OSError:
        await runner.cleanup()
        plots.close()
        raise
    return LivePage(runner, guard, plots, address)
