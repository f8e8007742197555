"""Running a batch: one run per volume, on a local process pool or on Ray, resumable.

**Workers.** A worker is a process (pool) or a Ray actor. Each drives up to ``per_worker``
volumes at once in one event loop: their renders take turns on the process's render thread
(CPU), while their judge calls (I/O) are all in flight together, so a worker is rarely idle
waiting for a model. The driver hands each worker a new volume whenever it has room.

**Each volume** gets its own run folder ``DIR/runs/KEY`` driven through
:meth:`Session.open` (new) or :meth:`Session.resume` (unfinished), whose lock keeps it to one
process. Its first population holds the reference TF carried to this volume
(:mod:`intuitf.batch.transfer`), or the volume's default TF when there is none to carry. Its judge checks the batch's shared budget before every call
(:class:`~intuitf.batch.budget.SharedBudget`) and, with a rate limit, waits for its turn
(:class:`JudgeLimiter`). When it ends, its result (status, similarity of its best rendering to
the reference picture, calls, cost, time) is written to ``DIR/results/KEY.json``.

**Resuming.** Run the same command again (or ``intuitf batch --resume DIR``): finished volumes
are skipped, unfinished ones resumed from their checkpoints, with every answer already paid for
taken from their verdict stores. A volume that cannot be read is reported and skipped.

**Failures.** A volume whose run stops for its judge (the model server down) or fails with an
error, or whose worker is lost, is tried again, up to ``max_failures`` more times in one pass
(as Ray Tune's ``max_failures``), each retry a resume with nothing repeated and a little later
than the last (2, 4, 8 ... s); only then is it reported failed.

**Stopping.** Ctrl-C cancels every run between two matches (each is resumed later with nothing
repeated); a killed batch takes its worker processes with it and resumes the same way.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from intuitf.batch.lease import DriverLease, LeasedJudge, LeaseWatch, start_reaper
from intuitf.batch.plan import VolumeItem
from intuitf.errors import IntuitfError, RenderError, TransferFunctionError, VolumeError
from intuitf.session.rundir import RunDirectory

log = logging.getLogger(__name__)

#: Statuses a volume can end a batch pass with.
FINISHED = "completed"
#: Statuses after which a volume is tried again (a resume), up to ``max_failures`` times.
RETRYABLE = ("judge", "failed", "storage")
#: How many times a volume is tried again after a failure, by default.
DEFAULT_MAX_FAILURES = 2
#: A volume's n-th retry waits this many seconds times 2**(n-1) (a judge may come back).
RETRY_WAIT_S = 2.0
#: Seconds to wait for a Ray cluster to answer (``--ray-timeout``).
DEFAULT_RAY_TIMEOUT = 30.0
RAY_HINT = 'pip install "intuitf[ray]" (or pip install ray)'


@dataclass
class BatchConfig:
    """What every worker needs to run any volume of the batch (plain, picklable data)."""

    root: str
    #: RunSpec fields shared by every volume: intent, judge and settings.
    template: dict
    #: Reader options (max_dim, shape, dtype, ...) for every volume.
    reader: dict = field(default_factory=dict)
    #: Seed each first population with the reference TF carried to the volume.
    carry: bool = True
    per_worker: int = 4
    #: Judge requests in flight per worker (None: no limit beyond the judge's own).
    max_in_flight: int | None = None
    #: Judge requests per second per worker (None: no limit).
    rate_per_s: float | None = None
    numba_threads: int | None = None
    #: "host:port" of the driver's lease (Ray: workers may outlive the driver); None: none.
    lease: str | None = None

    @property
    def uses_model(self) -> bool:
        return str(self.template.get("judge", {}).get("spec", "metric")) != "metric"


def runs_dir(root: str | Path) -> Path:
    return Path(root) / "runs"


def results_dir(root: str | Path) -> Path:
    return Path(root) / "results"


def read_result(root: str | Path, key: str) -> dict | None:
    p = results_dir(root) / f"{key}.json"
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None


def write_result(root: str | Path, result: dict) -> None:
    from intuitf.session.rundir import atomic_write_json

    atomic_write_json(results_dir(root) / f"{result['key']}.json", result)


def is_finished(root: str | Path, key: str) -> bool:
    """The volume's run completed and its result and best rendering are there."""
    res = read_result(root, key)
    return bool(
        res
        and res.get("status") == FINISHED
        and RunDirectory(runs_dir(root) / key).best_file(1, ".png").exists()
    )


