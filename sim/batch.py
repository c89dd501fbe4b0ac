"""``springflat flatten A.obj B.obj ... --out-dir DIR``: many meshes on all cores, or on a Dask cluster.

Each mesh is one task, :func:`flatten_one`: the same steps as a single ``springflat flatten`` (the
mesh's defaults, ``--init``, the engine, the outputs), run in a worker.  The task takes the mesh file's
bytes and gives back the output files' bytes, so a worker needs no shared file system; the command
writes them into ``DIR`` as ``<mesh name><ending>``, where the endings are the values of ``--out``,
``--history``, ``--plot`` and ``--distortion`` (``--out .dxf --out .pdf``), each mesh's files all or
none (:func:`sim.outputs.all_or_nothing`).

Workers: ``--jobs`` processes (default: the cores this process may use), each a
:class:`sim.workers.WorkerPool` of one, fed one mesh at a time (:func:`_pool_outcomes`), or with
``--scheduler ADDRESS`` a Dask cluster (``distributed.Client``); ``--scheduler local`` starts Dask's own
``LocalCluster`` of ``--jobs`` single-threaded worker processes.  Either way the outputs are the same bytes.

A mesh that fails (unreadable, invalid, a worker that died) is reported on its line and in the table,
and the others go on; with ``--skip-existing`` a mesh whose every output file is in ``DIR`` already, newer than
the mesh file, is ``skipped`` (an interrupted batch run again goes on where it stopped); the exit status is 4 when any mesh
failed, else 3 when any run diverged, else 0 (2: the batch was refused before its first run).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import errno
import io
import os
import sys
import tempfile
import time
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from golden_model.builtin import is_builtin
from golden_model.files import describe_os_error, read_file_bytes
from golden_model.mesh import MeshError, one_line, printable_name, valid_text

from .engines import engine_named
from .exit_codes import EXIT_DIVERGED, EXIT_MESHES_FAILED
from .flatten_run import OUTPUT_OPTIONS, check_options_used, output_paths, overlap_count
from .layouts import AUTO_START, LAYOUT_METHODS
from .outputs import OutputError, OutputWriteError, all_or_nothing, atomic_write, check_distinct, check_link_target, \
    check_output_path, file_ending, folded_name, print_note, when_interrupted
from .patterns import check_not_a_mesh, error_text, pattern_ending, pattern_kind
from .run_options import (USER_ERRORS, OneOutput, UserError, holes_mode, input_files, integer_argument,
                          mesh_names, params_from_args, path_argument, resolve_mesh, strict_json)
from .workers import WorkerPool, local_workers, undo_dask_malloc_trim, wait_for_one


def add_batch_options(parser: argparse.ArgumentParser) -> None:
    """The batch options of ``flatten``: more meshes, ``--out-dir``, ``--jobs``, ``--skip-existing``,
    ``--scheduler``."""
    parser.add_argument("more_meshes", nargs="*", metavar="MESH",
                        help="more meshes, right after the first (no option between them): a batch, one result "
                             "line each")
    parser.add_argument("--out-dir", type=path_argument, action=OneOutput, default=None, metavar="DIR",
                        help="batch: write DIR/<mesh name><ending> for each ending given to --out, --history, "
                             "--plot and --distortion (e.g. --out .dxf --out .pdf --distortion .csv)")
    parser.add_argument("--jobs", type=integer_argument, default=None, metavar="N",
                        help="batch: worker processes (default: every core)")
    parser.add_argument("--skip-existing", action="store_true",
                        help="batch: skip a mesh whose every output file is in --out-dir already and newer than "
                             "the mesh file (to go on after an interrupted batch: each mesh's files are written all "
                             "or none)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS|local",
                        help="batch on a Dask cluster: a scheduler address (tcp://host:8786), or local for Dask's "
                             "LocalCluster with --jobs worker processes")


@dataclass(frozen=True)
class BatchJob:
    """One mesh of a batch, as shipped to a worker.

    Attributes:
        source: the mesh as given on the command line (a file or a built-in name).
        name: the mesh's name: the file's stem, or the built-in's name; names the output files.
        data: the file's bytes (``None`` for a built-in).
        options: the run's options (``argparse`` namespace entries of ``flatten``).
        endings: ``{option: ending}`` of the outputs to write (``out`` may have several).
        scratch: where the worker makes its private directory: the local pool's directory, which this
            process removes however the worker ends (a Ctrl-C ends it at once, with no clean-up of its
            own); ``None`` on a Dask cluster (the worker's temporary directory).
        read_ns: when the mesh file had last changed as it was read (:func:`_mesh_changed_ns`).
    """

    source: str
    name: str
    data: bytes | None
    options: dict
    endings: tuple[tuple[str, str], ...]
    scratch: str | None = None
    read_ns: int = 0


@dataclass
class MeshOutcome:
    """What one mesh gave: its result or why it failed, and its output files.

    Attributes:
        status: the run's status (``converged``, ``max-iterations``, ``diverged``, ``stalled``), ``failed``, or
            ``skipped`` (``--skip-existing``: its files were there).
        summary: the ``--json`` summary of a single run (``None`` when failed).
        line: the one-line result, or the error.
        notes: what the run said on stderr (mesh notes).
        files: ``{ending: bytes}`` of the outputs.
        seconds: the worker's wall time.
    """

    source: str
    name: str
    status: str
    summary: dict | None = None
    line: str = ""
    notes: str = ""
    files: list[tuple[str, bytes]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        return self.status == "failed"


def _tell(name: str, notes: list[str | None]) -> None:
    """A batch mesh's notes on (its captured) stderr, each named by its mesh."""
    for note in filter(None, notes):
        print_note(f"{printable_name(name)}: {note}")


def flatten_one(job: BatchJob) -> MeshOutcome:
    """Run one mesh of a batch (in a worker): the steps of ``springflat flatten`` on a private directory."""
    from .flatten_run import (check_print_size, divergence_note, human_line, json_summary, pattern_notes, run_flatten,
                              notes_on_cut_files, pattern_drawing, run_formats, write_outputs)

    undo_dask_malloc_trim()
    start = time.perf_counter()
    stderr = io.StringIO()
    try:
        scratch = tempfile.TemporaryDirectory(prefix="springflat-batch-", dir=job.scratch)
    except OSError as exc:
        return _no_scratch(job, exc, job.scratch or tempfile.gettempdir(), start)
    with scratch as tmp:
        mesh_path = job.source
        out = Path(tmp) / "out"
        try:
            if job.data is not None:
                (Path(tmp) / "in").mkdir()
                mesh_path = str(Path(tmp) / "in" / Path(job.source).name)
                Path(mesh_path).write_bytes(job.data)
            out.mkdir()
        except OSError as exc:
            return _no_scratch(job, exc, Path(tmp).parent, start)
        # the ending alone picks a pattern's kind: in 'ear.flat' + '.obj' the mesh name's '.flat' is no ending
        stem = job.name.replace(".", "_")
        names = [(option, ending, out / f"{stem}{ending}") for option, ending in job.endings]
        args = argparse.Namespace(**job.options)
        args.mesh = mesh_path
        for option, _, _ in OUTPUT_OPTIONS:
            setattr(args, option, [] if option == "out" else None)
        for option, _, path in names:
            if option == "out":
                args.out.append(path)
            else:
                setattr(args, option, path)
        try:
            with contextlib.redirect_stderr(stderr):
                mesh, defaults = resolve_mesh(mesh_path, holes_mode(args.fill_holes, args.keep_holes))
                params = params_from_args(args, defaults, fixed_point=engine_named(args.engine).fixed_point)
                check_print_size(args, mesh)
                notes: list[str] = []  # each named by its mesh: the workers' notes come in any order
                try:
                    result = run_flatten(args, mesh, params, notes=notes)
                finally:  # the start's notes also where the engine then refuses the mesh
                    _tell(job.name, notes)
                drawing = pattern_drawing(args, mesh, result)
                written = write_outputs(args, mesh, result, drawing)
                _tell(job.name, [divergence_note(params, result),
                                 *pattern_notes(params, mesh, result, formats=run_formats(args)),
                                 *notes_on_cut_files(args, mesh, result, drawing)])  # prints at 1:1000
                summary = json_summary(args, mesh, params, result)
                line = human_line(mesh, result)
            files = [(ending, path.read_bytes()) for _, ending, path in names if path in written]
            return MeshOutcome(job.source, job.name, result.status, summary, line, stderr.getvalue(), files,
                               time.perf_counter() - start)
        except USER_ERRORS + (UserError,) as exc:
            message = str(exc)
        except OSError as exc:
            message = f"cannot access '{exc.filename}': {describe_os_error(exc)}" if exc.filename else str(exc)
        except Exception as exc:  # noqa: BLE001 - one mesh's bug must not end the batch
            message = f"unexpected {type(exc).__name__}: {exc}"
        message = message.replace(mesh_path, job.source)
        return MeshOutcome(job.source, job.name, "failed", None, message, stderr.getvalue(), [],
                           time.perf_counter() - start)


def _no_scratch(job: BatchJob, exc: OSError, where, start: float) -> MeshOutcome:
    """The failure of a worker that could not make its private directory or write its copy of the mesh there (a
    full temporary directory)."""
    return MeshOutcome(job.source, job.name, "failed", None, f"cannot write the worker's files in '{where}': "
                       f"{describe_os_error(exc)} (TMPDIR chooses the directory)", "", [], time.perf_counter() - start)


def in_a_batch(args: argparse.Namespace) -> str:
    """``in a batch``, with what made one when it is not several meshes: one mesh with ``--out-dir`` or
    ``--scheduler`` is a batch too, which a single run's file name would not tell its user."""
    if args.more_meshes:
        return "in a batch"
    return f"in a batch ({'--out-dir' if args.out_dir is not None else '--scheduler'} makes one, of one mesh here)"


def _endings(args: argparse.Namespace) -> tuple[tuple[str, str], ...]:
    """``(option, ending)`` of every output asked for; an ending is a file-name tail such as ``.pdf``."""
    endings = []
    for option, what, suffixes, value in output_paths(args):
        text = str(value)  # the example: an ending the option takes (--plot's .png), the one given if it is one
        example = next((suffix for suffix in suffixes if text.lower().endswith(suffix)), suffixes[0])
        if not text or "/" in text or os.sep in text:
            raise UserError(f"{in_a_batch(args)}, {what} takes a file-name ending such as {example}, not '{text}': "
                            f"each mesh writes --out-dir/<mesh name><ending>")
        if text[0].isalnum():  # 'x.dxf' would write 'bunnyx.dxf': a file name given where an ending belongs
            raise UserError(f"{in_a_batch(args)}, {what} takes a file-name ending that starts with a separator, such "
                            f"as {example} or _flat{example}, not '{text}' (each mesh writes --out-dir/<mesh name>"
                            "<ending>)")
        endings.append((option, text))
    tails = [e for _, e in endings]
    for tail in tails:
        if tails.count(tail) > 1:
            raise UserError(f"the ending '{tail}' is given twice: two outputs would be one file")
    return tuple(endings)


def _check_no_two_meshes_write_one_name(meshes: list[str], names: list[str], endings: tuple[tuple[str, str], ...],
                                        out_dir: Path) -> None:
    """Refuse two meshes whose names and endings make one file name (``a`` with ``.flat.obj``, ``a.flat`` with
    ``.obj``), naming both (the same-file check after this could only name the file twice)."""
    flags = {option: flag for option, flag, _ in OUTPUT_OPTIONS}
    writer: dict[str, tuple[str, str]] = {}  # by the name as out_dir's file system tells names apart
    for mesh, name in zip(meshes, names):
        for option, ending in endings:
            which, file = f"'{mesh}' with {flags[option]} {ending}", f"{name}{ending}"
            first, first_file = writer.setdefault(folded_name(file, out_dir), (which, file))
            if first != which:
                one = "" if first_file == file else f" (its file system takes '{first_file}' and '{file}' for one name)"
                raise UserError(f"{first} and {which} would both write '{out_dir / file}'{one}")


def _check_batch(args: argparse.Namespace, meshes: list[str]
                 ) -> tuple[tuple[tuple[str, str], ...], int, list[str], frozenset[str]]:
    """Refuse what a batch cannot do, before any run; returns the endings, the worker count, the meshes' names
    (:func:`~sim.run_options.mesh_names`) and the names of the meshes ``--skip-existing`` skips (their files all in
    ``--out-dir``)."""
    single = engine_named(args.engine).single
    if single:
        raise UserError(f"--engine {args.engine} runs one mesh at a time ({single}): drop it for a batch")
    if args.init is not None and args.init not in (AUTO_START,) + LAYOUT_METHODS:
        raise UserError(f"{in_a_batch(args)}, --init takes a method ({', '.join((AUTO_START,) + LAYOUT_METHODS)}), "
                        "not a layout file")
    check_options_used(args)
    jobs = local_workers(args.jobs, "--jobs", args.scheduler)
    endings = _endings(args)
    if args.out_dir is not None and not endings:
        raise UserError("--out-dir holds the batch's files, and none is asked for: add --out .ENDING (or --history, "
                        "--plot, --distortion)")
    if endings and args.out_dir is None:
        raise UserError("a batch (several meshes, or --scheduler) writes its outputs to --out-dir DIR (the endings "
                        "name the files)")
    names = mesh_names(meshes)
    if args.out_dir is not None:
        out_dir = args.out_dir
        # a skipped mesh's files are not written (a finished one made read-only is no obstacle), but they must
        # still be its outputs: not a mesh of the batch, nor an OBJ springflat did not write
        skipped = frozenset(name for source, name in zip(meshes, names)
                            if args.skip_existing and _already_written(out_dir, name, endings, source))
        written = [name for name in names if name not in skipped]
        source_of = dict(zip(names, meshes))
        flags = {option: (what, suffixes) for option, what, suffixes in OUTPUT_OPTIONS}
        for option, ending in endings:
            if option == "out":
                pattern_kind(Path(ending))
            for name in written:  # before any run: a later mesh's obstacle must not end the batch
                try:
                    check_output_path(out_dir / f"{name}{ending}", *flags[option], typed=False)
                except OutputError as exc:  # a finished mesh's file made read-only, its mesh touched since?
                    if args.skip_existing and all((out_dir / f"{name}{e}").is_file() for _, e in endings):
                        raise OutputError(f"{exc} ({printable_name(source_of[name])} is newer than its files, so "
                                          "--skip-existing runs it again)") from None
                    raise
        _check_no_two_meshes_write_one_name(meshes, names, endings, out_dir)
        # no mesh's output may be a mesh of the batch (or the --init or --formats file), nor another's output
        check_distinct([(flags[option][0], out_dir / f"{name}{ending}") for name in names for option, ending in endings],
                       [item for mesh in meshes
                        for item in input_files(argparse.Namespace(**{**vars(args), "mesh": mesh}))])
        for option, ending in endings:
            for name in names:
                check_link_target(out_dir / f"{name}{ending}", flags[option][0],
                                  pattern_ending if option == "out" else file_ending)
                if option == "out":
                    check_not_a_mesh(out_dir / f"{name}{ending}", flags[option][0])
    else:
        skipped = frozenset()
    return endings, jobs, names, skipped


def _job(source: str, name: str, options: dict, endings) -> BatchJob | MeshOutcome:
    """The job of one mesh, or its failure when its file cannot be read here; it keeps when the file had last
    changed as it was read."""
    if is_builtin(source):
        return BatchJob(source, name, None, options, endings)
    try:
        changed = _mesh_changed_ns(source)
        return BatchJob(source, name, read_file_bytes(source, "mesh", MeshError), options, endings, read_ns=changed)
    except OSError as exc:
        return MeshOutcome(source, name, "failed", line=f"cannot read mesh '{source}': {describe_os_error(exc)}")
    except MeshError as exc:
        return MeshOutcome(source, name, "failed", line=str(exc))


def _changed_while_it_ran(job: BatchJob, out_dir: Path, written: list[str]) -> str | None:
    """Where the mesh file changed after the batch read it (exported again while the batch ran): its files are of
    the mesh as read, so they are given the mesh's time as read, and ``--skip-existing`` runs it again; the note
    that says so, or ``None``."""
    try:
        if job.data is None or _mesh_changed_ns(job.source) == job.read_ns:
            return None
    except OSError:  # (gone since: nothing to run again)
        return None
    for ending in written:
        os.utime(out_dir / f"{job.name}{ending}", ns=(job.read_ns, job.read_ns))
    return (f"{printable_name(job.source)} changed while the batch ran: its files are of the mesh as it was read, "
            "and --skip-existing runs it again")


def _already_written(out_dir: Path, name: str, endings: tuple[tuple[str, str], ...], source: str) -> bool:
    """Whether every output file of the mesh ``name`` is in ``out_dir`` and newer than the mesh file ``source``
    (``--skip-existing``): a batch writes a mesh's files all or none, so an interrupted batch left each mesh with
    all of them or none; a mesh exported again since its files were written runs again, as make would (a pattern
    of the old mesh would go to the cutter), and so does one of the same time (a file system that keeps whole
    seconds cannot tell them apart)."""
    files = [out_dir / f"{name}{ending}" for _, ending in endings]
    if not all(path.is_file() for path in files):
        return False
    try:
        changed = _mesh_changed_ns(source)
    except OSError:  # (an unreadable mesh fails in its own line, as a run)
        return False
    return all(path.stat().st_mtime_ns > changed for path in files)


def _mesh_changed_ns(source: str) -> int:
    """When the mesh file ``source`` last changed, in ns (0 for a built-in): its own time, or a symbolic link's
    where that is later (a link pointed at another export is a change, as make -L counts it), or its inode's
    (``st_ctime``) where that is later: a mesh moved or copied into place with its old time kept (``mv``,
    ``cp -p``, an unpacked archive) is a change too."""
    if is_builtin(source):
        return 0
    link, target = os.lstat(source), os.stat(source)
    return max(link.st_mtime_ns, target.st_mtime_ns, target.st_ctime_ns)


def _write_files(out_dir: Path, outcome: MeshOutcome) -> None:
    """The mesh's output files in ``out_dir``, all or none; a write error fails the mesh."""
    try:
        with all_or_nothing():
            for ending, data in outcome.files:
                with atomic_write(out_dir / f"{outcome.name}{ending}") as tmp:
                    Path(tmp).write_bytes(data)
    except OutputError as exc:  # one that turned up during the run (a directory or FIFO of its name)
        outcome.status, outcome.line = "failed", str(exc)


def _died(job: BatchJob, exc: BaseException) -> MeshOutcome:
    from concurrent.futures.process import BrokenProcessPool, _RemoteTraceback

    if isinstance(exc, BrokenProcessPool) and exc.__cause__ is None:
        line = "its worker process died (killed by a signal, or out of memory)"
    else:  # a result that could not be sent back, ...: what caused it (not the worker's traceback, as text)
        cause = exc if exc.__cause__ is None or isinstance(exc.__cause__, _RemoteTraceback) else exc.__cause__
        line = f"the worker failed: {type(cause).__name__}: {one_line(str(cause))}"
    return MeshOutcome(job.source, job.name, "failed", line=line)


def _pool_outcomes(jobs: list[BatchJob], workers: int):
    """Each job's outcome as it finishes, on local worker processes: a pool of one process per worker, fed
    one job at a time, so that a worker that dies fails its own mesh only and its pool is replaced for the
    others (one pool of many processes fails every task it holds when any of them dies). A pool's process is
    forked while the other pools' threads run; those threads hold only their own pool's queue locks, which the
    new process never takes (it reads its own pool's queues), so the fork cannot leave it a lock held."""
    from concurrent.futures.process import BrokenProcessPool

    queue = list(jobs)
    running: dict = {}  # future -> (its pool, its job)
    # the workers' directories in one of this process's, removed once the workers have ended (stopped by a
    # Ctrl-C, or killed), with whatever they held
    with tempfile.TemporaryDirectory(prefix="springflat-batch-") as scratch, contextlib.ExitStack() as pools:
        def start(pool: WorkerPool) -> None:
            job = dataclasses.replace(queue.pop(0), scratch=scratch)
            running[pool.submit(flatten_one, job)] = (pool, job)

        for _ in range(min(workers, len(queue))):
            start(pools.enter_context(WorkerPool(1)))
        while running:
            done = wait_for_one(running)
            for future in done:
                pool, job = running.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:  # noqa: BLE001 - a worker that died fails its mesh only
                    outcome = _died(job, exc)
                    if isinstance(exc, BrokenProcessPool) and queue:
                        pool = pools.enter_context(WorkerPool(1))
                if queue:
                    start(pool)
                yield outcome


@contextlib.contextmanager
def _quiet_dask_workers() -> Iterator[None]:
    """Dask's warnings in the block, in this process and in the worker processes it starts (each reads its
    logging levels from the environment on its start), left out: the ones a stopped batch gives (a task
    cancelled, a worker killed; multiprocessing's resource tracker, started here too, on the semaphores
    of a killed worker, which it removes) are not for the user; errors still show in this process. The
    workers log only what is critical: their errors are this process's to report (a task's exception comes
    back with its result, a dead worker as such), and the one a Ctrl-C can give (a heartbeat that finds the
    scheduler gone while the cluster closes) is not the user's."""
    import logging

    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.ERROR)
    before = {name: os.environ.get(name) for name in (*QUIET_DASK_ENVIRONMENT, "PYTHONWARNINGS")}
    os.environ.update(QUIET_DASK_ENVIRONMENT)
    os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (before["PYTHONWARNINGS"], *QUIET_DASK_WARNINGS)))
    try:
        yield
    finally:
        logger.setLevel(level)
        for name, value in before.items():
            if value is None:
                del os.environ[name]
            else:
                os.environ[name] = value


