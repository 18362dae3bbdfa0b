"""Scale-out: ``wristmimic run PIPELINE.toml --ray ADDRESS`` runs the pipeline's jobs as Ray tasks.

A job (:class:`wristmimic.pipeline.Job`) trains one (dataset, scene) run and then evaluates it under the
``[evaluate]`` protocol. The driver (the ``wristmimic run`` process) plans the jobs, skips those whose cache
records are up to date, dispatches the rest with ``--ray-cpus-per-job`` / ``--ray-gpus-per-job`` resources and
gathers each result as it arrives; it is the only writer of the work folder and of ``pipeline_state.json``.
A failed job is reported with the worker's error; the others' results are kept and recorded. Ctrl-C on the
driver asks every job to stop (a small Ray actor holds the request; jobs ask it at most once a second): training
stops after its current iteration with a checkpoint, evaluation after its completed trials, and the driver
gathers what the jobs saved, so running the pipeline again resumes them; a second Ctrl-C cancels the jobs and
loses their progress since dispatch.

Data movement (no shared filesystem needed):

- each dataset is read once by the driver and ``ray.put`` in the object store; a node keeps a verified copy in
  ``$WRISTMIMIC_CACHE_DIR/datasets/<sha256>.h5`` (default ``~/.cache/wristmimic/datasets``) and fetches the
  object only when that copy is missing;
- an existing run folder (a checkpoint to resume, finished evaluation parts) goes to its job as a tar archive;
- the job trains and evaluates in a scratch folder and returns the run folder (with ``eval/<protocol>``) as a
  tar archive, even when it fails after saving a checkpoint; the driver unpacks it beside the old folder and
  swaps it in by renaming.

The outputs record the driver's paths (``config.json``: the dataset; ``summary.json``: the run folder), so a
job writes the same files a serial run does.

Code: ``--ray local`` starts Ray on this machine with ``PYTHONPATH`` set to the driver's package root, so the
workers import the driver's code. On a cluster, install the same wristmimic (with the ``ray`` extra, and the
``eval/`` folder of the checkout or ``$WRISTMIMIC_EVAL_DIR``) on every node; a job on a node whose sources
differ from the driver's (:func:`code_fingerprint`) fails, saying so.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import os
import shutil
import socket
import tarfile
import tempfile
import time
import traceback
import uuid
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import wristmimic
from wristmimic.errors import InputError, WristmimicError
from wristmimic.safe_io import atomic_output, sha256_file

if TYPE_CHECKING:
    from wristmimic.evaluate.protocol import Protocol
    from wristmimic.pipeline import Context, Job

INSTALL_HINT = "pip install 'wristmimic[ray]'"


class JobsFailed(WristmimicError):
    """Some jobs failed; the others' results were recorded."""


@dataclass(frozen=True)
class RayOptions:
    """How to run the jobs on Ray (``wristmimic run --ray ...``)."""

    address: str
    """``local``: start Ray on this machine; anything else goes to ``ray.init(address=...)``."""
    cpus_per_job: int | None = None
    """CPUs a job reserves and uses (physics and torch threads); None: ``[pipeline] ray_cpus_per_job``, else
    ``--nthread``, else 1."""
    gpus_per_job: float | None = None
    """GPUs a job reserves; None: ``[pipeline] ray_gpus_per_job``, else 0."""
    local_cpus: int | None = None
    """CPUs of the Ray that ``local`` starts; None: all cores."""

    def resolved(self, meta: dict[str, Any], nthread: int | None, spec_path: Path | None = None) -> RayOptions:
        """Defaults filled from the ``[pipeline]`` table ``meta`` and ``--nthread``; checks that Ray imports."""
        require_ray()
        check_address(self.address)
        cpus = next(c for c in (self.cpus_per_job, meta.get("ray_cpus_per_job"), nthread, 1) if c is not None)
        gpus = self.gpus_per_job if self.gpus_per_job is not None else meta.get("ray_gpus_per_job", 0)
        if not isinstance(cpus, int) or isinstance(cpus, bool) or cpus < 1:
            raise InputError(spec_path, "pipeline.ray_cpus_per_job", f"{cpus!r}", "an integer >= 1")
        if not isinstance(gpus, int | float) or gpus < 0:
            raise InputError(spec_path, "pipeline.ray_gpus_per_job", f"{gpus!r}", "a number >= 0")
        return replace(self, cpus_per_job=cpus, gpus_per_job=float(gpus))