def _base_result(item: VolumeItem) -> dict:
    return {
        "key": item.key,
        "label": item.label,
        "source": item.source,
        "kind": item.kind,
        "status": "pending",
        "message": "",
        "generations_done": 0,
        "generations": None,
        "calls": 0,
        "cached_calls": 0,
        "cost_usd": 0.0,
        "seconds": 0.0,
        "render_s": 0.0,
        "judge_s": 0.0,
        "open_s": 0.0,
        "outputs_s": 0.0,
        "similarity": None,
        "start_similarity": None,
        "best_png": None,
        "best_tf": None,
        "run_dir": None,
        "attempts": 0,
    }


# -- limiting judge calls per worker ----------------------------------------------------------
class JudgeLimiter:
    """At most ``max_in_flight`` comparisons at once and ``rate_per_s`` started per second, for
    all the runs of one worker (a provider's limit, divided among the workers)."""

    def __init__(self, max_in_flight: int | None = None, rate_per_s: float | None = None) -> None:
        self.max_in_flight = max_in_flight
        self.rate_per_s = rate_per_s
        self._sem: asyncio.Semaphore | None = None
        self._next = 0.0
        self._lock: asyncio.Lock | None = None

    async def __aenter__(self) -> JudgeLimiter:
        if self.max_in_flight:
            if self._sem is None:
                self._sem = asyncio.Semaphore(int(self.max_in_flight))
            await self._sem.acquire()
        if self.rate_per_s:
            if self._lock is None:
                self._lock = asyncio.Lock()
            async with self._lock:
                now = time.monotonic()
                start = max(now, self._next)
                self._next = start + 1.0 / float(self.rate_per_s)
            if start > now:
                await asyncio.sleep(start - now)
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._sem is not None:
            self._sem.release()


class ThrottledJudge:
    """A judge that waits for the worker's :class:`JudgeLimiter` before each comparison."""

    def __init__(self, judge: Any, limiter: JudgeLimiter) -> None:
        self._judge = judge
        self._limiter = limiter
        self.name = getattr(judge, "name", type(judge).__name__)

    async def compare(self, first, second, aspects, intent):
        async with self._limiter:
            return await self._judge.compare(first, second, aspects, intent)

    def __getattr__(self, name: str):
        return getattr(self._judge, name)


# -- one volume --------------------------------------------------------------------------------
class _Timing:
    """Where a run's time goes: renders (busy time on the render thread) and judging (from the
    end of a generation's renders to its end)."""

    def __init__(self, session) -> None:
        self.render_s = 0.0
        self.judge_s = 0.0
        self._rendered_at: float | None = None
        remove = session.on_render(self._rendered)  # the Session's render-timing hook
        unsubscribe = session.events.subscribe(self._on_event)

        def both() -> None:
            remove()
            unsubscribe()

        self.unsubscribe = both

    def _rendered(self, seconds: float) -> None:
        self.render_s += seconds

    def _on_event(self, e) -> None:
        if e.type == "rendered":
            self._rendered_at = time.perf_counter()
        elif e.type in ("generation_ended", "run_ended") and self._rendered_at is not None:
            self.judge_s += time.perf_counter() - self._rendered_at
            self._rendered_at = None