#: The environment of the processes a local cluster starts: Dask's ``logging.distributed`` level.
QUIET_DASK_ENVIRONMENT = {"DASK_LOGGING__DISTRIBUTED": "critical"}
#: The warning filters added to theirs (``PYTHONWARNINGS``, a comma-separated list the user's own may be
#: in): the resource tracker's.
QUIET_DASK_WARNINGS = ("ignore:resource_tracker:UserWarning",)


@contextlib.contextmanager
def dask_client(scheduler: str, workers: int):
    """A ``distributed.Client``: of a new ``LocalCluster`` of ``workers`` single-threaded processes for
    ``local``, else connected to the scheduler at ``scheduler`` (a one-line error when it cannot be reached)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a dependency of springflat
        raise UserError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    with contextlib.ExitStack() as stack:
        quiet = stack.enter_context(_quiet_when_abandoned())  # last out: after the cluster and client close
        if scheduler == "local":  # Ctrl-C is this process's to answer: it ends the workers (sim.dask_worker)
            stack.enter_context(_quiet_dask_workers())  # for the cluster's life: its end warns too
            # no dashboard; the scheduler's HTTP server (its health routes) on a free port, not on the
            # dashboard's 8787, so that clusters side by side (two springflat runs) do not warn of each other
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None,
                                                       scheduler_kwargs={"dashboard_address": ":0"},
                                                       preload=["sim.dask_worker"]))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout="10s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise UserError(f"cannot reach the Dask scheduler at '{scheduler}': {exc}") from None
        try:
            yield client
        except BaseException:  # an error, Ctrl-C, a kill: the command says in one line what happened
            quiet()
            raise


@contextlib.contextmanager
def _quiet_when_abandoned() -> Iterator[Callable[[], None]]:
    """A function that turns logging off until the block ends, called where the work is abandoned, and
    called by a stop signal the moment it arrives: Dask and tornado then log, from their own thread, the
    tasks in flight cancelled, their results "forgotten", a stream closed, which are the abandon's, not the
    user's (the command says in one line what happened). ``logging.disable``, as Dask's configuration
    gives its loggers levels of their own."""
    import logging

    before = logging.root.manager.disable  # what the caller had disabled (logging.disable's own state)

    def quiet() -> None:
        logging.disable(logging.CRITICAL)

    try:
        with when_interrupted(quiet):
            yield quiet
    finally:
        logging.disable(before)


def _dask_outcomes(jobs: list[BatchJob], scheduler: str, workers: int):
    """Each job's outcome as it finishes, on a Dask cluster (``local``: a ``LocalCluster`` of ``workers``)."""
    from distributed import as_completed

    with dask_client(scheduler, workers) as client:
        futures = client.map(flatten_one, jobs, pure=False)
        by_key = {future.key: job for future, job in zip(futures, jobs)}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # noqa: BLE001 - a worker that died fails its mesh only
                yield _died(by_key[future.key], exc)