def require_ray() -> None:
    """Raise a one-line error when Ray is not installed."""
    try:
        import ray  # noqa: F401
    except ImportError:
        raise WristmimicError(f"--ray needs Ray, which is not installed: {INSTALL_HINT}") from None


@dataclass(frozen=True)
class JobWork:
    """What a Ray task does for one job (everything it needs besides the dataset and the run folder)."""

    job: Job
    run_dir: str
    """The driver's absolute run folder, recorded in the outputs."""
    dataset_sha256: str
    train: bool
    evaluate: dict[str, Any] | None
    """The ``[evaluate]`` table, or None: no evaluation."""
    protocol: Protocol | None
    cpus: int
    code: str
    """The driver's :func:`code_fingerprint`: a worker running other code fails (its results would not be what
    the cache records say)."""


@dataclass
class JobResult:
    ok: bool
    error: str = ""
    archive: bytes | None = None
    """The run folder as a tar archive (None: nothing was written)."""
    trained: bool = False
    """The training part finished (recorded even if the evaluation then failed)."""
    note: str = ""
    host: str = ""
    seconds: float = 0.0
    stopped: bool = False
    """The job stopped on the driver's request (Ctrl-C), keeping its checkpoint / completed trials."""


class StopFlag:
    """Ray actor: the driver sets it on Ctrl-C; jobs read it (:func:`stop_check`)."""

    def __init__(self) -> None:
        self._set = False

    def set(self) -> None:
        self._set = True

    def is_set(self) -> bool:
        return self._set


def stop_check(flag: Any, every_s: float = 1.0) -> Callable[[], bool] | None:
    """A job's ``should_stop``: asks the driver's :class:`StopFlag` at most every ``every_s`` seconds; a flag
    that cannot be reached counts as not set (the job goes on)."""
    if flag is None:
        return None
    import ray

    last, value = -float("inf"), False

    def should_stop() -> bool:
        nonlocal last, value
        now = time.monotonic()
        if not value and now - last >= every_s:
            last = now
            with contextlib.suppress(Exception):
                value = bool(ray.get(flag.is_set.remote(), timeout=10))
        return value

    return should_stop


# ------------------------------------------------------------------------------------------------ worker


def run_job(work: JobWork, dataset: list[Any], run_archive: bytes | None, stop_flag: Any = None) -> JobResult:
    """Ray task: train and/or evaluate one job in a scratch folder; returns the run folder as an archive.

    ``dataset``: ``[ObjectRef]`` of the dataset's bytes (in a list so Ray does not fetch it unless needed);
    ``stop_flag``: the driver's :class:`StopFlag` (Ctrl-C), or None."""
    import torch

    from wristmimic.evaluate.runner import EvalInterrupted

    t0, host = time.perf_counter(), socket.gethostname()
    job = work.job
    scratch = Path(tempfile.mkdtemp(prefix="wristmimic-job-"))
    run_dir = scratch / job.run_dir.name
    threads = torch.get_num_threads()
    notes: list[str] = []
    trained, data = False, None
    should_stop = stop_check(stop_flag)
    try:
        _check_code(work)
        data = local_dataset(work.dataset_sha256, dataset)
        if run_archive is not None:
            unpack_run(run_archive, run_dir)
        torch.set_num_threads(work.cpus)
        if work.train:
            from wristmimic.pipeline import train_job

            r = train_job(job.spec, run_dir, work.cpus, False, dataset_file=data, should_stop=should_stop)
            if r.status == "interrupted":
                raise _Stopped(f"stopped at iteration {r.iteration} ({r.frames:,} frames), checkpoint kept")
            notes.append(f"trained: {r.status} at iteration {r.iteration} ({r.frames:,} frames)")
            trained = True
        if work.evaluate is not None and work.protocol is not None:
            from wristmimic.pipeline import evaluate_job

            try:
                evaluate_job(
                    run_dir, work.protocol, work.evaluate, work.cpus, False, data, Path(work.run_dir), should_stop
                )
            except EvalInterrupted as exc:
                raise _Stopped(f"evaluation stopped ({exc.completed:,} of {exc.total:,} trials kept)") from None
            notes.append(f"evaluated ({work.protocol.name})")
        return JobResult(True, "", pack_run(run_dir), trained, "; ".join(notes), host, _since(t0))
    except BaseException as exc:  # noqa: BLE001 - every failure goes back to the driver, with what was saved
        archive = pack_run(run_dir) if (run_dir / "config.json").is_file() else None
        error = _one_line(exc).replace(str(run_dir), work.run_dir)
        error = error.replace(str(data), str(job.spec.dataset)) if data else error  # the paths the user knows
        stopped = isinstance(exc, _Stopped)
        return JobResult(False, error, archive, trained, "; ".join(notes), host, _since(t0), stopped)
    finally:
        torch.set_num_threads(threads)
        shutil.rmtree(scratch, ignore_errors=True)