class WorkerCore:
    """Runs volumes of a batch inside one event loop (a pool process or a Ray actor)."""

    def __init__(self, config: BatchConfig, ledger: Any = None) -> None:
        from intuitf.batch.reference import Reference

        self.config = config
        self.root = Path(config.root)
        self.ledger = ledger if config.uses_model else None
        self.reference = Reference.load_saved(self.root / "reference")
        self.limiter = (
            JudgeLimiter(config.max_in_flight, config.rate_per_s)
            if config.max_in_flight or config.rate_per_s
            else None
        )
        self.active: dict[str, Any] = {}
        self.stopping = False
        self.watch = LeaseWatch(config.lease) if config.lease else None
        self._watching: asyncio.Task | None = None

    async def _watch_driver(self) -> None:
        """Stop every run as soon as the driver's lease ends (it was killed)."""
        if self.watch is None:
            return
        await self.watch.wait_gone()
        if not self.stopping:
            log.warning("The batch driver is gone: stopping this worker's runs.")
            self.stop()

    def stop(self) -> None:
        """Cancel every run between two matches (each is resumed later, nothing repeated)."""
        self.stopping = True
        for session in list(self.active.values()):
            try:
                session.cancel()
            except Exception:  # noqa: BLE001 - stopping must reach every run
                pass

    async def run(self, item: VolumeItem) -> dict:
        """Run (or resume, or skip) one volume; never raises: the result says what happened."""
        t0 = time.perf_counter()
        if self.watch is not None and self._watching is None:
            self._watching = asyncio.get_running_loop().create_task(self._watch_driver())
        prev = read_result(self.root, item.key) or {}
        # What an earlier pass recorded stands until this one has better figures: a volume
        # that stops at once (the budget spent before its turn) keeps its calls, generations
        # and similarity instead of reporting zeros.
        drop = ("status", "message", "skipped", "permanent", "lost", "retries", "worker")
        kept = {k: v for k, v in prev.items() if k not in drop}
        result = {**_base_result(item), **kept}
        result["attempts"] = int(result.get("attempts") or 0)
        try:
            result = await self._run(item, result)
        except (VolumeError, TransferFunctionError, RenderError) as exc:
            # The volume itself is unusable: trying again would fail the same way.
            result.update(status="failed", message=_message(exc), permanent=True)
        except IntuitfError as exc:
            result.update(status="failed", message=_message(exc))
        except Exception as exc:  # noqa: BLE001 - one volume's bug must not stop the batch
            log.error("volume %s failed:\n%s", item.key, traceback.format_exc())
            result.update(status="failed", message=f"{type(exc).__name__}: {exc}")
        result["seconds"] = float(result.get("seconds") or 0.0) + (time.perf_counter() - t0)
        result["worker"] = os.getpid()
        try:
            write_result(self.root, result)
        except IntuitfError as exc:
            result["message"] = (result.get("message") or "") + f" (result not saved: {exc})"
        return result

    async def _run(self, item: VolumeItem, result: dict) -> dict:
        from intuitf.session import Session

        rd = runs_dir(self.root) / item.key
        result["run_dir"] = str(rd)
        if is_finished(self.root, item.key):
            prev = read_result(self.root, item.key) or {}
            prev.pop("seconds", None)
            return {**result, **prev, "skipped": True, "seconds": 0.0}
        if self.stopping:
            return {**result, "status": "interrupted", "message": "The batch was stopped first."}
        if self.ledger is not None and self.ledger.totals().exhausted:
            status = "budget"
            return {**result, "status": status,
                    "message": "The batch's budget was spent before this volume's turn."}  # fmt: skip
        result["attempts"] += 1
        t_open = time.perf_counter()
        if RunDirectory(rd).exists():
            session = await asyncio.to_thread(Session.resume, rd)
        else:
            session, start_sim = await asyncio.to_thread(self._open, item, rd)
            result["start_similarity"] = start_sim
        open_s = time.perf_counter() - t_open
        outputs_s = 0.0
        self.active[item.key] = session
        try:
            if self.ledger is not None:
                from intuitf.batch.budget import attach_shared_budget

                attach_shared_budget(session.judge, self.ledger, item.key)
            if self.limiter is not None:
                limiter = self.limiter
                session.add_judge_middleware(lambda judge: ThrottledJudge(judge, limiter))
            if self.watch is not None:  # checked before each comparison
                watch = self.watch
                session.add_judge_middleware(lambda judge: LeasedJudge(judge, watch, self.stop))
            timing = _Timing(session)
            if self.stopping:
                session.cancel()
            # The outputs (best renderings, plots, exports, report) are written on a thread,
            # so that the worker's other runs keep asking the judge meanwhile.
            outcome = await session.arun(write_outputs=False)
            timing.unsubscribe()
            if session.last_ranking:
                t_out = time.perf_counter()
                try:
                    await asyncio.to_thread(session.write_outputs)
                    outputs_s = time.perf_counter() - t_out
                except IntuitfError as exc:  # e.g. a full disk: the run itself is kept
                    outcome.reason = "storage"
                    outcome.message = f"{outcome.message} Saving outputs failed: {exc}"
        finally:
            self.active.pop(item.key, None)
            await session.aclose()
        c = outcome.cost
        result.update(
            status=outcome.reason,
            message=outcome.message,
            generations_done=outcome.generations_done,
            generations=session.total_generations,
            calls=int(c.calls),
            cached_calls=int(c.cached_calls),
            cost_usd=float(c.usd),
            render_s=float(result.get("render_s") or 0.0) + timing.render_s,
            judge_s=float(result.get("judge_s") or 0.0) + timing.judge_s,
            open_s=float(result.get("open_s") or 0.0) + open_s,
            outputs_s=float(result.get("outputs_s") or 0.0) + outputs_s,
            run_seconds=float(c.seconds),
        )
        result.update(_match_figures(rd))
        best_png, best_tf = rd / "best" / "rank01.png", rd / "best" / "rank01.tf.json"
        if best_png.exists():
            from intuitf.imageio import load_image

            result["best_png"] = str(best_png.relative_to(self.root))
            result["best_tf"] = str(best_tf.relative_to(self.root))
            result["similarity"] = self.reference.similarity(load_image(best_png))
        return result

    def _open(self, item: VolumeItem, rd: Path):
        """Read the volume, carry the reference TF to it, and open its run (a worker thread)."""
        from intuitf.batch.transfer import transfer_tf
        from intuitf.session import Session
        from intuitf.tf.defaults import default_tf
        from intuitf.volume import load_volume

        vol = load_volume(item.source, **self.config.reader)
        ref = self.reference
        counts, _ = vol.histogram()
        if self.config.carry and ref.tf is not None:
            start, _ = transfer_tf(
                ref.tf,
                counts,
                ref_counts=ref.counts,
                ref_range=ref.value_range,
                target_range=tuple(vol.value_range),
            )
        else:  # no TF to carry (a picture), or --no-carry: the volume's own default TF
            start = default_tf(counts, tuple(vol.value_range))
        initial = [start.to_dict()]
        template = self.config.template
        spec = {
            **template,
            "name": item.key,
            "volume": {"source": item.source, **self.config.reader},
            "initial": initial,
            # A batch gives many volumes one look from a reference and spends one shared
            # budget through its workers' gated judges: it never sends the per-volume atlas
            # request that names structures for words (it would pass by that gate).
            "settings": {**(template.get("settings") or {}), "name_structures": False},
        }
        session = Session.open(spec, rd, volume=vol)
        try:
            start_sim = ref.similarity(session.render(start))
        except Exception:  # noqa: BLE001 - a figure for the report, never a failure
            start_sim = None
        return session, start_sim