@contextlib.contextmanager
def _output_directory(path: Path | None) -> Iterator[None]:
    """``--out-dir`` made, with its missing parents, for the block; at its end those of them still empty are
    removed again (a refusal, Ctrl-C, no mesh wrote a file): a batch leaves no empty
    directory that it made."""
    if path is None:
        yield
        return
    if path.exists() and not path.is_dir():
        raise UserError(f"--out-dir '{path}' exists and is not a directory")
    if path.is_symlink() and not path.exists():
        try:
            os.stat(path)
        except OSError as exc:  # a link to nothing, or a loop of links
            if exc.errno == errno.ELOOP:
                raise UserError(f"--out-dir '{path}' is a loop of symbolic links: it names no directory") from None
        raise UserError(f"--out-dir '{path}' is a symbolic link to '{os.readlink(path)}', which does not exist")
    # ('a/../b' makes 'a' and 'b': 'a/..' names no directory of its own)
    missing = [p for p in (path, *path.parents) if not p.exists() and p.name not in ("", ".", "..")]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputWriteError(path, exc, "--out-dir") from None
    try:
        yield
    finally:
        for made in missing:  # the deepest first
            try:
                made.rmdir()
            except OSError:  # not empty: a mesh's files are in it (and so in each one above it)
                continue


def cmd_batch(args: argparse.Namespace) -> int:
    """Flatten every mesh given; print a line per mesh as it finishes, then a table; the exit status."""
    with _output_directory(None if args.out_dir is None else args.out_dir):
        return _run_batch(args, [args.mesh, *args.more_meshes])


