"""Running POV-Ray: its command line, its processes, and renders.

This is the one place that builds a POV-Ray command line (:func:`render_switches`,
:func:`povray_command`) and starts a POV-Ray process (:func:`start_povray`).  It
relies on this behaviour of POV-Ray 3.7.0.10 (the record is in docs/decisions/pov.md):

* ``-D`` is required (Debian's ``povray.ini`` sets ``Display=On``);
  ``-V -GR -GS`` leave only warnings and errors on stderr (plus a banner);
* exit code 0 on success (also with warnings), 1 on a parse error or a
  missing input file;
* a failed render deletes or truncates the output file, so :func:`render`
  always writes to a temporary name next to the final file and renames it
  only on success;
* the fatal-error log (``+GF``) must be given as a bare file name; POV-Ray
  writes it into the image's folder and refuses any name with a folder part
  ("Stream output files must reside in same directory as image output file");
* ``+SR``/``+ER``/``+SC``/``+EC`` values in (0, 1] are fractions of the image,
  so "+ER1" means the whole height; :func:`pixel_range_args` takes 0-based pixel
  ranges and writes them unambiguously;
* POV-Ray resolves ``#include`` and image-map file names relative to its
  working directory and its library paths (``+L``), *not* relative to the
  file that contains the ``#include``.  :func:`render` runs in the folder of
  the ``.pov`` file; pass the folders of included scenes as
  ``library_paths``.

The executable and its version come from :mod:`povlens.pov.executable`; the
user's own POV-Ray options (library paths, clock, passthrough) from
:mod:`povlens.pov.povray_options`.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import shlex
import shutil
import subprocess
import tempfile
import time
import uuid
from pathlib import Path
from typing import IO, Iterable, Sequence

from povlens.errors import PovrayError, UsageError
from povlens.pov.executable import ENV_VAR, find_povray
from povlens.pov.povray_options import PovrayOptions, as_povray_options
from povlens.pov.povray_output import povray_failure
from povlens.pov.povray_paths import command_line_path
from povlens.util.files import atomic_output
from povlens.util.signals import interrupts_deferred, starting_process

__all__ = [
    "pixel_range_args",
    "render_switches",
    "povray_command",
    "priority_tools",
    "start_povray",
    "FIRST_OUTPUT_S",
    "poll_interval_s",
    "output_written",
    "povray_finished",
    "render",
    "start_render",
    "RenderJob",
]

#: Output file suffix -> POV-Ray output-format switch.
_FORMATS = {".exr": "+FE", ".png": "+FN", ".hdr": "+FH", ".tga": "+FT", ".ppm": "+FP"}


# ---------------------------------------------------------------------------
# the command line

#: Switches of every run: no display window, only warnings and errors on stderr.
_QUIET = ("-D", "-V", "-GR", "-GS")

#: Start and end switches of a pixel range, and the name of its axis in messages.
_RANGE_SWITCHES = {"row": ("+SR", "+ER"), "col": ("+SC", "+EC")}


def pixel_range_args(start: int | None, end: int | None, size: int, axis: str = "row") -> list[str]:
    """POV-Ray's ``+SR``/``+ER`` (``axis="row"``) or ``+SC``/``+EC`` (``"col"``)
    switches for the 0-based half-open pixel range [start, end).

    Parameters
    ----------
    start, end : pixels of the rendered image, 0 = top row / left column; None for
        the image's edge.
    size : the rendered image's height (rows) or width (columns), pixels.
    axis : ``"row"`` or ``"col"``.

    Returns
    -------
    list of str
        No switch for a full range.  POV-Ray counts from 1 and reads values in (0, 1]
        as fractions of the image, so "+ER1" would mean the whole image: an end of 1
        is written as the fraction 1.5/size, which POV-Ray truncates to row 1.

    Raises
    ------
    UsageError
        Unless 0 <= start < end <= size.
    """
    start_flag, end_flag = _RANGE_SWITCHES[axis]
    s = 0 if start is None else int(start)
    e = size if end is None else int(end)
    if not (0 <= s < e <= size):
        raise UsageError(
            f"bad {axis} range [{start}, {end}) for an image {size} pixels wide/high",
            f"use 0 <= start_{axis} < end_{axis} <= {size}",
        )
    args = []
    if s > 0:
        args.append(f"{start_flag}{s + 1}")  # >= 2: always read as a pixel number
    if e < size:
        args.append(f"{end_flag}{e}" if e >= 2 else f"{end_flag}{1.5 / size:.9f}")
    return args


def render_switches(
    image: str | os.PathLike,
    width: int,
    height: int,
    *,
    threads: int = 1,
    start_row: int | None = None,
    end_row: int | None = None,
    start_col: int | None = None,
    end_col: int | None = None,
    library_paths: Iterable[str | os.PathLike] = (),
    extra_args: Sequence[str] = (),
    povray_options: PovrayOptions | None = None,
) -> list[str]:
    """The switches of a render after the file names: format, size, no anti-aliasing,
    threads, pixel ranges, library paths, the user's ``povray_options``, then
    ``extra_args`` (both may override povlens's own switches).

    Parameters
    ----------
    image : the output image; its suffix chooses the format (``.exr``, ``.png``,
        ``.hdr``, ``.tga``, ``.ppm``).
    width, height : the rendered image's size, pixels.
    threads : POV-Ray's render threads (``+WT``).
    start_row, end_row, start_col, end_col : the traced sub-rectangle, 0-based
        half-open pixel ranges (:func:`pixel_range_args`).
    library_paths : folders where POV-Ray looks for ``#include`` files (``+L``, made
        absolute).
    extra_args : further POV-Ray switches or ``Name=value`` options of povlens's own
        (not checked).
    povray_options : the user's library paths (after ``library_paths``), clock and
        passthrough options (:class:`~povlens.pov.povray_options.PovrayOptions`,
        checked when it was made); None for none.

    Returns
    -------
    list of str

    Raises
    ------
    UsageError
        For an unknown suffix, a size or thread count below 1, or a bad range;
        :class:`~povlens.errors.ParameterError` if ``povray_options`` is not a
        :class:`~povlens.pov.povray_options.PovrayOptions`.
    """
    image = Path(image)
    fmt = _FORMATS.get(image.suffix.lower())
    if fmt is None:
        raise UsageError(
            f"cannot render to {image}: unknown image suffix {image.suffix!r}",
            "use one of " + ", ".join(sorted(_FORMATS)),
        )
    width, height, threads = int(width), int(height), int(threads)
    if width < 1 or height < 1:
        raise UsageError(f"bad image size {width}x{height}", "width and height must be >= 1")
    if threads < 1:
        raise UsageError(f"bad thread count {threads}", "use threads >= 1")
    spans = pixel_range_args(start_row, end_row, height, "row")
    spans += pixel_range_args(start_col, end_col, width, "col")
    user = as_povray_options(povray_options).switches()
    return [
        fmt, f"+W{width}", f"+H{height}", "-A", f"+WT{threads}",
        *spans,
        *(f"+L{command_line_path(Path(p).absolute())}" for p in library_paths),
        *user,
        *extra_args,
    ]  # fmt: skip


def povray_command(executable: str, scene: str, image: str, switches: Sequence[str],
                   error_log: str | None = None) -> list[str]:
    """The POV-Ray command line rendering ``scene`` to ``image``.

    Parameters
    ----------
    executable : the POV-Ray program (:func:`find_povray`).
    scene, image : file names as POV-Ray sees them from its working directory.
    switches : from :func:`render_switches`.
    error_log : a bare file name for POV-Ray's fatal-error log (``+GF``), written
        into the image's folder; None for none.

    Returns
    -------
    list of str
        ``[executable, -D, -V, -GR, -GS, [+GF<log>], +I<scene>, +O<image>, *switches]``.
    """
    log = [f"+GF{error_log}"] if error_log is not None else []
    return [executable, *_QUIET, *log, f"+I{scene}", f"+O{image}", *switches]


# ---------------------------------------------------------------------------
# starting and watching a process


@functools.lru_cache(maxsize=None)
def priority_tools() -> tuple[str | None, str | None]:
    """Paths of util-linux ``chrt`` and coreutils ``nice``, or None.  ``chrt`` only
    where Python knows ``SCHED_IDLE`` and a first ``chrt --idle 0 true`` works (a
    sandbox may forbid the policy: chrt would then fail instead of running POV-Ray;
    the ``preexec_fn`` falls back to nice 19)."""
    chrt = shutil.which("chrt") if hasattr(os, "SCHED_IDLE") else None
    true = shutil.which("true")
    if chrt is not None:
        try:
            ok = true is not None and subprocess.run(
                [chrt, "--idle", "0", true], stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=10).returncode == 0
        except (OSError, subprocess.SubprocessError):
            ok = False
        chrt = chrt if ok else None
    return chrt, shutil.which("nice")


def _lower_priority(nice: int, idle: bool) -> tuple[list[str], object]:
    """How :func:`start_povray` lowers POV-Ray's priority: (command prefix,
    ``preexec_fn``).

    A prefix program where there is one: ``chrt --idle 0`` (``SCHED_IDLE``) or
    ``nice -n N``, which sets the policy and execs POV-Ray in the same process, so
    Popen can start the child with ``vfork``; a ``preexec_fn`` forces a full
    ``fork`` of this large, threaded process with the interpreter lock held
    (several times slower: docs/decisions/pov.md).  The ``preexec_fn`` (the same
    settings, made in the child) is the fallback."""
    chrt, nice_cmd = priority_tools()
    if idle:
        if chrt is not None:
            return [chrt, "--idle", "0"], None

        def lower():
            try:
                os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            except (AttributeError, OSError):
                os.nice(19)
        return [], lower
    if nice > 0:
        if nice_cmd is not None:
            return [nice_cmd, "-n", str(int(nice))], None
        return [], lambda: os.nice(nice)
    return [], None


def start_povray(cmd: Sequence[str], cwd: str | os.PathLike, stderr: IO, *, nice: int = 0,
                 idle: bool = False) -> subprocess.Popen:
    """Start the POV-Ray command ``cmd`` (:func:`povray_command`) in the folder ``cwd``.

    Parameters
    ----------
    cmd : the command line.
    cwd : POV-Ray's working directory (file names in ``cmd`` are relative to it).
    stderr : an open file for POV-Ray's standard error (a file, not a pipe: nobody
        reads it while POV-Ray runs, and a chatty scene must not block on it).
    nice : > 0 lowers the scheduling priority by that much.
    idle : run only on CPU time nothing else wants (Linux ``SCHED_IDLE``, else
        nice 19).

    Returns
    -------
    subprocess.Popen
        stdin and stdout are ``/dev/null``.

    Raises
    ------
    PovrayError
        If the program cannot be started.
    povlens.util.signals.ProcessesStopped
        If the command is ending (its processes were stopped).
    """
    prefix, preexec = _lower_priority(nice, idle)
    proc = None
    try:
        # An interrupt inside Popen, after the fork, would lose the child (Popen has
        # no handle to return): hold it until the process is ours, then stop it.  No
        # process starts once the command has stopped its processes (a thread still
        # starting the depth probe's renders: util.signals.starting_process).
        with interrupts_deferred(), starting_process():
            proc = subprocess.Popen(
                prefix + list(cmd),
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=stderr,
                preexec_fn=preexec,
            )
        return proc
    except BaseException as exc:
        if proc is not None:
            proc.kill()
            proc.wait()
        if isinstance(exc, FileNotFoundError):
            raise PovrayError(
                f"POV-Ray at {cmd[0]} could not be started",
                f"check the installation or set {ENV_VAR} to a working povray",
            ) from None
        if isinstance(exc, OSError):
            raise PovrayError(
                f"cannot run POV-Ray ({cmd[0]}) in {cwd}: {exc.strerror or exc}",
                "check that the folder exists and the program is executable",
            ) from None
        raise


#: No POV-Ray run has written its image this soon after its start (s): POV-Ray's
#: start-up alone sits idle ~0.2 s (docs/decisions/pov.md).  Younger jobs are not
#: examined, so waiting takes less time from the Python threads that work.
FIRST_OUTPUT_S = 0.2

#: Waiting for POV-Ray runs polls them (their exit, their closed image:
#: :func:`povray_finished`) every ``POLL_SHARE`` of the age of the oldest one, between
#: ``POLL_MIN_S`` and ``POLL_MAX_S``: a finished run is noticed within 2 % of its time
#: (at most 50 ms), and sixteen runs in flight for a minute are not examined 200
#: times a second each, which took 1.4 CPU-s of 2 cores from POV-Ray on a 34 s render
#: (docs/decisions/planning.md, "Waiting costs CPU").
POLL_SHARE = 0.02
POLL_MIN_S = 0.005
POLL_MAX_S = 0.05


def poll_interval_s(age_s: float) -> float:
    """Seconds to sleep between two looks at POV-Ray runs the oldest of which started
    ``age_s`` seconds ago (:data:`POLL_SHARE`)."""
    return min(POLL_MAX_S, max(POLL_MIN_S, POLL_SHARE * float(age_s)))


def output_written(pid: int, path: Path) -> bool:
    """True once process ``pid`` has written ``path`` and closed it (Linux: no
    descriptor in /proc/PID/fd points to it).

    POV-Ray 3.7 writes its image in one go at the end of the render and then
    idles ~0.3 s before it exits (docs/decisions/pov.md); the image is final once
    closed, so the caller need not wait for the exit.  Only a process running a
    POV-Ray executable is judged early: a wrapper script in POVLENS_POVRAY (its
    executable is the shell) may still have work to do after its POV-Ray child
    exits, so it gives False until it exits.  A process with children is never
    judged early either.
    """
    try:
        if "povray" not in os.path.basename(os.readlink(f"/proc/{pid}/exe")):
            return False
        if Path(path).stat().st_size == 0:
            return False
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                if f.read().strip():
                    return False
        target = str(Path(path).resolve())
        fd_dir = f"/proc/{pid}/fd"
        for fd in os.listdir(fd_dir):
            try:
                if os.readlink(f"{fd_dir}/{fd}") == target:
                    return False
            except OSError:
                continue
        return True
    except OSError:
        return False


def povray_finished(proc: subprocess.Popen, image: str | os.PathLike, age_s: float,
                    products: Sequence[str | os.PathLike] = ()) -> bool:
    """True once POV-Ray has exited, or has written and closed ``image`` and every file
    of ``products`` (:func:`output_written`; it is then killed, as nothing is left but
    its shutdown, and ``proc.returncode`` is set to 0).

    Parameters
    ----------
    proc : the process of :func:`start_povray`.
    image : the image it writes.
    age_s : seconds since it started; below :data:`FIRST_OUTPUT_S` only its exit is
        checked.
    products : other files it writes that must be whole: a radiosity file
        (``+RFO``) is finished ~0.1 s after the image is closed (measured:
        ``raddem.pov`` at 320x240, image closed at 0.45 s, the file's last 700 bytes
        written at 0.55 s, the exit at 0.75 s).
    """
    if proc.poll() is not None:
        return True
    if age_s < FIRST_OUTPUT_S:
        return False
    if output_written(proc.pid, Path(image)) and all(
            Path(p).is_file() and output_written(proc.pid, Path(p)) for p in products):
        proc.kill()  # SIGTERM would run POV-Ray's slow shutdown
        proc.wait()
        proc.returncode = 0
        return True
    return False


# ---------------------------------------------------------------------------
# rendering


def render(pov_path: str | os.PathLike, out_path: str | os.PathLike, width: int, height: int,
           **options) -> Path:
    """Render ``pov_path`` to ``out_path`` (``width`` x ``height`` pixels) and wait.

    Runs ``povray -D -V -GR -GS +I<pov> +O<tmp> +F? +W +H -A +WT<threads>
    [+SR +ER +SC +EC] [+L...] [povray_options] [extra_args]`` with the working
    directory set to the folder of ``pov_path`` (or ``cwd``).  The output format follows the
    suffix of ``out_path`` (``.exr`` -> OpenEXR, linear half float; also
    ``.png``, ``.hdr``, ``.tga``, ``.ppm``).  Anti-aliasing is off (``-A``);
    ``povray_options`` and ``extra_args`` come last and may override it.

    ``options`` are the keyword arguments of :func:`start_render`: ``extra_args``,
    ``threads``, ``cwd``, ``start_row``/``end_row`` and ``start_col``/``end_col``
    (a sub-rectangle as 0-based half-open pixel ranges, row 0 = top; the output
    file still has the full ``width`` x ``height`` size and untraced pixels are
    black), ``library_paths``, ``povray_options`` (the user's library paths, clock
    and passthrough options: :class:`~povlens.pov.povray_options.PovrayOptions`),
    ``timeout`` (s), ``nice``, ``idle``.

    The image is written to a temporary name in the folder of ``out_path`` and
    renamed on success; on failure ``out_path`` is not touched.  Returns
    ``out_path`` as a :class:`Path`.

    Raises :class:`PovrayError` (carrying POV-Ray's own error text) if POV-Ray
    is missing or exits with a non-zero status, :class:`UsageError` for bad
    arguments.
    """
    return start_render(pov_path, out_path, width, height, **options).wait()


def start_render(
    pov_path: str | os.PathLike,
    out_path: str | os.PathLike,
    width: int,
    height: int,
    *,
    extra_args: Sequence[str] = (),
    threads: int = 1,
    cwd: str | os.PathLike | None = None,
    start_row: int | None = None,
    end_row: int | None = None,
    start_col: int | None = None,
    end_col: int | None = None,
    library_paths: Iterable[str | os.PathLike] = (),
    povray_options: PovrayOptions | None = None,
    timeout: float | None = None,
    nice: int = 0,
    idle: bool = False,
    products: Sequence[str | os.PathLike] = (),
) -> "RenderJob":
    """Start the render :func:`render` describes and return at once.

    ``nice`` > 0 lowers the process's scheduling priority (``os.nice``).  ``idle``
    runs it only on CPU time nothing else wants (Linux ``SCHED_IDLE``; ``nice 19``
    where the OS has no such policy): a render started on a guess yields the cores
    to the work that decides whether it is needed, and gets them all once that
    work is done.  ``products``: files besides the image POV-Ray writes that must be
    whole before it is judged finished and stopped (:func:`povray_finished`).

    POV-Ray 3.7 spends most of a small render's wall time idle (~0.6 s per
    process, a few ms of CPU), so independent renders are best started together
    and collected with :meth:`RenderJob.wait`, which renames the image into place
    or raises the error :func:`render` would.  ``timeout`` counts from the start.
    Bad arguments and a missing POV-Ray raise here, before any process starts.
    """
    pov_path = Path(pov_path).resolve()
    out_path = Path(out_path).absolute()
    if not pov_path.is_file():
        raise UsageError(f"scene file {pov_path} does not exist", "check the path")
    switches = render_switches(out_path, width, height, threads=threads, start_row=start_row,
                               end_row=end_row, start_col=start_col, end_col=end_col,
                               library_paths=library_paths, extra_args=extra_args,
                               povray_options=povray_options)
    executable = find_povray()
    workdir = Path(cwd).absolute() if cwd is not None else pov_path.parent
    stack = contextlib.ExitStack()
    proc = None
    try:
        tmp = stack.enter_context(atomic_output(out_path))
        # the fatal-error log: a bare name, written into the image's folder
        log = tmp.parent / f".povlens-{os.getpid()}-{uuid.uuid4().hex[:12]}.log"
        stack.callback(_remove, log)
        # POV-Ray keeps a render-state file (image name, suffix .pov-state) while it
        # renders and removes it when done; a killed render leaves it behind.
        state = tmp.with_suffix(".pov-state")
        stack.callback(_remove, state)
        stack.callback(_remove, workdir / state.name)
        # Relative names where possible: POV-Ray's I/O restrictions permit the
        # working directory.
        inp = os.path.relpath(pov_path, workdir) if _inside(pov_path, workdir) else str(pov_path)
        outp = os.path.relpath(tmp, workdir) if _inside(tmp, workdir) else str(tmp)
        cmd = povray_command(executable, inp, outp, switches, error_log=log.name)
        err = stack.enter_context(tempfile.TemporaryFile())
        proc = start_povray(cmd, workdir, err, nice=nice, idle=idle)
        deadline = None if timeout is None else time.monotonic() + timeout
        return RenderJob(proc, stack, cmd, workdir, pov_path, out_path, tmp, log, err,
                         timeout, deadline, products)
    except BaseException as exc:
        if proc is not None:        # an interrupt before the job was made
            proc.kill()
            proc.wait()
        stack.__exit__(type(exc), exc, exc.__traceback__)
        raise


class RenderJob:
    """A POV-Ray render started by :func:`start_render`."""

    def __init__(self, proc, stack, cmd, workdir, pov_path, out_path, tmp, log, err,
                 timeout, deadline, products=()):
        self.proc, self.cmd, self.pov_path, self.out_path = proc, cmd, pov_path, out_path
        self._products = [Path(workdir, p) for p in products]
        self._stack, self._workdir, self._tmp, self._log, self._err = stack, workdir, tmp, log, err
        self._timeout, self._deadline = timeout, deadline
        self._started = time.monotonic()
        self._done = False      # wait() or cancel() called
        self._over = False      # POV-Ray judged finished (or failed, or stopped)

    def wait(self) -> Path:
        """Wait for POV-Ray; rename the image into place and return its path.

        Raises :class:`PovrayError` with POV-Ray's own message if it failed (or ran
        past the timeout: it is killed); the temporary image is removed then."""
        if self._done:
            raise RuntimeError("RenderJob.wait called twice")
        self._done = True
        try:
            self._collect()
        except BaseException as exc:
            self._kill()
            self._stack.__exit__(type(exc), exc, exc.__traceback__)  # drops the temporary image
            raise
        finally:
            self._over = True
        self._stack.close()  # renames the image to out_path, removes the log
        return self.out_path

    def finished(self) -> bool:
        """Whether :meth:`wait` would return at once: POV-Ray has exited, or has written
        its image and every product (:func:`povray_finished`).  Never blocks."""
        if self._done:          # over, or another thread's wait() is judging it
            return self._over
        return povray_finished(self.proc, self._tmp, time.monotonic() - self._started,
                               self._products)

    def cancel(self) -> None:
        """Stop POV-Ray (if still running) and remove its temporary files (a Ctrl-C
        or SIGTERM meanwhile waits until they are gone)."""
        if self._done:
            return
        self._done = self._over = True
        with interrupts_deferred():
            self._kill()
            try:
                raise PovrayError(f"render of {self.pov_path} cancelled")
            except PovrayError as exc:
                self._stack.__exit__(type(exc), exc, exc.__traceback__)

    def _kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def _collect(self) -> None:
        # Poll rather than wait: the image is final when POV-Ray has closed it,
        # ~0.3 s before the process exits (povray_finished stops it then).
        while True:
            age_s = time.monotonic() - self._started
            if povray_finished(self.proc, self._tmp, age_s, self._products):
                returncode = self.proc.returncode
                break
            if age_s < FIRST_OUTPUT_S:
                time.sleep(0.02)    # too young to have written its image: fewer wake-ups
                continue
            if self._deadline is not None and time.monotonic() > self._deadline:
                raise PovrayError(
                    f"POV-Ray did not finish rendering {self.pov_path} within {self._timeout} s",
                    "render a smaller image, or raise the time limit",
                )
            time.sleep(poll_interval_s(age_s))
        self._err.seek(0)
        stderr = io.TextIOWrapper(io.BytesIO(self._err.read()), errors="replace").read()
        log_text = self._log.read_text(errors="replace") if self._log.exists() else ""
        if returncode != 0 or not self._tmp.exists() or self._tmp.stat().st_size == 0:
            raise povray_failure(
                self.pov_path, self._workdir, returncode, stderr, log_text, self.out_path,
                what=str(self.pov_path),
                command=f"\n(command, run in {self._workdir}: {shlex.join(self.cmd)})")


def _remove(path: Path) -> None:
    """Remove ``path`` if it is there.  Quietly: a read-only folder refuses even the
    removal of a file that is not there (EROFS), which must not hide POV-Ray's error."""
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)


def _inside(path: Path, folder: Path) -> bool:
    try:
        Path(path).resolve().relative_to(Path(folder).resolve())
        return True
    except ValueError:
        return False
