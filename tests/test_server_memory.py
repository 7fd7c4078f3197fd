"""A print server runs for days: what its in-process emulators keep is bounded
(app/server/worker.py EMULATOR_EVENTS_KEPT; the 30-minute GUI soak's RSS grew with each
emulated printer's event deque of 200,000 records, ~350 B each)."""

import numpy as np
import tifffile

from wideprint.app.client import Client
from wideprint.app.server.worker import EMULATOR_EVENTS_KEPT


def test_a_server_emulator_keeps_a_bounded_event_log(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    srv = PrintServer(ServerConfig(state_dir=tmp_path / "state", media_dir=tmp_path / "m",
                                   port=0))
    srv.start()
    client = Client(srv.state_dir)
    try:
        src = tmp_path / "a.tif"
        tifffile.imwrite(src, np.full((40, 80, 4), 90, np.uint8), photometric="separated")
        job = client.submit(src, settings={"placement": {"size": "pixels"}})["job"]
        assert client.wait(job["id"], 120)["state"] == "done"
        emulators = [w.dev.emulator for w in srv.workers.values() if w.dev is not None]
        assert emulators and all(e.events.maxlen == EMULATOR_EVENTS_KEPT for e in emulators)
        assert EMULATOR_EVENTS_KEPT <= 20_000
        assert any(e["event"] == "job_end" for e in emulators[0].events)   # still a log
    finally:
        client.close()
        srv.stop(timeout=5)