class _Stopped(WristmimicError):
    """A job stopped on the driver's request."""


@functools.cache
def code_fingerprint() -> str:
    """``<version>+<sha256 of the package's .py files>`` (12 hex digits) of the imported wristmimic."""
    root = Path(wristmimic.__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f"{f.relative_to(root).as_posix()}\0".encode() + f.read_bytes())
    return f"{wristmimic.__version__}+{h.hexdigest()[:12]}"


def _check_code(work: JobWork) -> None:
    if code_fingerprint() != work.code:
        where = Path(wristmimic.__file__).resolve().parent
        raise WristmimicError(
            f"node {socket.gethostname()} runs wristmimic {code_fingerprint()} from {where}, the driver "
            f"{work.code}: install the same code on every node"
        )


def cache_dir() -> Path:
    """``$WRISTMIMIC_CACHE_DIR/datasets`` if that variable is set, else ``~/.cache/wristmimic/datasets``."""
    root = os.environ.get("WRISTMIMIC_CACHE_DIR")
    return (Path(root) if root else Path.home() / ".cache" / "wristmimic") / "datasets"


def local_dataset(sha: str, ref: list[Any]) -> Path:
    """This node's copy of the dataset with this sha256; fetched from the object store when missing."""
    path = cache_dir() / f"{sha}.h5"
    if path.is_file() and sha256_file(path) == sha:
        return path
    import ray

    data = ray.get(ref[0])
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
    if sha256_file(path) != sha:
        raise WristmimicError(f"dataset copy {path} does not match sha256 {sha}")
    return path