def _match_figures(run_dir: Path) -> dict:
    """The run's matches, decided and undecided (no usable answer), from its journal."""
    from intuitf.evaluator.matches import MatchStats
    from intuitf.session.rundir import RunDirectory

    try:
        gens = RunDirectory(run_dir).generations()
        stats = MatchStats.from_journal(gens)
    except Exception:  # noqa: BLE001 - figures for the report, never a failure
        return {}
    return {
        "matches": stats.matches,
        "undecided": stats.undecided,
        "undecided_share": stats.undecided_share,
        # Generations in which the judge called every decided match a tie.
        "indistinct_generations": [int(e["generation"]) for e in gens if e.get("indistinct")],
    }


def _message(exc: BaseException) -> str:
    msg = getattr(exc, "message", None) or str(exc)
    hint = getattr(exc, "hint", None)
    return f"{msg} {hint}" if hint else msg


# -- worker processes (pool) ------------------------------------------------------------------
def _set_threads(n: int | None) -> None:
    if not n:
        return
    try:
        import numba

        numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # noqa: BLE001 - threads are a tuning, not a requirement
        pass


def _die_with_parent() -> None:
    """Linux: this process gets SIGKILL when the batch process that started it dies."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except Exception:  # noqa: BLE001 - elsewhere a watchdog thread does it
        pass
    parent = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, daemon=True, name="batch-parent-watch").start()


def _pool_main(config: BatchConfig, inbox, outbox, index: int) -> None:
    """A pool worker: take volumes from ``inbox``, report to ``outbox`` (see :class:`PoolBackend`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver decides how to stop
    _die_with_parent()
    logging.basicConfig(level=logging.WARNING)
    _set_threads(config.numba_threads)
    try:
        ledger = None
        if config.uses_model:
            from intuitf.batch.budget import LEDGER_NAME, BatchLedger

            ledger = BatchLedger(Path(config.root) / LEDGER_NAME)
        core = WorkerCore(config, ledger)
    except Exception as exc:  # noqa: BLE001
        outbox.put(("fatal", index, _message(exc)))
        return
    asyncio.run(_pool_loop(core, inbox, outbox, index))


async def _pool_loop(core: WorkerCore, inbox, outbox, index: int) -> None:
    loop = asyncio.get_running_loop()
    done = asyncio.Event()
    futures: list = []

    async def one(item_dict: dict) -> None:
        res = await core.run(VolumeItem.from_dict(item_dict))
        outbox.put(("done", index, res))

    def reader() -> None:  # a thread: the inbox is a blocking queue
        while True:
            msg = inbox.get()
            if msg is None:
                loop.call_soon_threadsafe(done.set)
                return
            if msg == "stop":
                loop.call_soon_threadsafe(core.stop)
            else:
                futures.append(asyncio.run_coroutine_threadsafe(one(msg), loop))

    threading.Thread(target=reader, daemon=True, name="batch-inbox").start()
    await done.wait()
    for fut in list(futures):
        await asyncio.wrap_future(fut)


class PoolBackend:
    """``workers`` local processes (spawned), one inbox each, one outbox for all."""

    name = "pool"

    def __init__(self, config: BatchConfig, workers: int) -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.outbox = ctx.Queue()
        self.inboxes = [ctx.Queue() for _ in range(workers)]
        self.procs = [
            ctx.Process(
                target=_pool_main,
                args=(config, self.inboxes[i], self.outbox, i),
                name=f"intuitf-batch-{i}",
                daemon=True,
            )
            for i in range(workers)
        ]
        for p in self.procs:
            p.start()
        self.workers = workers
        self.fatal: list[str] = []

    def alive(self, w: int) -> bool:
        return self.procs[w].is_alive()

    def submit(self, w: int, item: VolumeItem) -> None:
        self.inboxes[w].put(item.to_dict())

    def poll(self, timeout: float) -> list[tuple[int, dict]]:
        import queue

        out = []
        try:
            msg = self.outbox.get(timeout=timeout)
        except queue.Empty:
            return out
        while True:
            kind, w, payload = msg
            if kind == "done":
                out.append((w, payload))
            elif kind == "fatal":
                self.fatal.append(str(payload))
            try:
                msg = self.outbox.get_nowait()
            except queue.Empty:
                return out

    def stop(self) -> None:
        for q in self.inboxes:
            q.put("stop")

    def shutdown(self, wait: float = 30.0) -> None:
        for q in self.inboxes:
            try:
                q.put(None)
            except Exception:  # noqa: BLE001
                pass
        deadline = time.monotonic() + wait
        for p in self.procs:
            p.join(max(0.1, deadline - time.monotonic()))
        for p in self.procs:
            if p.is_alive():
                p.terminate()
                p.join(5)


# -- Ray ---------------------------------------------------------------------------------------
class _RayWorkerImpl:
    """A Ray actor that runs volumes like a pool worker (async: many volumes at once)."""

    def __init__(self, config: BatchConfig, ledger: Any, threads: int | None) -> None:
        logging.basicConfig(level=logging.WARNING)
        _set_threads(threads)
        self.core = WorkerCore(config, ledger)

    async def run(self, item: dict) -> dict:
        return await self.core.run(VolumeItem.from_dict(item))

    async def stop(self) -> None:
        self.core.stop()

    async def pid(self) -> int:
        return os.getpid()


def import_ray():
    """The ``ray`` module, or one clear message saying how to install it."""
    try:
        import ray
    except ImportError:
        raise IntuitfError(f"--ray needs Ray, which is not installed: {RAY_HINT}.") from None
    return ray


class RayBackend:
    """``workers`` Ray actors; ``address`` None/"local" starts a local instance, else joins."""

    name = "ray"

    def __init__(
        self,
        config: BatchConfig,
        workers: int | None,
        address: str | None,
        started_here: bool = False,
    ) -> None:
        ray = import_ray()
        self.ray = ray
        if not ray.is_initialized():
            _ray_init(ray, address)
            started_here = True
        #: Whether this batch started the Ray instance (and so shuts it down at the end).
        self.started_here = started_here
        ledger = None
        if config.uses_model:
            from intuitf.batch.budget import LEDGER_NAME, ray_ledger

            ledger = ray_ledger(str(Path(config.root) / LEDGER_NAME))
        self.ledger = ledger
        cpus = float(ray.cluster_resources().get("CPU", 1.0))
        self.workers = int(workers or max(1, int(cpus)))
        per = max(0.01, cpus / self.workers)
        threads = max(1, int(per))
        actor = ray.remote(num_cpus=per)(_RayWorkerImpl)
        self.actors = [actor.remote(config, ledger, threads) for _ in range(self.workers)]
        self.refs: dict[Any, int] = {}
        self._items: dict[Any, VolumeItem] = {}
        self.dead: set[int] = set()
        self.fatal: list[str] = []

    def alive(self, w: int) -> bool:
        return w not in self.dead

    def submit(self, w: int, item: VolumeItem) -> None:
        ref = self.actors[w].run.remote(item.to_dict())
        self.refs[ref] = w
        self._items[ref] = item

    def poll(self, timeout: float) -> list[tuple[int, dict]]:
        ray = self.ray
        if not self.refs:
            time.sleep(timeout)
            return []
        ready, _ = ray.wait(list(self.refs), num_returns=1, timeout=timeout)
        out = []
        for ref in ready:
            w = self.refs.pop(ref)
            item = self._items.pop(ref)
            try:
                out.append((w, ray.get(ref)))
            except Exception as exc:  # noqa: BLE001 - the actor died (node lost, OOM, ...)
                self.dead.add(w)
                res = _base_result(item)
                res.update(status="interrupted", lost=True,
                           message=f"The Ray worker was lost: {exc}")  # fmt: skip
                out.append((w, res))
        return out

    def stop(self) -> None:
        for a in self.actors:
            try:
                a.stop.remote()
            except Exception:  # noqa: BLE001
                pass

    def shutdown(self, wait: float = 30.0) -> None:
        handles = list(self.actors) + ([self.ledger.handle] if self.ledger is not None else [])
        for a in handles:
            try:
                self.ray.kill(a)
            except Exception:  # noqa: BLE001
                pass
        if self.started_here:
            self.ray.shutdown()


# -- the driver --------------------------------------------------------------------------------
@dataclass
class BatchProgress:
    """What the driver reports as it goes (for a progress display)."""

    total: int
    done: int = 0
    running: dict[str, float] = field(default_factory=dict)
    results: dict[str, dict] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def drive(
    config: BatchConfig,
    items: list[VolumeItem],
    *,
    workers: int | None = None,
    ray_address: str | None = None,
    use_ray: bool = False,
    on_update: Callable[[str, VolumeItem, dict | None], None] | None = None,
    ledger: Any = None,
    stop_when: Callable[[], bool] | None = None,
    max_concurrency: int | None = None,
    rate_per_min: float | None = None,
    max_failures: int = DEFAULT_MAX_FAILURES,
    ray_timeout: float = DEFAULT_RAY_TIMEOUT,
) -> dict[str, dict]:
    """Run every volume of ``items`` not already finished; returns results by key.

    ``on_update(event, item, result)`` is called with "skipped", "started", "retry" (a volume
    that failed goes again, ``max_failures`` times at most) and "done".
    ``max_concurrency`` (judge requests in flight) and ``rate_per_min`` (requests started per
    minute) hold for the whole batch: each of the W workers gets a W-th of them.
    ``stop_when()``, polled a few times a second, stops the batch like Ctrl-C when true.
    """
    notify = on_update or (lambda *_: None)
    results: dict[str, dict] = {}
    pending: deque[VolumeItem] = deque()
    for it in items:
        if is_finished(config.root, it.key):
            res = read_result(config.root, it.key) or {}
            res["skipped"] = True
            results[it.key] = res
            notify("skipped", it, res)
        else:
            pending.append(it)
    if not pending:
        return results
    started_ray = False
    reaper = None
    if use_ray:
        ray = import_ray()
        if not ray.is_initialized():
            _ray_init(ray, ray_address, ray_timeout)
            started_ray = True
            if ray_address in (None, "", "local"):
                reaper = start_reaper(ray)  # it goes away with this process, killed or not
        n_workers = int(workers or max(1, int(ray.cluster_resources().get("CPU", 1.0))))
    else:
        n_workers = max(1, min(workers or (os.cpu_count() or 1), len(pending)))
        if config.numba_threads is None:
            config.numba_threads = max(1, (os.cpu_count() or 1) // n_workers)
    if max_concurrency:
        config.max_in_flight = max(1, int(max_concurrency) // n_workers)
    if rate_per_min:
        config.rate_per_s = float(rate_per_min) / 60.0 / n_workers
    lease = None
    if use_ray:  # workers that may outlive this process stop when it is gone
        lease = DriverLease(_node_ip(ray_address))
        config.lease = lease.address
    try:
        if use_ray:
            backend: Any = RayBackend(config, n_workers, ray_address, started_here=started_ray)
        else:
            backend = PoolBackend(config, n_workers)
    except BaseException:
        if lease is not None:
            lease.close()
        if reaper is not None:
            reaper.close()
        raise
    load = [0] * backend.workers
    running: dict[str, tuple[int, VolumeItem]] = {}
    stopping = False
    failures: dict[str, int] = {}
    #: When a volume that failed may go again (monotonic time), by key.
    not_before: dict[str, float] = {}

    def finished(it: VolumeItem, res: dict) -> None:
        """A volume's run ended: record it, or queue it again if it failed and may retry."""
        status = res.get("status")
        retry = (status in RETRYABLE or res.get("lost")) and not res.get("permanent")
        retry = retry and not stopping and not exhausted()
        if retry and failures.get(it.key, 0) < max_failures:
            failures[it.key] = failures.get(it.key, 0) + 1
            res["retries"] = failures[it.key]
            wait = RETRY_WAIT_S * 2.0 ** (failures[it.key] - 1)
            not_before[it.key] = time.monotonic() + wait
            pending.append(it)
            notify("retry", it, res)
            return
        if failures.get(it.key):
            res["retries"] = failures[it.key]
            try:
                write_result(config.root, res)
            except IntuitfError:
                pass
        results[it.key] = res
        notify("done", it, res)

    def exhausted() -> bool:
        return ledger is not None and config.uses_model and ledger.totals().exhausted

    try:
        while pending or running:
            try:
                if stop_when is not None and not stopping and stop_when():
                    raise KeyboardInterrupt
                while pending and not stopping:
                    live = [w for w in range(backend.workers) if backend.alive(w)]
                    free = [w for w in live if load[w] < config.per_worker]
                    if not live:
                        while pending:
                            it = pending.popleft()
                            res = _base_result(it)
                            res.update(
                                status="interrupted", message="No worker was left to run it."
                            )
                            results[it.key] = res
                            notify("done", it, res)
                        break
                    if not free:
                        break
                    if exhausted():
                        while pending:
                            it = pending.popleft()
                            res = {**_base_result(it), **(read_result(config.root, it.key) or {})}
                            res.update(status="budget", message="The batch's budget was spent "
                                       "before this volume's turn.")  # fmt: skip
                            write_result(config.root, res)
                            results[it.key] = res
                            notify("done", it, res)
                        break
                    now = time.monotonic()
                    ready = [i for i in pending if not_before.get(i.key, 0.0) <= now]
                    if not ready:
                        break
                    w = min(free, key=lambda k: load[k])
                    it = ready[0]
                    pending.remove(it)
                    backend.submit(w, it)
                    load[w] += 1
                    running[it.key] = (w, it)
                    notify("started", it, None)
                for _w, res in backend.poll(0.2):
                    key = res.get("key")
                    entry = running.pop(key, None)
                    if entry is not None:
                        load[entry[0]] -= 1
                        finished(entry[1], res)
                # Volumes of a worker process that died: reported, resumed by the next run.
                for key, (w, it) in list(running.items()):
                    if not backend.alive(w):
                        running.pop(key)
                        res = read_result(config.root, key) or _base_result(it)
                        if res.get("status") in (None, "pending", FINISHED) or not res.get(
                            "status"
                        ):
                            res = _base_result(it)
                        res.update(status="interrupted", lost=True,
                                   message="Its worker process died; run the batch again to "
                                           "resume it.")  # fmt: skip
                        finished(it, res)
                if getattr(backend, "fatal", None):
                    raise IntuitfError(f"A batch worker could not start: {backend.fatal[0]}")
            except KeyboardInterrupt:
                if stopping:
                    raise
                stopping = True
                backend.stop()
                for it in pending:
                    res = _base_result(it)
                    res.update(status="interrupted", message="The batch was stopped first.")
                    results[it.key] = res
                pending.clear()
    finally:
        backend.shutdown()
        if lease is not None:
            lease.close()
        if reaper is not None:
            reaper.close()
    return results


def _node_ip(address: str | None) -> str:
    """The address workers reach this process at: loopback for a local Ray, else this node's
    address as Ray sees it."""
    if address in (None, "", "local"):
        return "127.0.0.1"
    try:
        import ray

        return str(ray.util.get_node_ip_address())
    except Exception:  # noqa: BLE001
        return socket.gethostbyname(socket.gethostname())


def _ray_init(ray, address: str | None, timeout: float = DEFAULT_RAY_TIMEOUT) -> None:
    """Start a local Ray instance, or join the one at ``address``, within ``timeout`` seconds.

    An address that does not answer fails at once (a TCP connect first), a cluster that
    accepts the connection but never completes the handshake after ``timeout`` seconds, and
    a cluster that refuses this process's token says so, with what to do.
    """
    kw: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
    local = address in (None, "", "local")
    if not local and address != "auto":
        _check_reachable(str(address), timeout)
        _use_token_if_any()
    box: dict[str, BaseException | None] = {}

    def init() -> None:
        try:
            if local:
                ray.init(num_cpus=os.cpu_count() or 1, include_dashboard=False, **kw)
            else:
                ray.init(address=address, **kw)
            box["error"] = None
        except BaseException as exc:  # noqa: BLE001 - handed to the calling thread
            box["error"] = exc

    where = address if not local else "a local instance"
    if local:  # starting one here: Ray's own start-up checks apply (and want the main thread)
        init()
        t = None
    else:
        # ray.init has no timeout of its own: a head that never answers would hold us forever,
        # and one that refuses the token is retried forever. Ray's own complaints (its C++
        # core writes them to the process's stderr) are caught meanwhile, to say why.
        t = threading.Thread(target=init, daemon=True, name="ray-init")
        with _captured_stderr() as said:
            t.start()
            end = time.monotonic() + timeout
            while t.is_alive() and time.monotonic() < end:
                t.join(0.25)
                if _is_auth_refusal(said()):
                    box["error"] = IntuitfError(said())
                    break
        if not t.is_alive() or box.get("error") is not None:
            t = None
    if t is not None and t.is_alive():
        raise IntuitfError(
            f"Ray at {where} did not answer within {timeout:g} s.",
            "Check the address (`ray status` on the head node shows it) and that this machine "
            "can reach it, or give a longer --ray-timeout.",
        )
    exc = box.get("error")
    if exc is None:
        return
    text = f"{type(exc).__name__}: {exc}"
    if _is_auth_refusal(text):
        raise IntuitfError(
            f"The Ray cluster at {where} refused this process's authentication token.",
            "The cluster uses token authentication: give this process the head's token, e.g. "
            "RAY_AUTH_TOKEN=$(ray get-auth-token) on the head node (or copy its "
            "~/.ray/auth_token here), and RAY_AUTH_MODE=token.",
        ) from None
    raise IntuitfError(
        f"Could not start or join Ray at {where}: {_first_line(text)}",
        "Check the address (`ray status` on the head node shows it), or drop ADDRESS to "
        "start a local instance.",
    ) from None


@contextlib.contextmanager
def _captured_stderr():
    """Send the process's stderr (file descriptor 2) to a temporary file meanwhile; yields a
    function returning what was written so far."""
    import tempfile

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)

        def said() -> str:
            tmp.seek(0)
            return tmp.read().decode("utf-8", "replace")

        try:
            yield said
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)


def _first_line(text: str, limit: int = 300) -> str:
    line = text.strip().splitlines()[0] if text.strip() else text
    return line[:limit]


def _is_auth_refusal(text: str) -> bool:
    low = text.lower()
    return any(k in low for k in ("invalidauthtoken", "unauthenticated", "authentication"))


def _split_address(address: str) -> tuple[str, int] | None:
    """(host, port) of HOST:PORT or ray://HOST:PORT, else None."""
    rest = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return host.strip("[]"), int(port)


def _check_reachable(address: str, timeout: float) -> None:
    """Fail at once, saying why, when nothing listens at ``address`` (a TCP connect)."""
    import socket

    if address.startswith(("ray://", "rays://")):
        try:
            import grpc  # noqa: F401
            import ray.util.client  # noqa: F401
        except ImportError:
            raise IntuitfError(
                f"--ray {address} needs Ray's client, which is not installed.",
                'pip install "intuitf[ray]" (it brings ray[client]).',
            ) from None
    hp = _split_address(address)
    if hp is None:
        raise IntuitfError(
            f"{address!r} is not a Ray address.",
            "Give HOST:PORT (the GCS port `ray start --head` printed), ray://HOST:PORT, "
            "auto, or no ADDRESS for a local instance.",
        )
    host, port = hp
    if not 0 < port < 65536:
        raise IntuitfError(f"{address!r}: the port must be within 1..65535.")
    try:
        with socket.create_connection((host, port), timeout=min(timeout, 10.0)):
            pass
    except OSError as exc:
        why = "no such host" if isinstance(exc, socket.gaierror) else (exc.strerror or str(exc))
        raise IntuitfError(
            f"Cannot reach a Ray cluster at {address}: {why}.",
            "Check the address (`ray status` on the head node shows it), that the head is "
            "running and that this machine can reach it.",
        ) from None


def _use_token_if_any() -> None:
    """Send the token, when there is one, to a cluster joined by its address.

    Ray turns token authentication on for a local cluster found automatically (``auto``) but
    never for an explicit address, so a driver joining a head started with ``ray start
    --head`` (token authentication on by default) would be refused although the token is
    right there: use it the way ``auto`` does.
    """
    if os.environ.get("RAY_AUTH_MODE") is not None:
        return  # the user chose
    try:
        from ray._private.authentication.authentication_token_setup import (
            maybe_enable_token_auth_if_token_available,
        )

        maybe_enable_token_auth_if_token_available(warn_if_disabled=False)
    except Exception:  # noqa: BLE001 - an older Ray without token authentication
        pass
