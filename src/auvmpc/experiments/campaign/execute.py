"""Running a campaign: one run on a worker, the local process pool, Dask.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import contextlib
import functools
import json
import multiprocessing
import os
import socket
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auvmpc.errors import ConfigError
from auvmpc.experiments.campaign.paired import paired_columns, reusable_twins
from auvmpc.experiments.campaign.sampling import (
    plan_run,
    sample_run,
    validate_campaign,
)
from auvmpc.experiments.campaign.spec import (
    LOCK_FILE,
    MAX_WORKER_DEATHS,
    OVERRIDE_NOTES,
    RESULTS_FILE,
    Campaign,
    CampaignSpec,
    _resolve,
    _with_implicit_overrides,
    load_campaign,
)
from auvmpc.experiments.campaign.store import (
    _exclusive,
    _Store,
)
from auvmpc.experiments.outputs import prepare_campaign_folder
from auvmpc.experiments.provenance import Stopwatch


@functools.lru_cache(maxsize=4)
def _campaign_from_payload(payload: str) -> Campaign:
    data = json.loads(payload)
    campaign = Campaign(
        CampaignSpec.model_validate(data["spec"]),
        data["source"],
        data["base_source"],
        data["base_data"],
        data["base_dir"],
        controller_overrides=tuple(data["controller_overrides"]),
    )
    return _with_implicit_overrides(campaign)


def execute_run(payload: str, index: int, twin: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Simulate run ``index`` of the campaign in ``payload`` (:meth:`Campaign.payload`).

    An exception inside the run is the run's result (status ``failed``, one-line
    ``error``, full ``traceback``), never raised: only a broken worker or environment
    makes this function raise.

    With a yardstick, the run is simulated twice (:func:`paired.paired_columns`): its
    metrics gain the yardstick's, prefixed ``yardstick_``, and the paired columns. ``twin``,
    the yardstick twin's columns read from another folder (``--yardstick-from``), is used
    instead of simulating the twin.

    Returns
    -------
    dict
        ``index``, ``seed``, ``status`` (``ok`` | ``failed``), ``parameters`` (result
        columns), ``metrics`` (empty when failed, but for ``override_notes``: the notes
        its overrides made, where they made some), ``error``, ``traceback``, ``wall_s``,
        ``worker`` (host:pid).
    """
    from auvmpc.experiments.run import simulate

    campaign = _campaign_from_payload(payload)
    sample = sample_run(campaign, index)
    started = time.perf_counter()
    metrics: dict[str, Any] = {}
    error = trace = None
    try:
        plan = plan_run(campaign, index)
        if plan.notes:  # kept also when the run fails: a dropped knob may be why
            metrics[OVERRIDE_NOTES] = json.dumps(plan.notes)
        # long_ok: the campaign's cost was checked (or confirmed) before any run started.
        result = simulate(_resolve(campaign, plan.data, plan.notes), long_ok=True)
        metrics = {**result.metrics, **metrics}
        if campaign.spec.yardstick is not None:
            metrics = {**metrics, **paired_columns(campaign, index, result, twin)}
        status = "ok"
    except Exception as exc:  # the run's own failure is a result, recorded once
        status, error, trace = "failed", _one_line(exc), traceback.format_exc()
    return {
        "index": index,
        "seed": sample.seed,
        "status": status,
        "parameters": sample.columns,
        "metrics": metrics,
        "error": error,
        "traceback": trace,
        "wall_s": time.perf_counter() - started,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


def _one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


def _worker_init(parent_pid: int) -> None:
    """Local pool worker: leave Ctrl-C to the coordinator, exit when the coordinator is gone
    (a coordinator killed with SIGKILL cannot stop its workers itself)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="auvmpc-parent-watch", daemon=True).start()


@dataclass(frozen=True)
class CampaignSummary:
    """What :func:`run_campaign` leaves behind.

    Attributes
    ----------
    out_dir : Path
    total : int
        Runs asked for (``--runs`` or the file's ``runs``).
    ok, failed : int
        Rows among runs ``0..total-1``.
    new : int
        Runs executed by this call (the rest were already stored).
    wall_s : float
        Wall time of this call.
    first_error : str or None
        The one-line error of the first failed run, if any.
    """

    out_dir: Path
    total: int
    ok: int
    failed: int
    new: int
    wall_s: float
    first_error: str | None = None


def run_campaign(
    source: str | Path | Campaign,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    runs: int | None = None,
    scheduler: str | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    overwrite: bool = False,
    yardstick_from: str | Path | None = None,
    long_ok: bool = False,
) -> CampaignSummary:
    """Run (or resume) a campaign into ``out_dir``.

    Parameters
    ----------
    source : str, Path or Campaign
        Built-in campaign name or campaign file.
    out_dir : path
        Campaign folder; ``results.sqlite`` inside holds one row per finished run. Calling
        again with the same campaign resumes: stored runs are not redone.
    workers : int, optional
        Local worker processes; default: every CPU this process may use. Ignored with
        ``scheduler``.
    runs : int, optional
        Run only runs ``0..runs-1`` (at most the file's ``runs``).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``); its workers must be
        able to import this version of auvmpc and read the scenario's files.
    on_progress : callable, optional
        ``on_progress(done, total)`` once before the first run and after each stored run.
    overwrite : bool
        Discard an earlier campaign folder at ``out_dir`` and start over (only one that
        auvmpc wrote, :mod:`auvmpc.experiments.outputs`). Without it such a folder is resumed.
    yardstick_from : path, optional
        A folder (finished or partial) of this campaign with another tested controller: run
        k's yardstick twin is copied from it where it finished there, instead of simulated
        (:func:`paired.reusable_twins`). Not part of the campaign's identity: the copied twin
        is the one a simulation would give. The session records the folder and the runs.
    long_ok : bool
        Run even when a run or the whole campaign is estimated beyond the cost limits
        (:mod:`auvmpc.scenario.cost`); memory beyond what is available is still refused.

    Raises
    ------
    ConfigError
        Bad campaign (before any run starts), ``out_dir`` holding another campaign or in
        use by another process, bad ``workers``/``runs``, unreachable scheduler,
        ``yardstick_from`` holding another campaign.
    """
    started = time.perf_counter()
    campaign = source if isinstance(source, Campaign) else load_campaign(source)
    total = campaign.spec.runs if runs is None else runs
    if (
        isinstance(total, bool)
        or not isinstance(total, int)
        or not 1 <= total <= campaign.spec.runs
    ):
        raise ConfigError("--runs", runs, f"need a whole number in 1..{campaign.spec.runs}")
    if workers is None:
        workers = (
            len(os.sched_getaffinity(0))
            if hasattr(os, "sched_getaffinity")
            else os.cpu_count() or 1
        )
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError("--workers", workers, "need a whole number >= 1")
    twins = {} if yardstick_from is None else reusable_twins(campaign, yardstick_from)
    validate_campaign(campaign, total, workers, long_ok)
    out = Path(out_dir)
    new = 0
    copied: list[int] = []  # runs whose stored twin came from yardstick_from
    stopwatch = Stopwatch()
    prepare_campaign_folder(out, overwrite=overwrite, files=(RESULTS_FILE, LOCK_FILE))
    with _exclusive(out):
        store = _Store(out, campaign)
        try:
            finished = store.finished()
            todo = [k for k in range(total) if k not in finished]
            done = total - len(todo)
            if on_progress is not None:
                on_progress(done, total)

            def record(result: Mapping[str, Any]) -> None:
                nonlocal done, new
                store.record(result)
                if result["status"] == "ok" and result["index"] in twins:
                    copied.append(result["index"])
                done, new = done + 1, new + 1
                if on_progress is not None:
                    on_progress(done, total)

            if todo and scheduler is not None:
                _execute_dask(campaign, todo, twins, scheduler, record)
            elif todo:
                _execute_local(campaign, todo, twins, workers, store, record)
            counts = dict(
                store.connection.execute(
                    'SELECT status, COUNT(*) FROM runs WHERE "index" < ? GROUP BY status', (total,)
                ).fetchall()
            )
            first_error = store.connection.execute(
                'SELECT error FROM runs WHERE "index" < ? AND status = ? ORDER BY "index" LIMIT 1',
                (total, "failed"),
            ).fetchone()
        finally:
            with contextlib.suppress(Exception):  # also after an interrupt: who ran what
                provenance = stopwatch.record(("osqp", "daqp", "proxsuite"))
                if yardstick_from is not None:
                    folder = str(Path(yardstick_from).resolve())
                    provenance["yardstick_from"] = {"folder": folder, "runs": sorted(copied)}
                store.record_session(provenance, new)
            store.close()
    return CampaignSummary(
        out,
        total,
        counts.get("ok", 0),
        counts.get("failed", 0),
        new,
        time.perf_counter() - started,
        None if first_error is None else first_error[0],
    )


def _execute_local(
    campaign: Campaign,
    todo: Sequence[int],
    twins: Mapping[int, Mapping[str, Any]],
    workers: int,
    store: _Store,
    record: Callable[[Mapping[str, Any]], None],
) -> None:
    """Run ``todo`` on a process pool, at most ``workers`` runs in flight (``twins``: the
    yardstick twins to copy, by run index).

    A worker process that dies breaks the pool (``BrokenProcessPool``) and fails every run
    in flight; each of them gets a death counted in the results file, the pool is
    recreated and those runs are rerun one at a time, so the culprit dies alone. A run
    counted ``MAX_WORKER_DEATHS`` deaths is recorded as failed.
    """
    payload = campaign.payload()
    arguments = {index: (payload, index, twins.get(index)) for index in todo}  # of execute_run
    deaths = store.deaths()
    queue = deque(k for k in todo if deaths.get(k, 0) == 0)
    alone = deque(k for k in todo if deaths.get(k, 0) > 0)  # suspects from an earlier break
    context = multiprocessing.get_context("spawn")
    while queue or alone:
        size = min(workers, max(len(queue), 1))
        pool = ProcessPoolExecutor(
            max_workers=size,
            mp_context=context,
            initializer=_worker_init,
            initargs=(os.getpid(),),
        )
        in_flight: dict[Future, int] = {}
        victims: list[int] = []
        clean = False
        try:
            _check_pool(pool, size)
            while True:
                if alone:
                    if not in_flight:
                        index = alone.popleft()
                        in_flight[pool.submit(execute_run, *arguments[index])] = index
                else:
                    while queue and len(in_flight) < workers:
                        index = queue.popleft()
                        in_flight[pool.submit(execute_run, *arguments[index])] = index
                if not in_flight:
                    break
                finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                results = []
                for future in finished:
                    index = in_flight.pop(future)
                    error = future.exception()
                    if isinstance(error, BrokenProcessPool):
                        victims.append(index)
                    elif error is not None:
                        raise RuntimeError(
                            f"run {index} could not be executed: {_one_line(error)}"
                        ) from error
                    else:
                        results.append(future.result())
                if victims:  # every other run in flight fails the same way
                    wait(in_flight)
                    for future, index in in_flight.items():
                        if future.exception() is None:
                            results.append(future.result())
                        else:
                            victims.append(index)
                    in_flight.clear()
                elif not alone:  # refill before writing, so no worker waits on the disk
                    while queue and len(in_flight) < workers:
                        index = queue.popleft()
                        in_flight[pool.submit(execute_run, *arguments[index])] = index
                for result in results:
                    record(result)
                if victims:
                    break
            clean = not victims
        finally:
            _shutdown(pool, clean)
        for index in sorted(victims):
            if store.add_death(index) >= MAX_WORKER_DEATHS:
                record(_died(campaign, index))
            else:
                alone.append(index)


def _worker_ready() -> int:
    import auvmpc.experiments.run  # noqa: F401  (the import a first run would otherwise pay)

    return os.getpid()


def _check_pool(pool: ProcessPoolExecutor, workers: int) -> None:
    """Start every worker at once and wait until each can import auvmpc.

    Each submit while no worker is idle starts another process, so the workers import in
    parallel rather than one after the other. A worker that cannot even start is the
    environment's fault, not a run's: stop without recording anything, so that a resume
    after the fix runs everything.
    """
    try:
        for future in [pool.submit(_worker_ready) for _ in range(workers)]:
            future.result()
    except BrokenProcessPool:
        raise RuntimeError(
            "campaign worker processes cannot start (see their error above); "
            "auvmpc must be importable by a fresh Python process"
        ) from None


def _shutdown(pool: ProcessPoolExecutor, clean: bool) -> None:
    """Stop the pool; after an error or interruption, without letting runs finish."""
    if clean:
        pool.shutdown(wait=True)
        return
    # ProcessPoolExecutor has no public way to stop running workers before Python 3.14.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(Exception):
            process.terminate()
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(timeout=5)


def _died(campaign: Campaign, index: int) -> dict[str, Any]:
    sample = sample_run(campaign, index)
    return {
        "index": index,
        "seed": sample.seed,
        "status": "failed",
        "parameters": sample.columns,
        "metrics": {},
        "error": f"WorkerDied: the worker process died {MAX_WORKER_DEATHS} times while running it",
        "traceback": None,
        "wall_s": None,
        "worker": None,
    }


def _execute_dask(
    campaign: Campaign,
    todo: Sequence[int],
    twins: Mapping[int, Mapping[str, Any]],
    scheduler: str,
    record: Callable[[Mapping[str, Any]], None],
) -> None:
    """Run ``todo`` as Dask futures. A worker that dies mid-run is handled by the
    scheduler, which reruns its tasks elsewhere up to ``distributed.scheduler.allowed-failures``
    times and then reports ``KilledWorker``: that run is recorded as failed. ``retries`` is
    left at 0: a run's own exception is returned as its result, so anything a task raises
    is an environment problem that retrying would only repeat."""
    try:
        from distributed import Client, as_completed
        from distributed.scheduler import KilledWorker
    except ImportError:
        raise ConfigError(
            "--scheduler", scheduler, "needs dask[distributed] (pip install auvmpc[dask])"
        ) from None
    try:
        client = Client(scheduler, timeout="20s", set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise ConfigError("--scheduler", scheduler, f"cannot connect: {_one_line(error)}") from None
    payload = campaign.payload()
    prefix = f"auvmpc-campaign-{campaign.hash[:12]}"
    futures: dict[Any, int] = {}
    try:
        for index in todo:
            key, twin = f"{prefix}-{index}", twins.get(index)
            futures[client.submit(execute_run, payload, index, twin, key=key, pure=False)] = index
        for future in as_completed(futures, loop=client.loop):  # no default client
            index = futures.pop(future)
            if future.status == "error":
                error = future.exception()
                if isinstance(error, KilledWorker):
                    failed = _died(campaign, index)
                    deaths = error.allowed_failures + 1
                    failed["error"] = f"KilledWorker: {deaths} Dask workers died while running it"
                    record(failed)
                else:
                    raise ConfigError(
                        "--scheduler",
                        scheduler,
                        f"run {index} could not execute on the cluster ({_one_line(error)}); "
                        "auvmpc must be importable on every worker",
                    )
            elif future.status != "finished":
                raise ConfigError(
                    "--scheduler",
                    scheduler,
                    f"run {index} was {future.status} by the cluster; "
                    "run the same command again to resume",
                )
            else:
                record(future.result())
            future.release()
    finally:
        for future in futures:
            future.cancel()
        client.close()
