"""Work in a child process that may crash: a signal there is an exception here.

A fault inside compiled code (a JIT-compiled Mitsuba kernel, a native library) kills the
process it runs in; no ``try`` can catch it. :class:`IsolatedProcess` runs calls in a child
Python process instead (:func:`_child_main`, started with :mod:`subprocess`, so
it also works inside daemonic Dask workers), one at a time, and turns the child's death into
:class:`ChildCrashed` naming the signal and the last stage the child reported. The next call
starts a new child; ``init`` calls are replayed there first.

Calls are ``fn(*args, **kwargs)`` with a module-level function and picklable arguments and
results (a call that does not pickle is :class:`NotSendable`, raised before anything is sent;
pickle, not JSON: the child is our own code, started by us, talking over a private
pipe); the child gets the parent's ``sys.path`` so that it can import what the parent
can. A child keeps module state between calls (e.g. a renderer built by an ``init`` call);
:meth:`IsolatedProcess.reinit` gives a running child new ``init`` calls (one child serves
one piece of work after another).
:attr:`IsolatedProcess.cpu_seconds` adds up the child's CPU time of the calls
that returned (the parent's ``time.process_time`` does not see it). The child's stdout is redirected to its stderr, so nothing it prints can corrupt the pipe;
its stderr is the parent's. Progress events (:mod:`brdffit.progress`) reported in the child
reach the parent's listeners, and the last ``stage`` is kept for the crash message.

>>> import operator
>>> with IsolatedProcess() as child:
...     child.call(operator.add, 2, 3)
5
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
import subprocess
import sys
import threading
import time

from .errors import BRDFError
from .progress import listening, report

__all__ = ["IsolatedProcess", "ChildCrashed", "NotSendable", "crash_text"]

_HEADER = struct.Struct("<Q")
_CHILD_COMMAND = "import sys; from brdffit._isolation import _child_main; sys.exit(_child_main())"


class ChildCrashed(BRDFError):
    """The child process died while running a call: ``signal_name`` (``"SIGSEGV"``, or
    ``None`` when it exited with ``exit_status``) and the last ``stage`` it reported."""

    def __init__(self, message: str, signal_name: str | None, exit_status: int | None,
                 stage: str | None):
        super().__init__(message)
        self.signal_name, self.exit_status, self.stage = signal_name, exit_status, stage


class NotSendable(BRDFError):
    """A call (its function, arguments) that cannot be pickled for the child, or that the
    child cannot unpickle (e.g. a class defined in the parent's ``__main__``): it did not
    run, the child is as it was."""


def crash_text(returncode: int | None) -> str:
    """``"SIGSEGV"`` for a child killed by a signal, ``"exit status 3"`` otherwise."""
    if returncode is not None and returncode < 0:
        try:
            return signal.Signals(-returncode).name
        except ValueError:
            return f"signal {-returncode}"
    return f"exit status {returncode}"


def _send(stream, obj) -> None:
    _write(stream, pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))


def _write(stream, data: bytes) -> None:
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _receive(stream):
    return pickle.loads(_read(stream))


def _read(stream) -> bytes:
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError
    (size,) = _HEADER.unpack(head)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return data


def _reap(proc: subprocess.Popen) -> int:
    """Wait for the child (killed after 30 s), close its output; its return code."""
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    proc.stdout.close()
    return proc.returncode


class IsolatedProcess:
    """A child Python process running calls one at a time (module docstring).

    ``what``: how crash messages name the work (``"the renderer"``); ``init``: calls
    ``(fn, args, kwargs)`` made first in every new child; ``env``: extra environment
    variables of the child. ``stage`` names what the child is doing in crash messages: set
    it before a call, or leave ``track_stages`` on to take the ``stage`` of the child's
    progress events.
    """

    def __init__(self, what: str = "the worker process", init=(), env=None,
                 track_stages: bool = True):
        self.what = what
        self.track_stages = track_stages
        self.init = list(init)
        self.env = dict(env or {})
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()
        self.stage: str | None = None
        self.starts = 0
        self.cpu_seconds = 0.0  # CPU time of the calls that returned, in all children

    # -- lifecycle ---------------------------------------------------------------------------
    def _start(self) -> None:
        env = {**os.environ, **self.env}
        self._proc = subprocess.Popen([sys.executable, "-c", _CHILD_COMMAND],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        self.starts += 1
        try:
            # the child imports what the parent can (the functions and classes of the calls)
            _send(self._proc.stdin, ("path", list(sys.path)))
            for fn, args, kwargs in self.init:
                self._call(fn, args, kwargs)
        except BaseException:  # never keep a child whose init did not run: the next call
            self.close()       # starts a new one
            raise

    @property
    def running(self) -> bool:
        """A child is up (it has not crashed nor been closed)."""
        return self._proc is not None

    def reinit(self, init=()) -> None:
        """Replace the ``init`` calls and make them now in the running child (a new child
        makes them at its start); a child whose new init dies or raises is closed."""
        with self._lock:
            self.init = list(init)
            if self._proc is None:
                return
            try:
                for fn, args, kwargs in self.init:
                    self._call(fn, args, kwargs)
            except BaseException:
                self.close()
                raise

    def close(self) -> None:
        """Stop the child (it exits when its input closes)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()
        except OSError:
            pass
        _reap(proc)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):  # pragma: no cover - best effort at interpreter exit
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass

    # -- calls -------------------------------------------------------------------------------
    def call(self, fn, *args, **kwargs):
        """``fn(*args, **kwargs)`` in the child; its exception is re-raised here, its death
        is :class:`ChildCrashed` (and the next call starts a new child)."""
        with self._lock:
            if self._proc is None:
                self._start()
            return self._call(fn, args, kwargs)

    def _call(self, fn, args, kwargs):
        proc = self._proc
        try:
            data = pickle.dumps(("call", fn, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # noqa: BLE001 – pickle raises several kinds
            raise NotSendable(f"{self.what}: cannot send {getattr(fn, '__name__', fn)!r} "
                              f"and its arguments to a child process ({type(exc).__name__}: "
                              f"{exc})") from None
        try:
            _write(proc.stdin, data)
            while True:
                kind, payload = _receive(proc.stdout)
                if kind == "event":
                    if self.track_stages and payload.get("stage"):
                        self.stage = str(payload["stage"])
                    report(**{k: v for k, v in payload.items() if k != "elapsed_s"})
                elif kind == "result":
                    result, cpu = payload
                    self.cpu_seconds += cpu
                    return result
                else:  # "error"
                    raise payload
        except (EOFError, BrokenPipeError, OSError) as exc:
            if isinstance(exc, OSError) and not isinstance(exc, BrokenPipeError) \
                    and proc.poll() is None:
                raise
            self._proc = None
            rc = _reap(proc)
            how = crash_text(rc)
            crashed = "crashed" if rc is not None and rc < 0 else "stopped"
            where = f" while {self.stage}" if self.stage else ""
            raise ChildCrashed(f"{self.what} {crashed} ({how}){where}",
                               how if rc is not None and rc < 0 else None,
                               None if rc is None or rc < 0 else rc, self.stage) from None


# -- the child ---------------------------------------------------------------------------------
def _child_main() -> int:
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # anything printed goes to stderr, never into the pipe
    sys.stdout = sys.stderr
    inp = os.fdopen(os.dup(0), "rb")

    def event(ev: dict) -> None:
        _send(out, ("event", {k: v for k, v in ev.items()
                              if isinstance(v, (str, int, float, bool, type(None)))}))

    while True:
        try:
            data = _read(inp)
        except EOFError:
            return 0
        try:
            message = pickle.loads(data)
        except Exception as exc:  # noqa: BLE001 – e.g. a class of the parent's __main__
            _send(out, ("error", NotSendable(f"the child process cannot load the call "
                                             f"({type(exc).__name__}: {exc})")))
            continue
        if message[0] == "path":
            sys.path[:] = list(dict.fromkeys([*message[1], *sys.path]))
            continue
        _, fn, args, kwargs = message
        try:
            cpu = time.process_time()
            with listening(event, min_interval=0.5):
                result = fn(*args, **kwargs)
            message = ("result", (result, time.process_time() - cpu))
            data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # noqa: BLE001 – every error goes back to the caller
            try:
                pickle.loads(pickle.dumps(exc))
            except Exception:  # noqa: BLE001 – an exception that does not pickle
                exc = RuntimeError(f"{type(exc).__name__}: {exc}")
            data = pickle.dumps(("error", exc), protocol=pickle.HIGHEST_PROTOCOL)
        _write(out, data)

