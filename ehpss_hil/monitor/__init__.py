"""The live bench monitor (``ehpss-hil monitor``, docs/monitor.md).

- :mod:`.state` — what the bus says, folded into the latest values, counters, rates and a
  decimated series of rows (pure: frames in, snapshots out, no I/O);
- :mod:`.reference` — x_d and y_m at the controller's sample index, from its config;
- :mod:`.listener` — the thread that reads and decodes the bus (optionally inside a run's
  network namespace) and sends the page's FAULT_INJECT frames;
- :mod:`.server` — the local web page (aiohttp; uPlot served from ``static/``) and its WebSocket;
- :mod:`.tui` — the same figures as text in a terminal.
"""
