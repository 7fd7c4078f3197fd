"""Long single-threaded computations of the suite, started in the background when the session
starts and run at the lowest priority, on the core the suite leaves idle.

Most of the suite keeps one of the machine's two cores busy (the test process, or the
server it waits for); a few tests each wait minutes for one single-threaded program
(ArgyllCMS's colprof making a media's profiles, the shipped masks' generators).  A test
module declares those computations in a module-level dict::

    BACKGROUND = {"test_function_name": ("key", [argv...], {"ENV": "value"})}

and tests/conftest.py queues every one whose test is in the run as soon as collection ends
(`declared`), in the order of their tests: they run two at a time (RUNNERS), each a
process at niceness 19, so each takes only the CPU the other tests do not want and slows
neither them nor their timing assertions, and the ones needed first are done first.  The
test takes the result with the `background` fixture (`background.output(key)`), starting
it at once if its turn has not come and waiting for it if it is not done (the process then
runs at the ordinary priority where the user may raise it: it is what the run waits for).
A computation whose own duration a test asserts does not belong here: its figure would be
the idle core's, not the machine's.  In argv and env values, `{dir}` is a folder of the
key's own."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

#: the background's niceness; WIDEPRINT_TEST_BACKGROUND_NICE=0 measures the suite as on a
#: quiet machine when other sessions' work shares the cores (bench/README.md "The test suite")
NICE = int(os.environ.get("WIDEPRINT_TEST_BACKGROUND_NICE", "19"))
#: processes of the queue running at once: the machine's two cores
RUNNERS = 2


class Background:
    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="wideprint-test-background-"))
        self.procs: dict[str, subprocess.Popen] = {}
        self.queue: list[tuple[str, list[str], dict[str, str]]] = []
        self._lock = threading.Lock()
        self._closed = False
        self._next = 0
        self._runners = 0

    def folder(self, key: str) -> Path:
        return self.root / key

    def submit(self, key: str, argv: list[str], env: dict[str, str] | None = None) -> None:
        """Queue `argv` under `key` (once per key); RUNNERS processes of the queue run at once."""
        with self._lock:
            if any(k == key for k, _, _ in self.queue):
                return
            self.queue.append((key, argv, dict(env or {})))
            if self._runners < RUNNERS:
                self._runners += 1
                threading.Thread(target=self._run_queue, name="background", daemon=True).start()

    def _run_queue(self) -> None:
        while True:
            with self._lock:
                while self._next < len(self.queue) and self.queue[self._next][0] in self.procs:
                    self._next += 1                     # started already by output()
                if self._closed or self._next >= len(self.queue):
                    self._runners -= 1
                    return
                proc = self._start(self.queue[self._next][0])
                self._next += 1
            proc.wait()

    def _start(self, key: str) -> subprocess.Popen:
        """The key's process, started now at niceness NICE if it was not (the lock held);
        stdout and stderr to DIR/out, err."""
        if key in self.procs:
            return self.procs[key]
        argv, env = next((a, e) for k, a, e in self.queue if k == key)
        d = self.folder(key)
        d.mkdir(parents=True)
        sub = {k: v.replace("{dir}", str(d)) for k, v in env.items()}
        with open(d / "out", "wb") as out, open(d / "err", "wb") as err:
            self.procs[key] = subprocess.Popen(
                [a.replace("{dir}", str(d)) for a in argv], stdout=out, stderr=err,
                env={**os.environ, **sub}, preexec_fn=lambda: os.nice(NICE))
        return self.procs[key]

    def output(self, key: str, timeout: float = 1800) -> str:
        """The computation's stdout once it ended (it must succeed)."""
        with self._lock:
            assert any(k == key for k, _, _ in self.queue), \
                f"{key}: not queued (its test is not in a BACKGROUND?)"
            proc = self._start(key)
        if proc.poll() is None:                  # a test waits for it: no longer background
            try:
                os.setpriority(os.PRIO_PROCESS, proc.pid, 0)
            except OSError:
                pass                             # lowering a niceness needs CAP_SYS_NICE
        rc = proc.wait(timeout=timeout)
        assert rc == 0, f"{key} exited {rc}:\n" + (self.folder(key) / "err").read_text()
        return (self.folder(key) / "out").read_text()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            procs = list(self.procs.values())
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        shutil.rmtree(self.root, ignore_errors=True)


def declared(items) -> list[tuple[str, list[str], dict[str, str]]]:
    """The BACKGROUND entries of the test modules whose tests are among `items`, in their
    order."""
    out = []
    for item in items:
        table = getattr(getattr(item, "module", None), "BACKGROUND", None)
        name = getattr(item, "originalname", None) or item.name
        if table and name in table:
            out.append(table[name])
    return out