def _run_batch(args: argparse.Namespace, meshes: list[str]) -> int:
    endings, workers, names, skipped_names = _check_batch(args, meshes)
    options = {k: v for k, v in vars(args).items() if k not in ("func", "mesh", "more_meshes")}
    start = time.perf_counter()
    outcomes: dict[str, MeshOutcome] = {}
    pending: list[BatchJob] = []
    for source, name in zip(meshes, names):
        if name in skipped_names:
            outcomes[name] = MeshOutcome(source, name, "skipped",
                                         line=f"skipped: its files are in {printable_name(str(args.out_dir))}")
            continue
        job = _job(source, name, options, endings)
        if isinstance(job, MeshOutcome):
            outcomes[name] = job
        else:
            pending.append(job)
    pending.sort(key=lambda job: -len(job.data or b""))  # the largest first: the last task to start is short
    count = min(workers, max(1, len(pending)))
    where = (f"Dask scheduler {args.scheduler}" if args.scheduler not in (None, "local")
             else f"{count} {'Dask ' if args.scheduler else ''}worker process{'es' if count != 1 else ''}")
    if not pending:  # every mesh skipped, or unreadable here: no worker starts
        where = "no worker process"
    skipped = len(skipped_names)
    if not args.json:
        print(f"springflat: {len(meshes)} mesh{'es' if len(meshes) != 1 else ''}"
              + (f" ({skipped} skipped: {'their' if skipped > 1 else 'its'} files are in "
                 f"{printable_name(str(args.out_dir))}, newer than the mesh; the options they were made with are "
                 "not compared: remove them to make them again)" if skipped else "")
              + (f" on {where}" if pending else ""), file=sys.stderr)
    done = 0
    unwritable: list[OSError] = []  # the standard output's error: the batch goes on, its files are written

    def say(line: str) -> None:
        if not unwritable:
            try:
                print(line, flush=True)
            except OSError as exc:
                unwritable.append(exc)

    def report(outcome: MeshOutcome) -> None:
        nonlocal done
        done += 1
        if outcome.notes:
            sys.stderr.write(outcome.notes)
        if args.json:
            # a file name's undecodable bytes as \xff, as the table prints them, not lone surrogates (which no
            # JSON reader can turn back into a name); any other character as it is (JSON escapes its own)
            record = {"source": valid_text(outcome.source), "mesh": printable_name(outcome.name),
                      "seconds": round(outcome.seconds, 3)}
            record.update(outcome.summary or {})
            if outcome.failed:  # also a run that finished but whose files could not be written
                record.update(status="failed", error=outcome.line)
            elif outcome.status == "skipped":
                record["status"] = "skipped"
            files = [e for _, e in endings] if outcome.status == "skipped" else [e for e, _ in outcome.files]
            record["files"] = [valid_text(str(args.out_dir / f"{outcome.name}{e}")) for e in files] \
                if args.out_dir is not None and not outcome.failed else []
            say(strict_json(record))
        elif outcome.failed:
            say(f"[{done}/{len(meshes)}] {printable_name(outcome.source)}: failed: {one_line(outcome.line)}")
        elif outcome.status == "skipped":
            say(f"[{done}/{len(meshes)}] {printable_name(outcome.source)}: {outcome.line}")
        else:
            say(f"[{done}/{len(meshes)}] {outcome.line} ({outcome.seconds:.1f} s)")

    for outcome in outcomes.values():
        report(outcome)
    if pending:
        stream = (_pool_outcomes(pending, workers) if args.scheduler is None
                  else _dask_outcomes(pending, args.scheduler, workers))
        job_of = {job.name: job for job in pending}
        for outcome in stream:
            if args.out_dir is not None and not outcome.failed:
                _write_files(args.out_dir, outcome)
                written = [ending for ending, _ in outcome.files]
                if not outcome.failed and written and (note := _changed_while_it_ran(job_of[outcome.name],
                                                                                     args.out_dir, written)):
                    outcome.notes += f"springflat: note: {note}\n"
            outcomes[outcome.name] = outcome
            report(outcome)
    ordered = [outcomes[name] for name in names]
    elapsed = time.perf_counter() - start
    failed = [o for o in ordered if o.failed]
    diverged = [o for o in ordered if o.status == "diverged"]
    if args.json:
        say(strict_json({"batch": {"meshes": len(ordered), "failed": len(failed), "diverged": len(diverged),
                                   "skipped": sum(o.status == "skipped" for o in ordered),
                                   "seconds": round(elapsed, 3), "workers": where}}))
    else:
        say(summary_table(ordered))
        statuses = {}
        for o in ordered:
            statuses[o.status] = statuses.get(o.status, 0) + 1
        counts = ", ".join(f"{n} {s}" for s, n in statuses.items())
        overlapping = sum(bool(overlap_count(o.summary)) for o in ordered if o.summary is not None)
        counts += f"; {overlapping} overlapping {'themselves' if overlapping > 1 else 'itself'}" if overlapping else ""
        say(f"{len(ordered)} mesh{'es' if len(ordered) != 1 else ''}: {counts}; {elapsed:.1f} s on {where}")
    if failed:  # each with its reason: the progress lines that gave them may have scrolled away
        print(f"springflat: error: {len(failed)} of {len(ordered)} meshes failed:", file=sys.stderr)
        for o in failed:
            print(f"  {printable_name(o.source)}: {one_line(o.line)}", file=sys.stderr)
    if unwritable:  # the table is lost: status 2 whatever the runs gave
        written = sum(1 for o in ordered if o.files and not o.failed)
        raise OutputError(f"cannot write standard output: {describe_os_error(unwritable[0])} (the batch ran to its "
                          "end" + (f": {written} mesh{'es' if written != 1 else ''}' files written to --out-dir)"
                                   if args.out_dir is not None else ")"))
    if failed:
        return EXIT_MESHES_FAILED
    return EXIT_DIVERGED if diverged else 0


