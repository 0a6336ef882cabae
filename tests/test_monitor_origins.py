"""The live monitor against a page from another origin (issue #20; the bench in
tests/_monitor_page.py): no injection, no read, no WebSocket, and the refusals counted."""

from __future__ import annotations

import ast
import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from _monitor_page import PAGE_MARKS, Monitored, browser, monitored_bench, until

pytestmark = PAGE_MARKS


@pytest.fixture
def monitored(tmp_path: Path) -> Iterator[Monitored]:
    with monitored_bench(tmp_path) as m:
        yield m


ATTACK_HTML = """<!doctype html><html><body><pre id="log"></pre><script>
const log = (t) => { document.getElementById("log").textContent += t + "\\n"; };
const target = "%(target)s";
(async () => {
  for (const headers of [{"Content-Type": "text/plain"}, {}]) {
    try {
      await fetch(target + "api/inject", { method: "POST", mode: "no-cors", headers,
        body: JSON.stringify({ kind: "k_loe", value: 0.3 }) });
      log("post: sent (opaque)");
    } catch (e) { log("post: failed " + e); }
  }
  try {
    const r = await fetch(target + "api/config");
    log("config: read " + (await r.text()).length);
  } catch (e) { log("config: unreadable"); }
  const ws = new WebSocket(target.replace("http", "ws") + "ws");
  ws.onopen = () => log("ws: open");
  ws.onmessage = () => log("ws: data");
  ws.onerror = () => log("ws: error");
  ws.onclose = () => log("ws: closed");
})();
</script></body></html>"""


def test_a_page_from_another_origin_cannot_inject_or_read(monitored: Monitored) -> None:
    """A second origin on 127.0.0.1 (another port: what any site the user opens could do with
    a no-cors request) posts injections to the monitor, tries to read its config and opens its
    WebSocket: nothing reaches the bus (the true k_LOE the monitor shows stays 1), nothing is
    read, and the monitor counts the refusals (printed when it stops)."""
    import http.server
    import threading

    from selenium.webdriver.common.by import By

    page = ATTACK_HTML % {"target": monitored.url}

    class Attack(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = page.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Attack)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    driver = browser()
    try:
        driver.get(f"http://127.0.0.1:{server.server_address[1]}/")  # type: ignore[attr-defined]

        def log() -> str:
            return str(driver.find_element(By.ID, "log").text)  # type: ignore[attr-defined]

        until("the attack finished", lambda: "ws: closed" in log() or "ws: error" in log())
        time.sleep(0.5)
        got = log()
        assert got.count("post: sent (opaque)") == 2, got  # the browser sent them …
        assert "config: unreadable" in got and "ws: open" not in got and "ws: data" not in got, got
        driver.get(monitored.url)  # type: ignore[attr-defined]
        until("the true gains", lambda: "1.000" in driver.find_element(By.ID, "k-true").text)  # type: ignore[attr-defined]
        time.sleep(1.0)
        k_true = str(driver.find_element(By.ID, "k-true").text)  # type: ignore[attr-defined]
        assert k_true.startswith("1.000"), k_true  # … and no injection reached the emulator
    finally:
        driver.quit()  # type: ignore[attr-defined]
        server.shutdown()
    monitored.monitor.terminate()
    assert monitored.monitor.wait() == 0
    refused = re.search(r"monitor: refused (\{.*\})", monitored.monitor.text)
    assert refused is not None, monitored.monitor.text
    counts = ast.literal_eval(refused.group(1))  # the monitor prints a dict of str → int
    assert counts.get("origin", 0) >= 3, counts  # two posts and the WebSocket (config: no CORS)