def pack_run(run_dir: Path) -> bytes:
    """A run folder as an uncompressed tar archive (checkpoints and Parquet barely compress)."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w") as tar:
        tar.add(run_dir, arcname=".")
    return buf.getvalue()


def unpack_run(archive: bytes, run_dir: Path) -> None:
    """Put an archive from :func:`pack_run` at ``run_dir``: unpacked beside it, then swapped in by renames."""
    run_dir = Path(run_dir)
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    tag = uuid.uuid4().hex[:8]
    incoming = run_dir.with_name(f".{run_dir.name}.incoming-{tag}")
    old = run_dir.with_name(f".{run_dir.name}.old-{tag}")
    try:
        with tarfile.open(fileobj=io.BytesIO(archive), mode="r") as tar:
            tar.extractall(incoming, filter="data")
        if run_dir.exists():
            run_dir.rename(old)
        incoming.rename(run_dir)
    finally:
        shutil.rmtree(incoming, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)


def _one_line(exc: BaseException) -> str:
    """A worker error as one line: our own errors as they read, others with their type and place."""
    if isinstance(exc, WristmimicError):
        return str(exc)
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    lines = [ln for ln in str(exc).splitlines() if ln.strip()]
    where = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
    place = f" (at {Path(where[0].filename).name}:{where[0].lineno})" if where else ""
    return f"{type(exc).__name__}: {lines[-1] if lines else ''}{place}"


def _since(t0: float) -> float:
    return time.perf_counter() - t0


# ------------------------------------------------------------------------------------------------ driver


class RayExecutor:
    """Runs a pipeline's jobs as Ray tasks (see the module docstring); connects only when there is work."""

    def __init__(self, options: RayOptions):
        self.options = options
        self._started = False

    def run(self, ctx: Context, jobs: list[Job], evaluate: dict[str, Any] | None) -> None:
        """Train (and evaluate) every job not up to date on Ray; record each finished job as it arrives."""
        from wristmimic.evaluate.protocol import load_protocol
        from wristmimic.pipeline import eval_inputs, eval_unit

        protocol = load_protocol(evaluate.get("protocol", "paper")) if evaluate is not None else None
        todo: list[tuple[Job, bool, bool]] = []
        for job in jobs:
            train = not ctx.up_to_date(job.unit, job.inputs, [job.checkpoint])
            ev = protocol is not None and (
                train
                or not ctx.up_to_date(eval_unit(job.run_dir), eval_inputs(job.run_dir, evaluate), [_out(job, protocol)])
            )
            if train or ev:
                todo.append((job, train, ev))
            else:
                ctx.note(job.unit, "up to date")
                if protocol is not None:
                    ctx.note(eval_unit(job.run_dir), "up to date")
        failed: list[tuple[Job, str]] = []
        if todo:
            failed = self._dispatch(ctx, todo, evaluate, protocol)
        ctx.outputs["runs"] = [job.run_dir for job in jobs]
        if protocol is not None:
            ctx.outputs["evals"] = [_out(job, protocol) for job in jobs]
            ctx.outputs["jobs_evaluated"] = True
        if failed:
            lines = [f"  {job.spec.scene} ({job.run_dir.name}): {err}" for job, err in failed]
            raise JobsFailed(
                f"{len(failed)} of {len(todo)} dispatched job(s) failed (the others are recorded; "
                "run again to retry the failed ones):\n" + "\n".join(lines)
            )

    # -- dispatch ------------------------------------------------------------------------------------------
    def _dispatch(
        self,
        ctx: Context,
        todo: list[tuple[Job, bool, bool]],
        evaluate: dict[str, Any] | None,
        protocol: Protocol | None,
    ) -> list[tuple[Job, str]]:
        import ray

        from wristmimic.pipeline import eval_inputs, eval_unit

        opts = self.options
        self._connect(ctx)
        pending: dict[Any, tuple[Job, bool, bool]] = {}
        try:
            flag = ray.remote(num_cpus=0)(StopFlag).remote()
            task = ray.remote(run_job)
            resources = {"num_cpus": opts.cpus_per_job, "num_gpus": opts.gpus_per_job, "max_retries": 1}
            refs: dict[str, Any] = {}
            for job, train, ev in todo:
                sha = job.inputs["dataset_sha256"]
                if sha not in refs:
                    refs[sha] = ray.put(Path(job.spec.dataset).read_bytes())
                work = JobWork(
                    job=replace(job, spec=replace(job.spec, dataset=Path(job.spec.dataset).resolve())),
                    run_dir=str(job.run_dir.resolve()),
                    dataset_sha256=sha,
                    train=train,
                    evaluate=evaluate if ev else None,
                    protocol=protocol if ev else None,
                    cpus=int(opts.cpus_per_job or 1),
                    code=code_fingerprint(),
                )
                archive = pack_run(job.run_dir) if job.run_dir.is_dir() else None
                ref = task.options(name=f"wristmimic job {job.run_dir.name}", **resources).remote(
                    work, [refs[sha]], archive, flag
                )
                pending[ref] = (job, train, ev)
            total, done, failed, stopping = len(pending), 0, [], False
            ctx.echo(f"ray: {total} job(s) dispatched ({opts.cpus_per_job} CPU, {opts.gpus_per_job:g} GPU each)")
            while pending:
                try:
                    ready, _ = ray.wait(list(pending), num_returns=1)
                except KeyboardInterrupt:
                    if stopping:
                        raise
                    stopping = True
                    flag.set.remote()
                    ctx.echo(
                        "ray: Ctrl-C: every job stops after its current training iteration (checkpoint kept) or its "
                        "completed trials; waiting for them (press Ctrl-C again to cancel them and lose that progress)"
                    )
                    continue
                job, train, ev = pending.pop(ready[0])
                try:
                    res: JobResult = ray.get(ready[0])
                except Exception as exc:  # the task itself failed: worker crash, unpicklable input, ...
                    res = JobResult(False, _one_line(exc))
                what = f"done on {res.host} in {res.seconds:.1f} s: {res.note}" if res.ok else f"FAILED: {res.error}"
                what = f"stopped: {res.error}" if res.stopped else what
                ctx.echo(f"ray: {job.run_dir.name}: {what}")
                if res.archive is not None:
                    unpack_run(res.archive, job.run_dir)
                if train and res.trained:
                    ctx.record(job.unit, job.inputs, [job.checkpoint])
                halted = "stopped" if res.stopped else "failed"
                ctx.note(job.unit, "up to date" if not train else "ran" if res.trained else halted)
                if ev:
                    if res.ok:
                        ctx.record(eval_unit(job.run_dir), eval_inputs(job.run_dir, evaluate), [_out(job, protocol)])
                    ctx.note(
                        eval_unit(job.run_dir), "ran" if res.ok else halted if res.trained or not train else "skipped"
                    )
                done += res.ok
                if not res.ok and not res.stopped:
                    failed.append((job, res.error))
                ctx.echo(f"ray: jobs {done} done, {len(pending)} running or queued, {len(failed)} failed (of {total})")
            if stopping:
                ctx.echo("ray: stopped; what the jobs saved is in the work folder: run the pipeline again to resume")
                raise KeyboardInterrupt
            return failed
        except BaseException:  # Ctrl-C or an error here: stop what still runs (its progress is lost)
            for ref in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(ref)
            raise
        finally:
            self._disconnect()

    def _connect(self, ctx: Context) -> None:
        """``ray.init`` for ``local`` or the address; one-line errors for addresses that do not answer."""
        import ray

        opts = self.options
        if ray.is_initialized():  # a Ray the caller started (e.g. a notebook or a test): use it, leave it running
            ctx.echo(f"ray: using the running Ray ({ray.cluster_resources().get('CPU', 0):g} CPU)")
            return
        if opts.address == "local":
            cpus = opts.local_cpus or os.cpu_count() or 1
            if (opts.cpus_per_job or 1) > cpus:
                raise InputError(None, "--ray-cpus-per-job", f"{opts.cpus_per_job} CPUs per job", f"<= {cpus}")
            root = str(Path(wristmimic.__file__).resolve().parents[1])
            env = {"PYTHONPATH": os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])])}
            kw: dict[str, Any] = {"address": "local", "num_cpus": cpus, "runtime_env": {"env_vars": env}}
        else:
            _check_reachable(opts.address)
            kw = {"address": opts.address}
        try:
            ray.init(include_dashboard=False, logging_level="WARNING", **kw)
        except (Exception, SystemExit) as exc:
            raise WristmimicError(f"--ray {opts.address}: cannot start or join Ray ({_one_line(exc)})") from None
        self._started = True
        res = ray.cluster_resources()
        ctx.echo(f"ray: {opts.address}: {res.get('CPU', 0):g} CPU, {res.get('GPU', 0):g} GPU")

    def _disconnect(self) -> None:
        if self._started:
            import ray

            ray.shutdown()
            self._started = False


def _out(job: Job, protocol: Protocol) -> Path:
    return job.run_dir / "eval" / protocol.name


def check_address(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT``, None for ``local`` and ``auto``; a one-line
    error for anything else."""
    if address in ("local", "auto"):
        return None
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    host = host.strip("[]")  # [IPv6]:port
    if not sep or not host or not port.isdigit():
        raise WristmimicError(f"--ray {address}: not an address (expected local, auto, HOST:PORT or ray://HOST:PORT)")
    return host, int(port)


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast, in one line, when ``HOST:PORT`` (or ``ray://HOST:PORT``) does not accept connections
    (``ray.init`` would wait minutes, then exit the process)."""
    hostport = check_address(address)
    if hostport is None:
        return
    host, port = hostport
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise WristmimicError(f"--ray {address}: cannot connect to {host}:{port} ({exc.strerror or exc})") from None
