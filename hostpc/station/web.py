"""The station's read-only live page (aiohttp): state, progress, the last robots with
their verdicts, and the drift plot of a chosen robot. Refreshes itself every second.

aiohttp serves it because the station already runs an asyncio loop: the page shares it,
with no second thread or framework. Routes: `/` (the page), `/api/state` (JSON),
`/drift/{serial}.png` (plot). Nothing on it changes the station.
"""

from __future__ import annotations

import asyncio
import dataclasses
import html
from typing import Any

from aiohttp import web

from hostpc.archive.drift import drift_findings
from hostpc.archive.history_page import drift_plot_png
from hostpc.station.service import Station

PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>zerocal station {name}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:60em}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:3px 8px}}
#state{{font-size:200%;font-weight:bold}}.PASS{{color:#070}}.FAIL,.ERROR{{color:#b00}}
.RUNNING{{color:#05a}}progress{{width:20em}}</style></head><body>
<h1>zerocal station <span id="name">{name}</span></h1>
<p>state: <span id="state" class="{state}">{state}</span>
 <progress id="progress" max="100" value="0"></progress> <span id="percent"></span></p>
<p>robot: <span id="serial"></span> <span id="model"></span><br>
<small id="line"></small></p>
<h2>Last robots</h2><table id="recent"><tr><th>robot</th><th>model</th><th>started</th>
<th>verdict</th><th>push</th></tr></table>
<h2>Drift of <select id="robot"></select></h2><img id="drift" alt="drift plot">
<script>
let chosen = null;
async function refresh() {{
  const s = await (await fetch('/api/state')).json();
  const st = document.getElementById('state');
  st.textContent = s.state; st.className = s.state;
  document.getElementById('progress').value = s.progress;
  document.getElementById('percent').textContent = s.progress + ' %';
  document.getElementById('serial').textContent = s.serial;
  document.getElementById('model').textContent = s.model;
  document.getElementById('line').textContent = s.last_line;
  const table = document.getElementById('recent');
  table.querySelectorAll('tr.run').forEach(r => r.remove());
  for (const r of s.runs) {{
    const tr = document.createElement('tr'); tr.className = 'run';
    for (const v of [r.serial, r.model, r.started_at, r.verdict, r.push_status]) {{
      const td = document.createElement('td'); td.textContent = v; tr.appendChild(td); }}
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


def build_app(station: Station) -> web.Application:
    async def page(_request: web.Request) -> web.Response:
        return web.Response(text=PAGE.format(name=html.escape(station.config.station),
                                             state=html.escape(station.status.state)),
                            content_type="text/html")

    async def state(_request: web.Request) -> web.Response:
        runs: list[dict[str, Any]] = []
        if station.archive is not None:
            runs = await asyncio.to_thread(station.archive.runs)
        latest = list(reversed(runs))[:20]
        body = dataclasses.asdict(station.status)
        body["runs"] = [{k: r[k] for k in ("id", "serial", "model", "started_at", "verdict",
                                           "push_status")} for r in latest]
        return web.json_response(body)

    async def drift(request: web.Request) -> web.Response:
        serial = request.match_info["serial"]
        if station.archive is None:
            raise web.HTTPNotFound()
        runs = await asyncio.to_thread(station.archive.runs, serial)
        if not runs:
            raise web.HTTPNotFound(text=f"no runs of {serial}")
        png = await asyncio.to_thread(drift_plot_png, runs, drift_findings(runs))
        return web.Response(body=png, content_type="image/png")

    app = web.Application()
    app.add_routes([web.get("/", page), web.get("/api/state", state),
                    web.get("/drift/{serial}.png", drift)])
    return app


async def serve_page(station: Station, host: str, port: int) -> web.AppRunner:
    runner = web.AppRunner(build_app(station), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    return runner
