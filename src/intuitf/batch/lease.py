"""The batch driver's lease: workers stop sending the moment their driver is gone.

A Ray worker outlives a killed driver until Ray notices (seconds, on a busy machine longer),
and meanwhile keeps asking the model, paying for answers nobody will read. So the driver
listens on a TCP port and every worker holds a connection to it: when the driver process
dies, however it dies (``kill -9`` included), its operating system closes those connections
at once. A worker looks at its connection before each comparison (a non-blocking peek: no
round trip) and, in the background, waits on it; on end-of-file it cancels its runs between
two matches and refuses further comparisons. Nothing is ever sent on the connection.

A worker that cannot connect (a firewall between the nodes) logs it and goes on without a
lease, as before. A local Ray instance the batch started is shut down by a small reaper
process when the driver dies without shutting it down itself (:func:`start_reaper`).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import subprocess
import sys
import threading

from intuitf.errors import RunCancelled

log = logging.getLogger(__name__)


class DriverLease:
    """The driver's side: a listening socket whose connections live as long as this process.

    ``address`` ("host:port") is what workers connect to; ``host`` defaults to this node's
    address as Ray sees it when given, else loopback.
    """

    def __init__(self, host: str = "127.0.0.1") -> None:
        self._server = socket.create_server(("0.0.0.0" if host != "127.0.0.1" else host, 0))
        self.address = f"{host}:{self._server.getsockname()[1]}"
        self._held: list[socket.socket] = []
        self._closed = False
        self._thread = threading.Thread(target=self._accept, daemon=True, name="batch-lease")
        self._thread.start()

    def _accept(self) -> None:
        while not self._closed:
            try:
                conn, _ = self._server.accept()
            except OSError:
                return
            self._held.append(conn)  # held open, never written: its end is the signal

    def close(self) -> None:
        """End the lease (the batch is done): workers see it end like a dead driver's."""
        self._closed = True
        for s in [self._server, *self._held]:
            try:
                s.close()
            except OSError:
                pass


class LeaseWatch:
    """The worker's side: a connection to the driver's lease, and whether it still stands."""

    def __init__(self, address: str, timeout: float = 5.0) -> None:
        host, _, port = address.rpartition(":")
        self.gone = False
        self.sock: socket.socket | None = None
        try:
            self.sock = socket.create_connection((host, int(port)), timeout=timeout)
            self.sock.setblocking(False)
        except OSError as exc:
            log.warning("No lease from the batch driver at %s (%s): going on without.",
                        address, exc)  # fmt: skip

    def alive(self) -> bool:
        """False (for good) once the driver's end of the connection has closed."""
        if self.gone or self.sock is None:
            return not self.gone
        try:
            data = self.sock.recv(1, socket.MSG_PEEK)
        except (BlockingIOError, InterruptedError):
            return True  # open, nothing to read: the driver lives
        except OSError:
            data = b""
        if data == b"":
            self.gone = True
        return not self.gone

    async def wait_gone(self) -> None:
        """Return when the driver's end closes (never, without a connection)."""
        if self.sock is None:
            await asyncio.Event().wait()
            return
        loop = asyncio.get_running_loop()
        while self.alive():
            try:
                await loop.sock_recv(self.sock, 1)  # returns b"" at the end
            except OSError:
                pass
            if not self.alive():
                return
            await asyncio.sleep(0.05)  # unreachable in practice: the driver never sends


class LeasedJudge:
    """A judge that asks only while the driver's lease is alive."""

    def __init__(self, judge, watch: LeaseWatch, on_gone) -> None:
        self._judge = judge
        self._watch = watch
        self._on_gone = on_gone
        self.name = getattr(judge, "name", type(judge).__name__)
        # Checked again as each request leaves: comparisons that passed the check below and
        # then waited for the judge's concurrency are stopped too, not sent after the end.
        add_gate = getattr(judge, "add_send_gate", None)
        if add_gate is not None:
            add_gate(self._check)

    def _check(self) -> None:
        if not self._watch.alive():
            self._on_gone()
            raise RunCancelled("The batch driver is gone; this run stops and resumes later.")

    async def compare(self, first, second, aspects, intent):
        self._check()
        return await self._judge.compare(first, second, aspects, intent)

    def __getattr__(self, name: str):
        return getattr(self._judge, name)


_REAPER = r"""
import os, signal, sys, time

pids = [int(p) for p in sys.argv[1:]]
data = sys.stdin.buffer.read()  # EOF: the driver is gone (or done)
if data.strip().endswith(b"done"):
    sys.exit(0)

def tree(pid):
    out = [pid]
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as fh:
                for child in fh.read().split():
                    out += tree(int(child))
    except OSError:
        pass
    return out

victims = [p for pid in pids for p in tree(pid)]
for sig in (signal.SIGTERM, signal.SIGKILL):
    for p in victims:
        try:
            os.kill(p, sig)
        except OSError:
            pass
    time.sleep(2.0)
"""


class Reaper:
    """A process that takes a local Ray instance down when the driver that started it dies.

    The driver holds the write end of the reaper's stdin; its death closes it. A driver that
    ends normally shuts Ray down itself and tells the reaper (:meth:`close`) to leave.
    """

    def __init__(self, pids: list[int]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _REAPER, *map(str, pids)],
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # a Ctrl-C or kill of the driver's group spares it
        )

    def close(self) -> None:
        try:
            self.proc.stdin.write(b"done")  # type: ignore[union-attr]
            self.proc.stdin.close()  # type: ignore[union-attr]
            self.proc.wait(5)
        except (OSError, subprocess.TimeoutExpired):
            pass


def start_reaper(ray) -> Reaper | None:
    """A :class:`Reaper` for the local Ray instance this process started (None elsewhere)."""
    try:
        node = ray._private.worker._global_node
        pids = [p.process.pid for procs in node.all_processes.values() for p in procs]
    except Exception:  # noqa: BLE001 - Ray internals differ between versions
        return None
    if not pids or not sys.platform.startswith("linux"):
        return None
    return Reaper(pids)