def summary_table(outcomes: list[MeshOutcome]) -> str:
    """A plain-text table: one row per mesh, in the order given."""
    rows = [("mesh", "status", "iterations", "E_S", "E_C", "folded", "overlaps", "seconds")]
    for o in outcomes:
        name = printable_name(o.name)  # a file's stem may hold a newline: one row each
        if o.failed or o.summary is None:
            rows.append((name, o.status if o.status == "skipped" else "failed", "", "", "", "", "",
                         f"{o.seconds:.1f}"))
        else:
            s = o.summary
            overlaps = overlap_count(s)
            rows.append((name, s["status"], str(s["iterations"]), error_text(s["area_error"]),
                         error_text(s["shape_error"]), str(s["folded"]), "" if overlaps is None else str(overlaps),
                         f"{o.seconds:.1f}"))
    widths = [max(_columns(row[k]) for row in rows) for k in range(len(rows[0]))]
    lines = ["  ".join(cell + " " * (w - _columns(cell)) if k < 2 else " " * (w - _columns(cell)) + cell
                       for k, (cell, w) in enumerate(zip(row, widths)))
             for row in rows]
    return "\n".join(line.rstrip() for line in lines)


def _columns(text: str) -> int:
    """The terminal columns ``text`` takes: two for a wide character (CJK), none for a mark that joins the one
    before it (an accent, a Thai vowel, a variation selector; a Hangul vowel or final of a decomposed syllable)
    or an invisible format character."""
    return sum(0 if unicodedata.category(c) in ("Mn", "Me", "Cf") or "\u1160" <= c <= "\u11ff"
               else 2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text)
